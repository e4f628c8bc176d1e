"""Cnoidal waves with m > 0.9 from a displacement shaker (configs/rotating_cnoidal_displacement_shaker.yaml)
against flexmm.theory.cnoidal, closed by the measured mean rotation (wave_with_mean).

Slow: runs the scene at two amplitudes. docs/scenes.md lists the measured numbers.
"""
import math

import numpy as np
import pytest
from rigid_scene_checks import run

from flexmm.analysis.measure.periodic import measure_periodic_wave
from flexmm.theory.cnoidal import linear_speed, wave_with_mean
from flexmm.theory.rotating import RotatingChainND

pytestmark = pytest.mark.slow

NAME = "rotating_cnoidal_displacement_shaker"


def measure(tmp_path, amplitude_m):
    scene, ds, _ = run(NAME, tmp_path / f"{amplitude_m:g}", [f"excitation.amplitude_m={amplitude_m}"])
    lat, f = scene.lattice, scene.excitation.frequency_hz
    p = RotatingChainND.from_si(lat.a_m, lat.theta0_rad, lat.k_long_n_per_m, lat.k_shear_n_per_m,
                                lat.k_rot_n_m_per_rad, lat.mass_kg, lat.inertia_kg_m2, n_v=lat.n_lateral)
    T = math.sqrt(lat.mass_kg / lat.k_long_n_per_m)
    omega = 2 * math.pi * f * T
    out = []
    for first in (20, 120):  # two stretches of 100 units (1.3 coherence lengths of the free 2f wave)
        wave = measure_periodic_wave(ds.theta.values, ds.time.values, f, np.arange(first, first + 100))
        theory = wave_with_mean(p, omega, wave.amplitude, wave.mean)
        out.append((wave, theory, wave.sites_per_s * T, theory.c / p.eta))
    return out, linear_speed(p, omega) / p.eta


def test_displacement_shaker_makes_cnoidal_waves_beyond_m_09(tmp_path):
    strong, c_lin = measure(tmp_path, 2.5e-3)
    for wave, theory, c, c_th in strong:
        assert theory.wave.m > 0.9  # the soliton-train regime
        assert c == pytest.approx(c_th, rel=0.015)  # phase speed
        assert c_lin - c == pytest.approx(c_lin - c_th, rel=0.15)  # the amplitude dispersion itself
        mean, h1, h2, h3 = theory.wave.harmonics(3)
        assert wave.bound_ratios[0] == pytest.approx(h2 / h1, rel=0.15)  # sharp crests, flat troughs
        assert wave.crest - wave.mean > 1.5 * (wave.mean - wave.trough)
    weak, _ = measure(tmp_path, 1.0e-3)
    for wave, theory, c, c_th in weak:
        assert 0.75 < theory.wave.m < 0.88
        assert c == pytest.approx(c_th, rel=0.02)
        mean, h1, h2, h3 = theory.wave.harmonics(3)
        assert wave.bound_ratios[0] == pytest.approx(h2 / h1, rel=0.2)
