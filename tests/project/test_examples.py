"""The examples run, in shortened form, and produce plausible outputs.

Each one's output as the docs show it (``examples/output/<name>.txt``, its first line the
command) is checked to be what the script prints now, numbers aside.
"""

import json
import math
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = [pytest.mark.lammps, pytest.mark.mdanalysis, pytest.mark.slow]

ROOT = Path(__file__).resolve().parents[2]
#: A number as the examples print them (1, -0.5, 3.3e-04, 1.004): masked when outputs are
#: compared, since timings, and the numbers of a shortened run, vary.
NUMBER = re.compile(r"nan|[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


def masked(lines):
    """The lines with every number replaced by ``#`` and runs of blanks by one."""
    return [" ".join(NUMBER.sub("#", line).split()) for line in lines]


def assert_output_is_current(name, command, stdout):
    """``examples/output/<name>.txt`` (which the docs show) is ``$ command`` and then what
    the script printed (run as ``command`` in an empty folder), numbers aside."""
    recorded = (ROOT / "examples" / "output" / f"{name}.txt").read_text().splitlines()
    assert recorded[0] == f"$ {command}", recorded[0]
    printed = stdout
    assert masked(recorded[1:]) == masked(printed.splitlines()), (
        f"examples/output/{name}.txt is not what {command} prints now; record it again "
        f"(run the command in an empty folder, its output after a first line '$ {command}')"
        f":\n{printed}")


def run_example(tmp_path, name, *args):
    """Run ``examples/<name>.py args`` in ``tmp_path``; the finished process."""
    proc = subprocess.run([sys.executable, str(ROOT / "examples" / f"{name}.py"), *args],
                          capture_output=True, text=True, timeout=600, cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-4000:]
    return proc


def interrupted(tmp_path, name, outdir, when):
    """``examples/<name>.py --quick --outdir outdir`` sent SIGINT once it prints a line
    holding ``when``: its exit status, standard output and standard error."""
    run = subprocess.Popen([sys.executable, str(ROOT / "examples" / f"{name}.py"), "--quick",
                            "--outdir", str(outdir)], stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, text=True, cwd=tmp_path)
    for line in run.stdout:
        if when in line:
            run.send_signal(signal.SIGINT)
            break
    out, err = run.communicate(timeout=300)
    return run.returncode, out, err


def test_water_cluster_output_is_current(tmp_path):
    """32 TIP3P waters, 1 ps NVE with ASE's calculator (~20 s idle)."""
    proc = run_example(tmp_path, "water_cluster")
    assert_output_is_current("water_cluster", "python examples/water_cluster.py", proc.stdout)


def test_validate_against_lammps_runs_and_its_output_is_current(tmp_path):
    """The gaps to fix rigid/nve for every system (the mixture's force field comes from
    tests/helpers.py: the example failed at that import once the tests' builders moved)."""
    proc = run_example(tmp_path, "validate_against_lammps")
    assert_output_is_current("validate_against_lammps",
                             "python examples/validate_against_lammps.py", proc.stdout)
    assert "4 CO2+4 H2O+2 Ne" in proc.stdout


def test_tip3p_water_quick(tmp_path):
    """216 rigid TIP3P waters, LAMMPS PPPM forces: 1 ps thermostat, 2 ps NVE (~30 s)."""
    # The test extra installs both MDAnalysis and lammps; no skipping.
    proc = run_example(tmp_path, "tip3p_water", "--quick")
    for name in ("tip3p.psf", "tip3p.xtc", "tip3p.log", "tip3p_rdf.png", "tip3p_msd.png",
                 "tip3p_rotation.png", "tip3p_results.json"):
        assert (tmp_path / name).stat().st_size > 0, name
    res = json.loads((tmp_path / "tip3p_results.json").read_text())
    assert res["n_water"] == 216 and res["n_frames"] == 201
    # Liquid water, even after this short run (TIP3P: first peak near 2.8 Å).
    assert 2.65 < res["rdf_first_peak_position_A"] < 2.95
    assert 2.0 < res["rdf_first_peak_height"] < 3.5
    # TIP3P's first minimum is shallow and flat (g ≈ 0.92-0.97 from 3.4 to 4.1 Å), so
    # its position, and the neighbours within it (4.8 in 50 ps), scatter in a 2 ps run.
    assert 3.2 < res["rdf_first_minimum_A"] < 4.3
    assert 4.0 < res["coordination_number"] < 9.0
    assert 1.0 < res["diffusion_1e-5_cm2_s"] < 15.0
    assert 0.2 < res["tau2_ps"] < 5.0
    assert math.isfinite(res["tau2_integral_ps"])
    # PPPM against Ewald, and energy conservation at 2 fs.
    assert res["force_error_vs_ewald"] < 1e-3 and res["torque_error_vs_ewald"] < 1e-3
    assert abs(res["energy_drift_eV_per_ps"]) < 0.05
    for source in ("Mark & Nilsson", "Yeh & Hummer", "Price & Brooks"):
        assert source in proc.stdout
    assert_output_is_current("tip3p_water", "python examples/tip3p_water.py --quick",
                             proc.stdout)
    # A Ctrl-C in the production was a traceback that left the trajectory and log cut
    # anywhere; now the step under way ends, both are closed whole, and --analyse-only
    # analyses what was run.
    stopped = tmp_path / "stopped"
    code, out, err = interrupted(tmp_path, "tip3p_water", stopped, "production 1 / 2 ps")
    assert code == 130 and "Traceback" not in err, out + err
    assert "stopped (SIGINT) at 1" in out and "--analyse-only analyses it" in out
    assert not (stopped / "tip3p_results.json").exists()
    analysed = run_example(tmp_path, "tip3p_water", "--outdir", str(stopped),
                           "--analyse-only")
    assert "analysed" in analysed.stdout
    partial = json.loads((stopped / "tip3p_results.json").read_text())
    assert 100 < partial["n_frames"] < 201  # 1-1.1 ps of the 2, a frame each 10 fs


def test_tip4p2005_quick(tmp_path):
    """216 TIP4P/2005 waters (explicit M), LAMMPS PPPM with tail corrections, C-rescale NPT.

    The full run (200 ps) is what docs/validation/water.md reports; this one checks that the
    pipeline runs and gives liquid-like numbers after 1.4 ps from a quenched lattice.
    """
    proc = run_example(tmp_path, "tip4p2005", "--quick")
    assert "Warning" not in proc.stderr, proc.stderr  # no step-size or energy warnings
    res = json.loads((tmp_path / "tip4p2005_results.json").read_text())
    assert res["molecules"] == 216
    assert 0.85 < res["density_g_cm3"] < 1.15
    assert 0.0 < res["diffusion_A2_ps"] < 5.0
    assert "Abascal & Vega 2005" in proc.stdout
    assert (tmp_path / "tip4p2005.log").stat().st_size > 0
    assert_output_is_current("tip4p2005", "python examples/tip4p2005.py --quick", proc.stdout)
    # Again into the same folder (as docs/validation/water.md's two commands): the log got
    # the second run appended (two headers, times from 0 again); now it is replaced, and
    # the run says so.
    again = run_example(tmp_path, "tip4p2005", "--quick")
    assert again.stdout.startswith("replacing an earlier run's tip4p2005.log, "
                                   "tip4p2005_results.json, tip4p2005_com.npz in .")
    log = (tmp_path / "tip4p2005.log").read_text()
    assert log.count("Time[ps]") == 1
    # A Ctrl-C in the production (a 25-minute run at the defaults) was a traceback that kept
    # only the log's header; now it keeps a checkpoint, and --resume ends where an
    # uninterrupted run ends, to roundoff: the resumed run's new LAMMPS instance sums its
    # forces in the order of lists it builds anew (measured: density 2e-16 and D's axes
    # 1e-15 relative, or equal).
    first = json.loads((tmp_path / "tip4p2005_results.json").read_text())
    stopped = tmp_path / "stopped"
    code, out, err = interrupted(tmp_path, "tip4p2005", stopped, "production 0.5 / 1 ps")
    assert code == 130 and "Traceback" not in err, out + err
    assert f"continue with: python {ROOT / 'examples' / 'tip4p2005.py'} --outdir {stopped} " \
           "--resume" in out
    assert not (stopped / "tip4p2005_results.json").exists()
    resumed = run_example(tmp_path, "tip4p2005", "--outdir", str(stopped), "--resume")
    assert "resuming at" in resumed.stdout
    result = json.loads((stopped / "tip4p2005_results.json").read_text())
    assert result["density_g_cm3"] == pytest.approx(first["density_g_cm3"], rel=1e-12)
    assert result["diffusion_A2_ps"] == pytest.approx(first["diffusion_A2_ps"], rel=1e-12)
    assert sorted(p.name for p in stopped.iterdir()) == [
        "tip4p2005.log", "tip4p2005_com.npz", "tip4p2005_results.json"]
    assert (stopped / "tip4p2005.log").read_text().count("Time[ps]") == 1


def example_module(name):
    from helpers import benchmark_module

    return benchmark_module(name)


@pytest.mark.parametrize("name, args, message", [
    ("tip4p2005", ["--production-ps", "0.3"], "argument --production-ps: the diffusion fit "
                                              "needs at least 1 ps, got 0.3"),
    ("tip4p2005", ["--timestep-fs", "0"], "argument --timestep-fs: must be positive, got 0.0"),
    ("tip3p_water", ["--n-side", "0"], "argument --n-side: must be at least 1, got 0"),
    ("tip3p_water", ["--production-ps", "-1"], "argument --production-ps: must be positive"),
    ("tip3p_water", ["--analyse-only", "--outdir", "{tmp}"], "argument --analyse-only: no "
                                                             "tip3p.psf, tip3p.xtc in"),
])
def test_the_water_examples_refuse_a_bad_argument_first(tmp_path, capsys, name, args, message):
    """``--production-ps 0.3`` printed a diffusion coefficient fitted through one lag,
    ``--timestep-fs 0`` divided by zero after the quench, ``--n-side 0`` and
    ``--analyse-only`` in an empty folder gave tracebacks, ``--production-ps -1`` ran the
    whole simulation first."""
    module = example_module(name)
    with pytest.raises(SystemExit) as stop:
        module.parse([a.format(tmp=tmp_path) for a in args])
    assert stop.value.code == 2
    assert message in capsys.readouterr().err.strip().splitlines()[-1]


def test_quick_keeps_a_time_given_explicitly():
    """``--quick --production-ps 0.4`` ran 2 ps: --quick set every time over what was given."""
    tip3p = example_module("tip3p_water").parse(["--quick", "--production-ps", "0.4"])
    assert (tip3p.production_ps, tip3p.equilibration_ps, tip3p.sample_fs) == (0.4, 1.0, 10.0)
    tip4p = example_module("tip4p2005").parse(["--quick", "--production-ps", "3"])
    assert (tip4p.production_ps, tip4p.quench_ps) == (3.0, 0.05)
    assert example_module("tip4p2005").parse([]).production_ps == 200.0
