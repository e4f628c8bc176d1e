"""Mass chains against the closed forms of docs/physics.md §2 (flexmm.theory.chains).

Bistable damped fronts (speed and the energy law K = m v Δφ/(2ηa), 1 %), sech² solitary waves of
the softening chain (v − c0 within 2 %), the exact Toda soliton, and Nesterenko's speed–force
exponent 1/6 for the Hertz chain (1 %).
"""

import numpy as np
import pytest
import xarray as xr
from mass_chain_helpers import crossing_times, peak_times, problem_from, run_in_memory

from flexmm.api import run_scene
from flexmm.config import scene_from_dict
from flexmm.theory.chains import (
    bistable_front,
    front_kinetic_energy,
    nesterenko_speed_from_force,
    softening_solitary_wave,
    toda_soliton,
)


@pytest.mark.parametrize("alpha, beta, eta, n", [(0.02, 0.25, 0.05, 400), (0.01, 0.35, 0.03, 700)])
def test_mass_chain_damped_bistable_front_speed_and_energy_law(tmp_path, alpha, beta, eta, n):
    """Nondimensional k = m = a = L = 1, SI scales m = 10 g, k = 100 N/m, a = 1 cm."""
    m, k, a = 0.01, 100.0, 0.01
    T = np.sqrt(m / k)
    theory = bistable_front(alpha, beta, 1.0, 1.0, 1.0, 1.0, eta)
    assert theory.w >= 10
    sc = scene_from_dict({
        "name": "front",
        "lattice": {"kind": "mass_chain", "n_units": n, "spacing_m": a, "mass_kg": m, "left": "driven",
                    "bond": {"law": "linear", "k_n_per_m": k},
                    "onsite": [{"law": "bistable_cubic", "alpha_n_per_m3": alpha * k / a**2, "beta": beta,
                                "jump_m": a}]},
        "excitation": {"kind": "boundary_displacement", "shape": "smooth_step", "amplitude_m": a,
                       "duration_s": 5 * T},
        "damping": {"viscous": {"coefficient_n_s_per_m": eta * m / T}},
        "solver": {"duration_s": 1.2 * (n - 60) / theory.v * T},
        "output": {"n_frames": 600, "velocities": False},
    })
    ds = xr.open_dataset(run_scene(sc, run_dir=tmp_path).path)
    t = ds.time.values / T
    tc = crossing_times(t, ds.u.values / a)
    sites = np.arange(n // 3, n - 100)  # after the trigger's transient (decay time ~ 1/η)
    v = 1.0 / np.polyfit(sites, tc[sites], 1)[0]
    assert v == pytest.approx(theory.v, rel=0.01)
    during = (t > tc[sites[0]]) & (t < tc[sites[-1]])
    K = ds.kinetic_energy.values[during] / (m * a**2 / T**2)
    assert K.mean() == pytest.approx(front_kinetic_energy(1.0, v, theory.dphi, eta, 1.0), rel=0.01)
    assert K.std() < 0.01 * K.mean()  # steady


def test_mass_chain_softening_solitary_wave_speed_excess():
    """Launch the long-wave sech² pulse and compare its measured v − c0 with theory at its amplitude."""
    n, k1, k2 = 1500, 1.0, 1.0
    lat = {"kind": "mass_chain", "n_units": n, "spacing_m": 1.0, "mass_kg": 1.0,
           "bond": {"law": "polynomial", "k1_n_per_m": k1, "k2_n_per_m2": k2}}
    for dm in (0.005, 0.02):
        p = problem_from(lat, 1200.0, solver={"dt_fraction": 0.05})
        w = softening_solitary_wave(k1, k2, dm)
        d = w.profile(np.arange(n - 1) - 100.0)
        p.system.q0[:-1] = -np.cumsum(d[::-1])[::-1]
        p.system.v0[:] = -w.v * w.profile(np.arange(n) - 100.5)
        t, q, _, _ = run_in_memory(p, 1200)
        strain = np.diff(q, axis=1)
        bonds = np.arange(300, 1300)
        v = 1.0 / np.polyfit(bonds, peak_times(t, strain[:, bonds]), 1)[0]
        amp = np.median(strain[:, bonds].max(axis=0))
        assert amp > 0  # tensile: a rarefaction pulse for k2 > 0
        expected = softening_solitary_wave(k1, k2, amp).v
        assert v - 1.0 == pytest.approx(expected - 1.0, rel=0.02)


def test_mass_chain_toda_soliton_matches_exact_solution_second_order():
    n, A, B, kappa = 300, 1.0, 1.0, 1.0
    lat = {"kind": "mass_chain", "n_units": n, "spacing_m": 1.0, "mass_kg": 1.0,
           "bond": {"law": "toda", "a_n": A, "b_per_m": B}}
    bonds = np.arange(n - 1) - 60.0
    errors = []
    for frac in (0.05, 0.025):
        p = problem_from(lat, 100.0, solver={"dt_fraction": frac})
        r0 = toda_soliton(A, B, 1.0, kappa, bonds, 0.0)
        h = 1e-6
        rdot = (toda_soliton(A, B, 1.0, kappa, bonds, h) - toda_soliton(A, B, 1.0, kappa, bonds, -h)) / (2 * h)
        p.system.q0[:-1] = -np.cumsum(r0[::-1])[::-1]
        p.system.v0[:-1] = -np.cumsum(rdot[::-1])[::-1]
        t, q, _, _ = run_in_memory(p, 50)
        exact = toda_soliton(A, B, 1.0, kappa, bonds, t[-1])
        errors.append(np.abs(np.diff(q[-1]) - exact).max() / np.abs(r0).max())
    assert errors[1] < 0.005
    assert errors[0] / errors[1] == pytest.approx(4.0, rel=0.1)  # converges at order 2


def test_mass_chain_hertz_nesterenko_speed_force_exponent():
    """Impacts over a decade and a half of speed: V ∝ F_m^{1/6} (Nesterenko)."""
    lat = {"kind": "mass_chain", "n_units": 200, "spacing_m": 1.0, "mass_kg": 1.0,
           "bond": {"law": "hertz", "stiffness_n_per_m_p": 1.0}}
    forces, speeds = [], []
    for v0 in (0.01, 0.05, 0.3):
        p = problem_from(lat, 240 * v0**-0.2, solver={"dt_s": 0.02 * v0**-0.2},
                         excitation={"kind": "impact", "velocity_m_s": v0})
        t, q, _, _ = run_in_memory(p, 2500)
        t = t * p.system.scales.time_s  # SI (A = 1 N/m^1.5, D = 1 m, m = 1 kg)
        force = np.clip(-np.diff(q, axis=1), 0.0, None) ** 1.5
        bonds = np.arange(60, 160)
        speeds.append(1.0 / np.polyfit(bonds, peak_times(t, force[:, bonds]), 1)[0])
        forces.append(np.median(force[:, bonds].max(axis=0)))
    exponent = np.polyfit(np.log(forces), np.log(speeds), 1)[0]
    assert exponent == pytest.approx(1 / 6, rel=0.01)
    ratio = np.array(speeds) / [nesterenko_speed_from_force(1, 1, 1, f) for f in forces]
    # the discrete solitary wave is ~1 % faster than the long-wave formula at equal peak force
    assert np.ptp(ratio) < 1e-3 and ratio.mean() == pytest.approx(1.0, abs=0.03)
