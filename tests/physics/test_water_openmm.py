"""rigidmd's water models against OpenMM's own model files: an implementation that is not LAMMPS.

OpenMM ships TIP3P, SPC/E, TIP4P-Ew and OPC (``opc.xml`` is Amber's OPC,
whose energy OpenMM's own tests check against Amber's).  The same 125 whole
waters at liquid density go through OpenMM (PME, the model file, virtual M
sites placed by OpenMM) and through rigidmd's LAMMPS set-up
(:meth:`~rigidmd.water.WaterModel.lammps_commands` with Ewald,
intramolecular pairs excluded, :func:`~rigidmd.mdanalysis.thermo.excluded_kspace_energy`
taken off), 7 Å cut-off on both sides.  Compared: the parameters of each
file with rigidmd's, the intermolecular energy per molecule and each body's
force and torque with the same parameters, and the long-range Lennard-Jones
correction with its formula.
"""

import numpy as np
import pytest
from ase import units
from helpers import benchmark_module, whole_water_box

from rigidmd.mdanalysis.thermo import ewald_parameter, excluded_kspace_energy
from rigidmd.openmm import FORCE_FIELD_FILES, real_atom_forces, water_system
from rigidmd.systems import water_box
from rigidmd.water import water_model

mm = pytest.importorskip("openmm",
                         reason="needs OpenMM (pip install openmm; the test extra has it)")
pytestmark = [pytest.mark.openmm, pytest.mark.lammps]

KJ = units.kJ / units.mol
CUTOFF = 7.0  # Å; the 125-water box is 15.5 Å wide


def openmm_result(atoms, model, tail=False, **kwargs):
    """OpenMM's energy (kJ/mol), forces on the real atoms (kJ/mol/Å) and placed sites (Å)."""
    _, system = water_system(atoms, model, CUTOFF, tail=tail, error_tolerance=1e-7, **kwargs)
    context = mm.Context(system, mm.VerletIntegrator(1e-3),
                         mm.Platform.getPlatformByName("Reference"))
    context.setPositions(atoms.positions / 10)
    context.computeVirtualSites()
    state = context.getState(getEnergy=True, getForces=True, getPositions=True, groups={1})
    u = mm.unit
    forces = state.getForces(asNumpy=True).value_in_unit(u.kilojoule_per_mole / u.angstrom)
    return (state.getPotentialEnergy().value_in_unit(u.kilojoule_per_mole),
            real_atom_forces(system, forces),
            state.getPositions(asNumpy=True).value_in_unit(u.angstrom))


def rigidmd_result(atoms, model, tail=False):
    """Intermolecular energy (kJ/mol) and forces (kJ/mol/Å) of rigidmd's LAMMPS set-up."""
    from rigidmd.lammps import LAMMPSCalculator

    n = len(atoms) // model.sites
    types = {"O": 1, "H": 2, "X": 3} if model.sites == 4 else {"O": 1, "H": 2}
    calc = LAMMPSCalculator(model.lammps_commands(CUTOFF, "ewald", 1e-8, tail=tail),
                            atom_types=types,
                            molecule_ids=np.repeat(np.arange(1, n + 1), model.sites))
    atoms = atoms.copy()
    atoms.calc = calc
    energy = atoms.get_potential_energy() - excluded_kspace_energy(
        model, ewald_parameter(calc), n)
    return energy / KJ, atoms.get_forces() / KJ


def body_force_torque(positions, forces, sites):
    """Each body's total force and torque about its oxygen."""
    x = positions.reshape(-1, sites, 3)
    f = forces.reshape(-1, sites, 3)
    return f.sum(axis=1), np.cross(x - x[:, :1], f).sum(axis=1)


