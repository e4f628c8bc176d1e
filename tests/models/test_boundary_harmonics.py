"""Frequency-doubled reflection from a rotating-squares end (configs/rotating_boundary_frequency_doubling.yaml)
against second-order perturbation theory of the boundary (docs/physics.md §1.7).

Slow: runs the scene twice (two amplitudes). docs/scenes.md lists the measured numbers.
"""
import math

import numpy as np
import pytest
from rigid_scene_checks import run

from flexmm.analysis.measure.reflection import complex_amplitudes, running_waves
from flexmm.models.rotating_chain import build
from flexmm.theory.boundary_harmonics import boundary_reflection

pytestmark = pytest.mark.slow

NAME = "rotating_boundary_frequency_doubling"
SITES = np.arange(150, 291)  # inside the straight chain, away from the end
WINDOW = (0.155, 0.195)  # s: the reflection has arrived, the shaker's re-reflection not yet


def measured(tmp_path, amplitude_m):
    scene, ds, _ = run(NAME, tmp_path / f"{amplitude_m:g}", [f"excitation.amplitude_m={amplitude_m}"])
    lat, f = scene.lattice, scene.excitation.frequency_hz
    w0 = math.sqrt(lat.k_long_n_per_m / lat.mass_kg)
    waves = {}
    for k in (1, 2):
        q = 2 * math.asin(2 * math.pi * k * f / (2 * w0))  # straight chain: ω = 2 ω0 sin(q/2)
        y = complex_amplitudes(ds.time.values, ds.u.values, k * f, *WINDOW)
        waves[k] = running_waves(y, SITES, q)
    return scene, waves


def theory(scene, amplitude_m):
    system = build(scene.lattice)
    sc = system.scales

    def force(q):
        out = np.zeros_like(q)
        system.force(q, system.args, out)
        return out

    omega = 2 * math.pi * scene.excitation.frequency_hz * sc.time_s
    return boundary_reflection(force, system.q0.copy(), system.mass, 0, omega, amplitude_m / sc.length_m,
                               1.0, 1.0, free=system.inv_mass > 0), sc.length_m


def test_reflected_second_harmonic_scales_with_square_and_matches_theory(tmp_path):
    amps = (2.5e-5, 1.0e-5)
    r2 = {}
    for a in amps:
        scene, waves = measured(tmp_path, a)
        th, length = theory(scene, a)
        # the incident wave is the shaker's; the end reflects it totally (|r1| = 1 to first order)
        assert abs(waves[1].right) == pytest.approx(a, rel=0.005)
        assert abs(waves[1].left) == pytest.approx(abs(th.r1) * length, rel=0.005)
        # the 800 Hz wave runs only away from the end: nothing comes in at 2f
        assert abs(waves[2].right) < 0.01 * abs(waves[2].left)
        r2[a] = abs(waves[2].left)
        tol = 0.04 if a > 2e-5 else 0.015  # the next order grows with the amplitude
        assert r2[a] == pytest.approx(abs(th.r2) * length, rel=tol)
    exponent = math.log(r2[amps[0]] / r2[amps[1]]) / math.log(amps[0] / amps[1])
    assert exponent == pytest.approx(2.0, abs=0.04)
