"""The `boundary_force` excitation: a force (or moment) pulse on an end that holds no DOF.

Checks that can fail: the impulse a force pulse hands a free chain (total momentum after the pulse
= ∫F dt = 2 F T/π for a half sine, with the sign of the end's inward normal), the energy ledger
(recorded work = energy gained), the drive rows in SI (a moment is a generalised force on the
staggered rotation, scaled by k_l a²), and that it drives a predeformed (loaded, displaced) end,
which a prescribed displacement refuses.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import xarray as xr

from flexmm.api import run_scene
from flexmm.assemble import SceneError, build_problem
from flexmm.config import ConfigError, scene_from_dict
from flexmm.integrators.common import MODE_FORCE, SHAPES

MASS, N = 0.01, 40


def _chain(excitation: dict) -> dict:
    lat = {"kind": "mass_chain", "n_units": N, "spacing_m": 0.01, "mass_kg": MASS,
           "bond": {"law": "polynomial", "k1_n_per_m": 100.0, "k2_n_per_m2": 2000.0}}
    return {"name": "pulse", "lattice": lat, "excitation": excitation,
            "solver": {"duration_s": 0.05, "accuracy": None, "dt_s": 2e-5}, "output": {"n_frames": 51}}


@pytest.mark.parametrize("end, sign", [("left", 1.0), ("right", -1.0)])
def test_force_pulse_hands_the_chain_its_impulse(tmp_path, end, sign) -> None:
    F, T = 0.5, 0.01
    exc = {"kind": "boundary_force", "end": end, "shape": "half_sine", "amplitude_n": F, "duration_s": T}
    ds = xr.load_dataset(run_scene(scene_from_dict(_chain(exc)), run_dir=tmp_path / end).path)
    after = ds["time"].values > T
    momentum = MASS * ds["u_dot"].values[after].sum(axis=1)  # kg m/s, every frame after the pulse
    assert momentum == pytest.approx(sign * 2 * F * T / math.pi, rel=1e-4)  # into the lattice
    gained = ds["total_energy"].values - ds["total_energy"].values[0]
    assert ds["applied_work"].values[-1] > 0
    assert gained == pytest.approx(ds["applied_work"].values, abs=1e-4 * ds["applied_work"].values[-1])


PREDEFORMED = {"kind": "rotating_squares_chain", "n_units": 60, "a_m": 0.016, "theta0_rad": 0.05,
               "k_long_n_per_m": 71690, "k_shear_n_per_m": 1326.98, "k_rot_n_m_per_rad": 7.038e-4,
               "mass_kg": 4.52e-3, "inertia_kg_m2": 8.7814e-8, "n_lateral": 1,
               "predeform": {"loads": [{"end": "left", "force_n": 0.2}, {"end": "right", "force_n": 0.2}],
                             "theta_guess_rad": 0.1}}


def _loaded(excitation: dict) -> dict:
    return {"name": "loaded", "lattice": PREDEFORMED, "excitation": excitation,
            "solver": {"duration_s": 0.01, "accuracy": None, "dt_s": 2.5e-5}, "output": {"n_frames": 41}}


def test_moment_pulse_rows_in_si_and_a_predeformed_end_is_driven() -> None:
    M, T = -0.004, 0.003
    exc = {"kind": "boundary_force", "shape": "gaussian", "amplitude_n_m": M, "duration_s": T}
    problem = build_problem(scene_from_dict(_loaded(exc)))
    system, terms = problem.system, problem.terms
    rot = system.dof(system.rotation_field, system.ends["left"][0])
    d = int(np.flatnonzero(terms.drv_dof == rot)[0])
    assert terms.drv_mode[d] == MODE_FORCE and terms.drv_shape[d] == SHAPES["gaussian"]
    k_l_a2 = PREDEFORMED["k_long_n_per_m"] * PREDEFORMED["a_m"] ** 2  # N m: the energy scale
    tau = math.sqrt(PREDEFORMED["mass_kg"] / PREDEFORMED["k_long_n_per_m"])  # s: the time scale
    sigma = T / (2 * math.sqrt(2 * math.log(2)))  # the FWHM T as a standard deviation
    assert terms.drv_prm[d, :3] == pytest.approx([M / k_l_a2, sigma / tau, 2 * T / tau], rel=1e-12)
    assert system.inv_mass[rot] > 0  # the end keeps its inertia: nothing is held
    assert abs(system.q0[rot] - system.rest_state[rot]) < 1e-15 and abs(system.q0[rot]) > 0.1  # displaced end
    with pytest.raises(SceneError, match="predeformed"):  # a prescribed rotation cannot start from it
        build_problem(scene_from_dict(_loaded({"kind": "boundary_displacement", "amplitude_rad": -0.1,
                                               "duration_s": T})))


def test_moment_pulse_on_a_loaded_end_keeps_the_energy_ledger(tmp_path) -> None:
    exc = {"kind": "boundary_force", "shape": "gaussian", "amplitude_n_m": -0.004, "duration_s": 0.003}
    ds = xr.load_dataset(run_scene(scene_from_dict(_loaded(exc)), run_dir=tmp_path / "m").path)
    rest = ds["theta"].values[0]
    assert np.abs(ds["theta"].values[-1] - rest).max() > 0.01  # the moment moved the end units
    gained = ds["total_energy"].values - ds["total_energy"].values[0]
    work = ds["applied_work"].values
    assert work.max() > 0
    assert gained == pytest.approx(work, abs=1e-3 * work.max())


@pytest.mark.parametrize("amplitudes, error, fragment", [
    ({"amplitude_n": 0.5, "amplitude_n_m": 0.001}, ConfigError,
     "excitation.amplitude_n: expected: give exactly one of amplitude_n (force) or amplitude_n_m (moment)"),
    ({}, ConfigError, "excitation: expected: give exactly one of amplitude_n (force) or amplitude_n_m (moment)"),
    ({"amplitude_n_m": 0.001}, SceneError, "amplitude_n_m needs a rotation field; model 'mass_chain' has none")])
def test_amplitude_errors_name_the_field(amplitudes, error, fragment) -> None:
    """Both a force and a moment, neither, or a moment on a model without rotations (a mass chain):
    user errors (FlexmmError) that name the field."""
    from flexmm.errors import FlexmmError

    exc = {"kind": "boundary_force", "end": "left", "duration_s": 0.01, **amplitudes}
    with pytest.raises(error) as err:
        build_problem(scene_from_dict(_chain(exc)))
    assert isinstance(err.value, FlexmmError) and fragment in str(err.value), str(err.value)