# Largest relative gap of each file's parameter from rigidmd's, measured.  TIP3P: rigidmd's
# are ASE's (σ 3.15061 Å, ε 0.1521 kcal/mol, CHARMM's), OpenMM's Jorgensen's A and C
# (3.15075 Å, 0.635968 kJ/mol): ε 6.6e-4.  SPC/E: OpenMM's ε 0.6497752 kJ/mol and
# σ 3.16572 Å against Berendsen's 0.650 and 3.166: 3.5e-4.  OPC: Amber's q_H 0.679142 e
# against the paper's 0.6791: 6.2e-5.  TIP4P-Ew: identical (0).
PARAMETER_GAP = {"tip3p": 6.6e-4, "spce": 3.5e-4, "tip4pew": 0.0, "opc": 6.2e-5}


@pytest.mark.parametrize("name", FORCE_FIELD_FILES)
def test_parameters_and_m_site_are_the_model_files(name):
    model = water_model(name)
    atoms = whole_water_box(name)
    _, system = water_system(atoms, model, CUTOFF)
    nonbonded = next(f for f in system.getForces() if isinstance(f, mm.NonbondedForce))
    params = [nonbonded.getParticleParameters(i) for i in range(model.sites)]
    charge = np.array([p[0].value_in_unit(mm.unit.elementary_charge) for p in params])
    sigma = params[0][1].value_in_unit(mm.unit.angstrom)
    epsilon = params[0][2].value_in_unit(mm.unit.kilojoule_per_mole) * KJ
    ours = model.charges(1)
    charged = ours != 0
    assert np.all(charge[~charged] == 0)
    gaps = np.abs(np.concatenate([charge[charged] / ours[charged] - 1,
                                  [sigma / model.sigma - 1, epsilon / model.epsilon - 1]]))
    assert gaps.max() == pytest.approx(PARAMETER_GAP[name], abs=0.05e-4)
    # M where OpenMM's virtual site puts it from rigidmd's O and H: TIP4P-Ew 3e-10 Å,
    # OPC 9.6e-6 Å (Amber's weights come from its 0.87243313 Å, 0.15939833 Å geometry;
    # rigidmd has the paper's 0.8724 and 0.1594).
    placed = openmm_result(atoms, model)[2]
    assert np.abs(placed - atoms.positions).max() < 2e-5


@pytest.mark.parametrize("name", FORCE_FIELD_FILES)
def test_energy_forces_and_torques_equal_openmm_with_the_same_parameters(name):
    model = water_model(name)
    atoms = whole_water_box(name)
    n = len(atoms) // model.sites
    e_ours, f_ours = rigidmd_result(atoms, model)
    e_mm, f_mm, _ = openmm_result(atoms, model, parameters="rigidmd")
    # Measured per molecule: 2.2e-5 (TIP3P), 2.4e-5 (SPC/E), 3.5e-5 (TIP4P-Ew), 7.7e-5
    # kJ/mol (OPC, whose M OpenMM places 9.6e-6 Å away); a missed excluded pair, a wrong M
    # or a missing Lennard-Jones term moves it by 0.1-100 kJ/mol.
    assert abs(e_ours - e_mm) / n < 3e-4
    f1, t1 = body_force_torque(atoms.positions, f_ours, model.sites)
    f2, t2 = body_force_torque(atoms.positions, f_mm, model.sites)
    # Measured largest gap (of forces up to ~100 kJ/mol/Å, torques up to ~135 kJ/mol):
    # forces 9e-5 to 1.8e-4, torques 5e-5 to 1e-4; OPC 3.3e-3 and 3.6e-3 (its M).
    assert np.abs(f1 - f2).max() < 1e-2
    assert np.abs(t1 - t2).max() < 1e-2


