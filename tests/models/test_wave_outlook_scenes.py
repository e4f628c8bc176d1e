"""The outlook's waves (harmonic generation, breathers, envelope solitons) in their shipped scenes, against theory.

Slow: each test runs a scene. docs/scenes.md lists the measured numbers.
"""
import math

import numpy as np
import pytest
from mass_chain_scene_checks import run

from flexmm.analysis.measure.breathers import site_oscillation
from flexmm.analysis.features.envelope import envelope_track
from flexmm.analysis.measure.harmonics import harmonic_profiles
from flexmm.models.mass_chain import build
from flexmm.theory.breathers import SineGordonBreather, breather_frequency, frenkel_kontorova_scales
from flexmm.theory.envelope import SECH_FWHM, envelope_soliton
from flexmm.theory.harmonics import fpu_second_harmonic
from flexmm.theory.rotating import RotatingChainND

pytestmark = pytest.mark.slow


def test_scene_second_harmonic_grows_and_beats_as_perturbation_theory(tmp_path):
    scene, ds = run("fpu_second_harmonic_shaker", tmp_path)
    lat, exc = scene.lattice, scene.excitation
    t, u = ds.time.values, ds.u.values
    h1, h2 = harmonic_profiles(t, u, exc.frequency_hz, 0.4, 0.6, orders=(1, 2))
    theory = fpu_second_harmonic(exc.amplitude_m, 2 * math.pi * exc.frequency_hz, lat.bond.k1_n_per_m,
                                 lat.bond.k2_n_per_m2, lat.mass_kg)
    sites = np.arange(0, 281)
    h1, h2 = h1[sites], h2[sites]
    expected = theory.amplitude(sites)
    peak = expected.max()
    assert np.allclose(h1, exc.amplitude_m, rtol=0.005)  # the fundamental is undepleted
    # linear growth near the drive: the slope over the first 10 sites within 1 %
    slope = np.polyfit(sites[:11], h2[:11], 1)[0]
    assert slope == pytest.approx(np.polyfit(sites[:11], expected[:11], 1)[0], rel=0.01)
    # the first beat: maximum and zero where the theory puts them
    first = sites < 1.5 * 2 * theory.coherence_length
    assert h2[first].max() == pytest.approx(expected[first].max(), rel=0.02)
    assert abs(sites[first][np.argmax(h2[first])] - theory.coherence_length) <= 2
    assert abs(sites[first][np.argmin(h2[first][10:]) + 10] - 2 * theory.coherence_length) <= 2
    # the whole profile over three beats: within 10 % of the peak everywhere
    assert np.max(np.abs(h2 - expected)) < 0.1 * peak


def test_scene_breather_frequency_amplitude_and_energy_as_sine_gordon(tmp_path):
    scene, ds = run("sine_gordon_breather", tmp_path)
    lat = scene.lattice
    sub = lat.onsite[0]
    omega0, ell = frenkel_kontorova_scales(lat.bond.k_n_per_m, lat.mass_kg, sub.amplitude_j, sub.period_m)
    x0 = build(lat).initial_displacement_m  # u is measured from the released state
    t = ds.time.values
    phi = 2 * np.pi * (ds.u.values + x0) / sub.period_m
    centre = lat.n_units // 2
    early, late = (t > 0.05) & (t < 0.25), t > 0.4
    first, last = (site_oscillation(t[w], phi[w, centre]) for w in (early, late))
    omega = 2 * np.pi * last.frequency_hz / omega0
    assert last.n_periods >= 30 and 0.5 < omega < 0.95  # a breather, well inside the gap
    assert last.peak == pytest.approx(first.peak, rel=0.005)  # steady
    assert omega == pytest.approx(breather_frequency(last.peak), rel=0.002)  # ω = cos(A/4)
    # energy left in the breather (the radiation has gone into the absorbing ends): 16 ν A_s ℓ
    energy = ds.total_energy.values[late].mean()
    assert energy == pytest.approx(SineGordonBreather(omega, ell).energy * sub.amplitude_j, rel=0.005)
    # localised: four widths out, the oscillation is the breather's sech tail (radiation gone)
    width = ell / math.sqrt(1 - omega**2)
    far = np.abs(phi[late][:, centre + int(4 * width)]).max()
    assert far < 1.5 * 4 * math.atan(math.sqrt(1 - omega**2) / omega / math.cosh(4.0))


def _envelope(tmp_path, overrides=()):
    scene, ds = run("rotating_envelope_soliton", tmp_path, list(overrides), tag=str(len(overrides)))
    track = envelope_track(ds.time.values, ds.theta.values[:, :780])  # before the absorbing layer
    return scene, track


def test_scene_envelope_soliton_against_nonlinear_schroedinger(tmp_path):
    scene, strong = _envelope(tmp_path)
    lat, exc = scene.lattice, scene.excitation
    p = RotatingChainND.from_si(lat.a_m, lat.theta0_rad, lat.k_long_n_per_m, lat.k_shear_n_per_m,
                                lat.k_rot_n_m_per_rad, lat.mass_kg, lat.inertia_kg_m2, lat.n_lateral)
    T = math.sqrt(lat.mass_kg / lat.k_long_n_per_m)
    nls = envelope_soliton(p, 2 * math.pi * exc.frequency_hz * T)
    assert nls.focusing
    late = strong.time >= 3.0
    product = strong.amplitude[late] * strong.fwhm[late] / SECH_FWHM  # θ_m L
    assert product.mean() == pytest.approx(nls.product, rel=0.05)
    assert np.ptp(strong.fwhm[late]) < 0.1 * strong.fwhm[late].mean()  # it keeps its width
    assert strong.speed(2.0, 4.5) * T == pytest.approx(nls.group_velocity, rel=0.01)
    _, weak = _envelope(tmp_path, ["excitation.amplitude_rad=0.001"])
    early = np.argmin(np.abs(weak.time - 0.5))
    assert weak.fwhm[-5] > 3 * weak.fwhm[early]  # the linear burst spreads
