"""The predeformed rotating-squares scenes against theory (slow: each runs a scene).

Rarefaction soliton: the discrete, relaxed and loaded chain carries the soliton of
flexmm.theory.prestressed at its predicted speed and shape. Cnoidal shaker: the steady periodic
rotation at a site away from the drive against flexmm.theory.cnoidal. docs/scenes.md quotes the
measured values.
"""

import math

import numpy as np
import pytest
from scipy import optimize
from rigid_scene_checks import peak, run

from flexmm.analysis import analyze_run
from flexmm.analysis.context import RunContext
from flexmm.analysis.measure.periodic import measure_periodic_wave
from flexmm.analysis.features.rest import from_rest, rest_fields
from flexmm.theory.cnoidal import driven_wave, linear_speed
from flexmm.theory.prestressed import prestressed_chain, static_rotation
from flexmm.theory.rotating import (RotatingChainND, dispersion_chain, exact_soliton, soliton_initial_state,
                                    soliton_speed)

pytestmark = pytest.mark.slow


def _chain(lat) -> RotatingChainND:
    return RotatingChainND.from_si(lat.a_m, lat.theta0_rad, lat.k_long_n_per_m, lat.k_shear_n_per_m,
                                   lat.k_rot_n_m_per_rad, lat.mass_kg, lat.inertia_kg_m2, lat.n_lateral,
                                   int(lat.lateral_stretch))


def _fwhm(row: np.ndarray) -> float:
    """Full width at half of the largest |value|, linearly interpolated (sites)."""
    y = np.abs(row)
    k, half = int(np.argmax(y)), 0.5 * np.abs(row).max()
    lo, hi = k, k
    while y[lo - 1] > half:
        lo -= 1
    while y[hi + 1] > half:
        hi += 1
    left = lo - (y[lo] - half) / (y[lo] - y[lo - 1])
    right = hi + (y[hi] - half) / (y[hi] - y[hi + 1])
    return right - left


def _exact_fwhm_sites(p: RotatingChainND, A: float) -> float:
    z = np.linspace(-60.0, 60.0, 120001)
    th = exact_soliton(p, A, z)[0]
    return float(np.ptp(z[np.abs(th) > 0.5 * abs(A)])) / p.eta


def _loaded(lat) -> RotatingChainND:
    """The theory's chain about the uniform equilibrium under the config's (symmetric) end load."""
    p0 = _chain(lat)
    return prestressed_chain(p0, static_rotation(p0, lat.predeform.loads[0].force_n / (lat.k_long_n_per_m * lat.a_m)))


@pytest.fixture(scope="module")
def rarefaction(tmp_path_factory):
    """rarefaction(A): the scene run at launched amplitude A (each amplitude runs once)."""
    runs = {}

    def get(amplitude: float) -> dict:
        if amplitude not in runs:
            runs[amplitude] = _rarefaction(tmp_path_factory.mktemp("rarefaction"), amplitude)
        return runs[amplitude]

    return get