@pytest.mark.parametrize("name", ["tip3p", "opc"])
def test_long_range_lennard_jones_correction(name):
    r"""``tail=True`` adds :math:`\frac{8\pi N_O^2 \varepsilon\sigma^3}{3V}
    [\frac13(\sigma/r_c)^9 - (\sigma/r_c)^3]` (LAMMPS's ``pair_modify tail``).

    OpenMM's dispersion correction averages over atom pairs with each atom's
    pair with itself, larger by :math:`(1 + 1/N_O)\,N/(N + 1)`: 0.5 % (TIP3P) and
    0.6 % (OPC) at 125 waters, 0.003-0.005 kJ/mol per molecule, what a
    comparison with OpenMM that keeps both corrections sees.
    """
    model = water_model(name)
    atoms = whole_water_box(name)
    n_o = len(atoms) // model.sites
    x = model.sigma / CUTOFF
    formula = (8 * np.pi * n_o**2 * model.epsilon * model.sigma**3 / (3 * atoms.get_volume())
               * (x**9 / 3 - x**3)) / KJ
    lammps = rigidmd_result(atoms, model, tail=True)[0] - rigidmd_result(atoms, model)[0]
    assert lammps == pytest.approx(formula, rel=1e-9)
    openmm = (openmm_result(atoms, model, parameters="rigidmd", tail=True)[0]
              - openmm_result(atoms, model, parameters="rigidmd")[0])
    n = len(atoms)
    assert openmm == pytest.approx(formula * (1 + 1 / n_o) * n / (n + 1), rel=1e-6)


def test_what_openmm_cannot_take_is_refused_with_one_line():
    opc = water_model("opc")
    with pytest.raises(ValueError, match="OpenMM ships no file for tip4p2005; use one of"):
        water_system(whole_water_box("tip4p2005"), water_model("tip4p2005"), CUTOFF)
    wrapped = water_box(5, seed=1, model="opc", whole=False)  # molecules straddle the faces
    with pytest.raises(ValueError, match=r"molecule \d+ \(atoms \d+-\d+\) is split across"):
        water_system(wrapped, opc, CUTOFF)
    with pytest.raises(ValueError, match="at most half the cell's smallest width"):
        water_system(whole_water_box("opc"), opc, 8.0)
    with pytest.raises(ValueError, match="parameters must be 'file' or 'rigidmd'"):
        water_system(whole_water_box("opc"), opc, CUTOFF, parameters="amber")
    with pytest.raises(ValueError, match="tip4pew: molecule 0 .* is not in this model's geom"):
        water_system(whole_water_box("opc"), water_model("tip4pew"), CUTOFF)


@pytest.mark.slow
def test_openmm_check_benchmark_quick(tmp_path):
    """``validation/water_openmm_check.py --quick``: OpenMM's NPT from the benchmark's start,
    density and ΔH_vap (with TIP4P-Ew's polarisation correction) stored and printed."""
    import json

    bench = benchmark_module("water_openmm_check")
    (result,) = bench.main(["--quick", "--models", "tip4pew", "--outdir", str(tmp_path)])
    assert json.loads((tmp_path / "openmm" / "tip4pew.json").read_text()) == result
    series = np.load(tmp_path / "openmm" / "tip4pew.series.npz")
    assert len(series["energy_kj_mol"]) == len(series["volume_A3"]) == 10  # 1 ps, 0.1 ps apart
    assert result["molecules"] == 216 and result["cutoff"] == 9.0
    assert 0.9 < result["density"][0] < 1.1 and result["density"][1] > 0
    # 1 ps from a lattice: the liquid's ΔH_vap (48.8) within a few kJ/mol; E_pol 4.64.
    assert 40 < result["dhvap"][0] < 60 and result["dhvap"][1] > 0
    assert result["dhvap"][0] - result["dhvap_corrected"] == pytest.approx(4.64, abs=0.01)
    with pytest.raises(SystemExit):
        bench.main(["--quick", "--models", "tip4p2005", "--outdir", str(tmp_path)])


