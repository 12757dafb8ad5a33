"""Heat of vaporisation and its parts (rigidmd.mdanalysis.thermo), on known energies."""

import numpy as np
import pytest
from ase import units
from helpers import CoulombLJ, water_parameters

from rigidmd.mdanalysis.thermo import (
    KJ_PER_MOL,
    HeatOfVaporization,
    block_average,
    ewald_parameter,
    excluded_kspace_energy,
    polarization_energy,
)
from rigidmd.mdanalysis.viscosity import ShearViscosity
from rigidmd.systems import water_cluster
from rigidmd.water import water_model

SPCE = water_model("spce")


# --------------------------------------------------- heat of vaporisation
@pytest.mark.lammps
@pytest.mark.parametrize("name", ["spce", "tip4p2005"])
def test_excluded_kspace_energy_leaves_the_intermolecular_energy(name):
    """A dimer in a 30 Å box with PPPM: LAMMPS's energy less the excluded pairs' k-space
    part is the dimer's pair energy (CoulombLJ, no cut-off).  Measured gaps 3.7e-5 eV
    (SPC/E) and 1.0e-5 eV (TIP4P/2005): the periodic images' dipole energy (~1e-4 eV)
    and PPPM's 1e-6 accuracy; bound 1e-3 eV.  The excluded part itself is -4.2 and
    -7.4 eV, so the test fails without it."""
    from rigidmd.lammps import LAMMPSCalculator

    model = water_model(name)
    atoms = water_cluster(2, seed=1, model=name)
    atoms.set_initial_charges(model.charges(2))
    reference = atoms.copy()
    reference.calc = CoulombLJ(parameters=water_parameters(model))
    exact = reference.get_potential_energy()
    atoms.set_cell([30.0] * 3)
    atoms.pbc = True
    atoms.center()
    types = {"O": 1, "H": 2} if model.sites == 3 else {"O": 1, "H": 2, "X": 3}
    calc = LAMMPSCalculator(model.lammps_commands(12.0, "pppm", 1e-6, tail=False),
                            atom_types=types)
    atoms.calc = calc
    raw = atoms.get_potential_energy()
    offset = excluded_kspace_energy(model, ewald_parameter(calc), 2)
    assert abs(offset) > 1.0
    assert raw - offset == pytest.approx(exact, abs=1e-3)


def test_heat_of_vaporization_of_known_energies(rng):
    """-<U>/N + RT with the block error of an uncorrelated series, and E_pol for SPC/E."""
    n, mean = 216, -46.0 * KJ_PER_MOL * 216
    energies = mean + rng.normal(0.0, 0.5, 10_000)
    hv = HeatOfVaporization(energies, n, 298.0, model=SPCE).run()
    rt = units.kB * 298.0 / KJ_PER_MOL  # 2.478 kJ/mol
    assert rt == pytest.approx(2.4777, abs=1e-3)
    expected_err = 0.5 / np.sqrt(10_000) / n / KJ_PER_MOL
    assert hv.results.delta_h_kj_mol == pytest.approx(46.0 + rt, abs=4 * expected_err)
    assert hv.results.delta_h_stderr_kj_mol == pytest.approx(expected_err, rel=0.5)
    # Berendsen et al. quote 5.22 kJ/mol for SPC/E; the same formula gives 5.24.
    assert hv.results.polarization_energy_kj_mol == pytest.approx(5.22, abs=0.03)
    assert hv.results.delta_h_corrected_kj_mol == pytest.approx(
        hv.results.delta_h_kj_mol - hv.results.polarization_energy_kj_mol)
    plain = HeatOfVaporization(energies, n, 298.0, model=water_model("tip3p")).run()
    assert plain.results.delta_h_corrected_kj_mol is None
    shifted = HeatOfVaporization(energies + 5.0, n, 298.0, energy_offset=5.0).run()
    assert shifted.results.delta_h_kj_mol == pytest.approx(hv.results.delta_h_kj_mol)
    assert polarization_energy(water_model("tip4p2005")) / KJ_PER_MOL == pytest.approx(
        4.33, abs=0.01)


def test_the_mean_is_the_series_mean_when_the_blocks_are_unequal():
    """19 frames in 10 blocks (one of one frame, nine of two): the mean of the block means
    weighted the lone frame twice, ``block_average([0]*10 + [10], 10)`` gave 1.0 (the mean is
    10/11), and ΔH_vap of a known ⟨U⟩/N came out 0.26 kJ/mol off."""
    values = np.array([0.0] * 10 + [10.0])
    mean, error = block_average(values, 10)
    assert mean == pytest.approx(10 / 11) and error > 0
    energies = np.r_[np.full(10, -40.0), np.full(9, -50.0)] * 216 * KJ_PER_MOL
    result = HeatOfVaporization(energies, 216, 298.0).run().results
    assert result.potential_energy_kj_mol == pytest.approx(energies.mean() / 216 / KJ_PER_MOL)


def test_bad_inputs_are_refused():
    with pytest.raises(ValueError, match="n_molecules"):
        HeatOfVaporization([1.0, 2.0], 0, 298.0)
    with pytest.raises(ValueError, match="non-finite"):
        HeatOfVaporization([1.0, np.nan], 2, 298.0)
    with pytest.raises(ValueError, match="cannot make 10 blocks"):
        block_average([1.0, 2.0])
    with pytest.raises(ValueError, match="longer than twice max_lag_ps"):
        ShearViscosity(np.zeros((100, 6)), 1000.0, 300.0, 0.01).run()


def test_a_water_model_given_by_name_gets_its_correction():
    """``model="spce"`` left out the polarisation correction in silence (None), and
    ``n_molecules=215.6`` was taken as 215 (ΔH 49.4 instead of 49.2 kJ/mol)."""
    energies = np.full(100, -46.7 * 216 * KJ_PER_MOL)
    by_model = HeatOfVaporization(energies, 216, 298.0, model=SPCE).run().results
    by_name = HeatOfVaporization(energies, 216.0, 298.0, model="SPC/E").run().results
    assert by_name.delta_h_corrected_kj_mol == by_model.delta_h_corrected_kj_mol
    assert by_name.correction_reference == by_model.correction_reference is not None
    with pytest.raises(ValueError, match=r"^HeatOfVaporization: model: unknown water model "
                                         "'spc-x'"):
        HeatOfVaporization(energies, 216, 298.0, model="spc-x")
    for bad in (215.6, "216", True, float("nan"), 0):
        with pytest.raises(ValueError, match="n_molecules must be a positive whole number"):
            HeatOfVaporization(energies, bad, 298.0)