def _rarefaction(tmp_path, amplitude: float) -> dict:
    """Run the scene at a launched amplitude; measure the pulse on top of the relaxed state."""
    scene, ds, result = run("predeformed_rarefaction_soliton", tmp_path / f"A{amplitude}",
                            [f"excitation.amplitude_rad={amplitude}"])
    lat = scene.lattice
    rest = rest_fields(RunContext.from_dataset(ds))
    moved = from_rest(ds, rest)
    theta, u = moved["theta"].values, moved["u"].values / lat.a_m
    t = ds["time"].values / math.sqrt(lat.mass_kg / lat.k_long_n_per_m)
    half = t > 0.2 * t[-1]  # after the launch transients
    rows = [peak(r) for r in theta[half]]
    pos, amp = np.array([r[0] for r in rows]), np.array([r[1] for r in rows])
    return {"lat": lat, "theta_rest": rest["theta"], "amp": amp,
            "speed": np.polyfit(t[half], pos, 1)[0],  # units per sqrt(m/k_l)
            "fwhm": np.mean([_fwhm(r) for r in theta[half]]),
            "rotation_sign": np.sign(amp.mean()) * np.sign(rest["theta"][lat.n_units // 2]),
            "strain": np.diff(u[half], axis=1).max(),  # tensile peak, per unit
            "analysis": analyze_run(result.path)}


def test_scene_predeformed_rarefaction_soliton_follows_prestressed_theory(rarefaction):
    """A rarefaction vector soliton keeps its amplitude and moves at the prestressed law's speed."""
    r = rarefaction(-0.38)
    lat = r["lat"]
    p = _loaded(lat)
    assert r["theta_rest"][lat.n_units // 2] == pytest.approx(p.theta_s, abs=1e-4)  # relaxed = uniform theory
    A = r["amp"].mean()
    assert np.ptp(r["amp"]) < 0.01 * abs(A) and A == pytest.approx(-0.38, rel=0.01)  # steady shape
    assert r["rotation_sign"] < 0  # rotates against the predeformation ...
    per_site = max(np.diff(soliton_initial_state(p, A, 60, 30 + k / 20).U).max() for k in range(20))
    assert r["strain"] == pytest.approx(per_site, rel=0.05)  # ... with a tensile strain pulse
    c = float(soliton_speed(p, A)) / p.eta
    assert r["speed"] == pytest.approx(c, rel=0.02)
    assert r["fwhm"] == pytest.approx(_exact_fwhm_sites(p, A), rel=0.03)
    rows = {c.quantity: c for c in r["analysis"].comparisons}  # flexmm analyze: from the rest state
    assert abs(rows["speed"].rel_diff) < 0.02 and abs(rows["FWHM"].rel_diff) < 0.03


def test_scene_predeformed_rarefaction_solitons_speed_up_with_amplitude(rarefaction):
    """Unlike compressive solitons, rarefaction ones get faster with amplitude, as the law predicts.

    c(A) is steep here (dc/dA ≈ 10 per rad at A = −0.37), so the speed at the measured amplitude is
    within 3 %, and the amplitude the law gives at the measured speed within 0.5 %.
    """
    big, small = rarefaction(-0.38), rarefaction(-0.37)
    p = prestressed_chain(_chain(big["lat"]), float(big["theta_rest"][big["lat"].n_units // 2]))
    c_big, c_small = (float(soliton_speed(p, r["amp"].mean())) / p.eta for r in (big, small))
    for r, c in ((big, c_big), (small, c_small)):
        assert r["speed"] == pytest.approx(c, rel=0.03)
        A_at_speed = optimize.brentq(lambda a: float(soliton_speed(p, a)) / p.eta - r["speed"], -0.4, -0.36)
        assert r["amp"].mean() == pytest.approx(A_at_speed, rel=0.005)
    assert big["speed"] / small["speed"] == pytest.approx(c_big / c_small, rel=0.03)
    assert big["speed"] > 1.2 * small["speed"]


# ---------------------------------------------------------------- cnoidal waves
def _cnoidal(tmp_path, amplitude_n: float):
    """(measured PeriodicWave at units 20-120, theory DrivenWave at its amplitude, chain, omega, T)."""
    scene, ds, _ = run("predeformed_cnoidal_shaker", tmp_path / f"F{amplitude_n}",
                       [f"excitation.amplitude_n={amplitude_n}"])
    lat = scene.lattice
    moved = from_rest(ds, rest_fields(RunContext.from_dataset(ds)))
    f, T = scene.excitation.frequency_hz, math.sqrt(lat.mass_kg / lat.k_long_n_per_m)
    wave = measure_periodic_wave(moved["theta"].values, ds["time"].values, f, np.arange(20, 121))
    p, omega = _loaded(lat), 2 * math.pi * f * T
    return wave, driven_wave(p, omega, wave.amplitude), p, omega, T


def test_scene_predeformed_cnoidal_wave_matches_theory(tmp_path):
    """Strong drive: slower than the linear wave by the predicted amount, rectified mean rotation,
    sharp crests and flat troughs as the cnoidal solution; weak drive: the linear sinusoid."""
    wave, theory, p, omega, T = _cnoidal(tmp_path, 0.15)
    c_lin = linear_speed(p, omega) / p.eta
    c_meas, c_th = wave.sites_per_s * T, theory.c / p.eta
    mean, h1, h2 = theory.wave.harmonics(2)
    assert c_meas == pytest.approx(c_th, rel=0.02)
    assert c_lin - c_meas == pytest.approx(c_lin - c_th, rel=0.1)  # the amplitude dispersion itself
    assert wave.mean == pytest.approx(mean, rel=0.08)
    assert wave.bound_ratios[0] == pytest.approx(h2 / h1, rel=0.25)
    asym = (wave.crest - wave.mean) / (wave.mean - wave.trough)
    assert asym == pytest.approx((theory.wave.crest - mean) / (mean - theory.wave.trough), rel=0.15)

    weak, theory_weak, _, _, _ = _cnoidal(tmp_path, 0.005)
    assert weak.sites_per_s * T == pytest.approx(c_lin, rel=0.003)
    q = weak.wavenumber  # against the exact discrete dispersion, not the continuum
    assert float(dispersion_chain(p, q)[0]) == pytest.approx(omega, rel=0.005)
    assert weak.bound_ratios[0] < 0.02 and theory_weak.wave.m < 0.1 * theory.wave.m