@pytest.mark.slow
def test_rigidmd_and_openmm_track_each_other_from_one_state(tmp_path):
    """``validation/water_openmm_nve.py --quick``: 27 TIP4P-Ew waters, NVE at 0.5 and 1 fs in
    rigidmd (NO_SQUISH, LAMMPS) and OpenMM (leapfrog with SETTLE, M a virtual site) from the
    same positions and velocities, Ewald at 1e-6 on both sides."""
    import json

    script = benchmark_module("water_openmm_nve")
    result = script.main(["--quick", "--outdir", str(tmp_path)])
    stored = json.loads((tmp_path / "water_openmm_nve_quick.json").read_text())
    assert stored["divergence"] == result["divergence"]  # (the 0.1 ps runs' errors are NaN)
    assert (tmp_path / "water_openmm_nve_quick.txt").exists()
    runs = {(r["code"], r["dt_fs"]): r for r in result["runs"]}
    assert set(runs) == {(c, dt) for c in ("rigidmd", "openmm") for dt in (0.5, 1.0)}
    for dt in (0.5, 1.0):
        ours, theirs = runs["rigidmd", dt], runs["openmm", dt]
        # The same state read by both: kinetic temperatures of translation and rotation
        # from OpenMM's atom velocities (M massless, inertia of O, H, H) against rigidmd's
        # bodies; measured 3e-10 relative (OpenMM keeps velocities in its own precision).
        for key in ("T_tr_start", "T_rot_start"):
            assert theirs[key] == pytest.approx(ours[key], rel=1e-8)
        # rigidmd's own kinetic energies against the same sums over its atoms: measured
        # 3e-13 to 2e-12 K along the runs.
        assert ours["T_tr_atoms_max_dev"] < 1e-8 and ours["T_rot_atoms_max_dev"] < 1e-8
    # Two second-order integrators: their trajectories part at O(h²).  RMS distance of the
    # oxygens after 0.1 ps, measured 3.2e-5 Å at 0.5 fs and 8.1e-5 Å at 1 fs (a ratio of
    # 4.0 with Ewald at 1e-8; at 1e-6 the forces' own gap, ~1e-5 Å, adds to both).  A force
    # on M not carried to the body, or M misplaced, parts them by 1e-2 Å or more at any step;
    # a first-order error gives a ratio near 2 or below.
    d05, d1 = (result["divergence"][k][10] for k in ("0.5", "1"))
    assert d05 < 1e-4
    assert d1 / d05 > 2.2


@pytest.mark.slow
def test_long_run_pipeline(tmp_path):
    """``validation/water_openmm_long.py --quick``: a rigidmd (RigidLangevin) and an OpenMM
    (LangevinMiddleIntegrator) run of 216 TIP4P-Ew waters, each stopped by a 10 s budget,
    and their report (U, kinetic and configurational temperatures)."""
    import json

    script = benchmark_module("water_openmm_long")
    result = script.main(["--quick", "--outdir", str(tmp_path)])
    stored = json.loads((tmp_path / "water_openmm_long_quick.json").read_text())
    assert stored["groups"] == json.loads(json.dumps(result["groups"]))
    groups = {g["code"]: g for g in result["groups"]}
    assert set(groups) == {"rigidmd", "openmm"}
    assert groups["rigidmd"]["dof_tr"] == 3 * 216 - 3  # fixcm: the momentum is held
    assert groups["openmm"]["dof_tr"] == 3 * 216  # Langevin noise moves the momentum
    for g in groups.values():
        assert g["ps"] > 0
        # The start is liquid TIP4P-Ew at 298 K: U within 1 kJ/mol of -46.4, and the
        # configurational temperatures of its first frames within 60 K of 298 K.
        assert abs(g["U_frames"][0] + 46.4) < 1.0
        for key in ("Tconf_tr", "Tconf_rot"):
            assert abs(g[key][0] - 298) < 60, (key, g[key])
    # rigidmd's LAMMPS energy holds a constant intramolecular Coulomb part; moved onto
    # OpenMM's scale its frames agree with OpenMM's energy to PPPM against PME at 1e-5.
    assert all(sd < 0.01 for sd in groups["rigidmd"]["offset_sd"])
    assert abs(groups["rigidmd"]["U"][0] + 46.4) < 1.0


def _long_run(path, seed, frames=3, n=4):
    """A stand-in of ``water_openmm_long.py run``'s file: ``n`` TIP4P-Ew waters, ``frames``
    frames 1 ps apart, energies and kinetic energies every 10 fs."""
    import json

    rng = np.random.default_rng(seed)
    grown = rng.uniform(0, 20, (10, n, 3, 3)).astype(np.float32)  # a longer run: more of them
    model = water_model("tip4pew")
    samples = 100 * frames
    meta = {"model": "tip4pew", "molecules": n, "code": "rigidmd", "thermo": "langevin",
            "fixcm": 1, "tau_ps": 1.0, "dt_fs": 2.0, "seed": seed, "ke_fs": 10.0,
            "u_fs": 10.0, "frame_fs": 1000.0}
    np.savez_compressed(path, masses=np.tile(model.masses(), n), cell=np.eye(3) * 20,
                        meta=json.dumps(meta), K_tr=rng.uniform(1, 2, samples),
                        K_rot=rng.uniform(1, 2, samples), U=rng.uniform(-50, -40, samples),
                        U_t_ps=np.arange(samples) / 100,
                        frames=grown[:frames])


def test_long_runs_configurational_sums_are_of_the_runs_own_frames(tmp_path, monkeypatch):
    """The report kept each run's configurational sums beside it, keyed by the path alone:
    after another run was written to the same file, its report took the first run's sums
    (U_frames, T_conf and rigidmd's energy offset, silently).  OpenMM's nine force calls a
    frame are replaced by a stand-in that counts them."""
    script = benchmark_module("water_openmm_long")
    computed = []

    def sums(context, x, masses, rng, sites):
        computed.append(x)
        return np.array([x.sum(), 1.0, 2.0, 3.0, 4.0])

    monkeypatch.setattr(script, "configurational_sums", sums)
    contexts = {"tip4pew": None}  # no OpenMM context: the stand-in needs none
    path = tmp_path / "run.npz"
    _long_run(path, seed=1)
    first = script.analyse_run(path, contexts)
    assert len(computed) == 3
    again = script.analyse_run(path, contexts)  # the same run: its cached sums
    assert len(computed) == 3
    np.testing.assert_array_equal(again["U_frames"], first["U_frames"])
    _long_run(path, seed=2)  # another run into the same file
    second = script.analyse_run(path, contexts)
    assert len(computed) == 6
    for cache in tmp_path.glob("run.npz.conf*"):
        cache.unlink()
    fresh = script.analyse_run(path, contexts)  # no cache: its own frames' sums
    assert len(computed) == 9
    for key in ("U_frames", "U", "conf"):
        np.testing.assert_array_equal(second[key], fresh[key])
    assert second["offset"] == fresh["offset"]
    assert second["U_frames"][0, 0] != pytest.approx(first["U_frames"][0, 0])
    _long_run(path, seed=2, frames=5)  # the same run grown: its sums extended
    script.analyse_run(path, contexts)
    assert len(computed) == 11


def test_long_runs_out_and_report_files_are_checked(tmp_path, capsys):
    """A second ``run`` into an existing ``--out`` replaced the first run's file silently
    (now refused unless ``--overwrite``); ``report a.npz a.npz`` pooled one run twice."""
    script = benchmark_module("water_openmm_long")
    out = tmp_path / "run.npz"
    out.write_bytes(b"a finished run")
    run = ["run", "--code", "rigidmd", "--thermo", "langevin", "--dt-fs", "2",
           "--budget-s", "10", "--out", str(out)]
    with pytest.raises(SystemExit) as stop:
        script.parse(run)
    assert stop.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert f"argument --out: {out} exists" in err and "--overwrite" in err
    assert script.parse([*run, "--overwrite"]).overwrite
    (tmp_path / "sub").mkdir()
    other = tmp_path / "sub" / ".." / "run.npz"
    with pytest.raises(SystemExit) as stop:
        script.parse(["report", str(out), str(other)])
    assert stop.value.code == 2
    assert f"argument files: {other} given twice" in capsys.readouterr().err
    assert out.read_bytes() == b"a finished run"
