"""Launched waves with their theory (docs/physics.md §2): the FPU-β (mKdV) sech solitary wave and
the sine-Gordon kink; expected values from the closed-form laws written out here."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from flexmm.analysis.report import analyze as report
from flexmm.api import run_scene
from flexmm.config import ConfigError, load_scene, scene_from_dict

FPU = {"kind": "mass_chain", "n_units": 300, "spacing_m": 0.01, "mass_kg": 0.01,
       "bond": {"law": "polynomial", "k1_n_per_m": 100.0, "k3_n_per_m3": 4.0e6}}


@pytest.mark.parametrize("strain, direction", [(0.05, 1), (-0.05, -1)])
def test_launched_fpu_beta_pulse_runs_at_the_mkdv_speed_with_its_width(tmp_path, strain, direction):
    """D = Dm sech(n/W), W = sqrt(k1/(6 k3))/|Dm| = 4.08 sites, v = c0 sqrt(1 + k3 Dm²/(2 k1)):
    v − c0 (0.25 % of c0) within 6 % (the discrete wave differs at O(1/W²) = 0.06), W within 1 %,
    either polarity, and the analysis row."""
    k1, k3, a, m = 100.0, 4.0e6, 0.01, 0.01
    sc = scene_from_dict({
        "name": "fpu", "solver": {"duration_s": 1.5}, "lattice": FPU,
        "initial": {"launch": [{"kind": "fpu_beta_pulse", "strain": strain, "direction": direction,
                                "center_site": 40 if direction > 0 else 259}]}})
    res = report.analyze_run(run_scene(sc, run_dir=tmp_path / "fpu").path)
    (p,) = res.pulses
    c0, Dm = a * math.sqrt(k1 / m), strain * a
    v = c0 * math.sqrt(1 + k3 * Dm**2 / (2 * k1))
    assert p.direction == direction and p.amplitude == pytest.approx(strain, rel=0.01)
    assert (abs(p.speed_m_s) - c0) / (v - c0) == pytest.approx(1.0, abs=0.06)
    assert p.width_sech_m == pytest.approx(math.sqrt(k1 / (6 * k3)) / abs(Dm) * a, rel=0.01)
    (row,) = [r for r in res.comparisons if r.quantity == "speed"]
    assert "FPU-β" in row.note and abs(row.rel_diff) < 1e-4


def test_fpu_beta_launch_on_a_bond_with_k2_is_an_error(tmp_path):
    f = tmp_path / "k2.yaml"
    f.write_text(yaml.safe_dump({
        "name": "k2", "solver": {"duration_s": 0.1},
        "lattice": {**FPU, "bond": {**FPU["bond"], "k2_n_per_m2": 10.0}},
        "initial": {"launch": [{"kind": "fpu_beta_pulse", "strain": 0.05, "center_site": 40}]}}, sort_keys=False))
    sc = load_scene(f)
    with pytest.raises(Exception, match="k2 = 0"):
        run_scene(sc, run_dir=tmp_path / "k2")


def _kink_scene(onsite, k, eta, n=300, duration=0.05):
    return scene_from_dict({
        "name": "kink", "solver": {"duration_s": duration}, "output": {"n_frames": 201},
        "lattice": {"kind": "mass_chain", "n_units": n, "spacing_m": 0.01, "mass_kg": 0.01, "relax": False,
                    "bond": {"law": "linear", "k_n_per_m": k}, "onsite": onsite},
        "damping": {"viscous": {"coefficient_n_s_per_m": eta}},
        "initial": {"launch": [{"kind": "kink", "center_site": 40}]}})


def _front_speed(res):
    front = max(res.fronts, key=lambda f: f.n_switched)
    rows = [r for r in res.comparisons if r.quantity == "speed" and r.item == f"front {front.index}"]
    return front, rows


def test_driven_damped_sine_gordon_kink_runs_at_the_mclaughlin_scott_speed(tmp_path):
    """ω0 = 2π·100 Hz, w = 8 sites, α = η/(m ω0) = 0.1, γ = Fλ/(2πA) = 0.1:
    v = c/sqrt(1 + (4α/(πγ))²) = 0.618 c (McLaughlin & Scott 1978), within 0.2 %."""
    A, lam, m, a, k = 0.01, 0.01, 0.01, 0.01, 252662.0
    w0 = math.sqrt(A / m) * 2 * math.pi / lam
    alpha, gamma = 0.1, 0.1
    eta, force = alpha * m * w0, gamma * 2 * math.pi * A / lam
    sc = _kink_scene([{"law": "sine", "amplitude_j": A, "period_m": lam},
                      {"law": "constant_force", "force_n": force}], k, eta)
    res = report.analyze_run(run_scene(sc, run_dir=tmp_path / "sg").path)
    front, rows = _front_speed(res)
    v = a * math.sqrt(k / m) / math.sqrt(1 + (4 * alpha / (math.pi * gamma)) ** 2)
    assert front.direction == 1 and front.speed_m_s == pytest.approx(v, rel=2e-3)
    assert len(rows) == 1 and "McLaughlin–Scott" in rows[0].note and abs(rows[0].rel_diff) < 2e-3


def test_driven_damped_phi4_kink_runs_at_its_energy_balance_speed(tmp_path):
    """V = h(1 − (u/L)²)²: F·2L v/a = η v² M/(a sqrt(1 − v²/c²)), M = (4L/3) sqrt(2h/k)/a;
    width L a sqrt(k/(2h)) = 8 sites."""
    m, a, L, h = 0.01, 0.01, 0.002, 0.01
    k = 2 * h * (8 / L) ** 2  # L a sqrt(k/(2h)) = 8 a
    w0 = math.sqrt(8 * h / L**2 / m)
    eta, force = 0.1 * m * w0, 0.05 * 8 * h / L  # a small tilt against the barrier's slope scale
    sc = _kink_scene([{"law": "phi4", "barrier_j": h, "half_distance_m": L},
                      {"law": "constant_force", "force_n": force}], k, eta, duration=0.1)
    res = report.analyze_run(run_scene(sc, run_dir=tmp_path / "phi4").path)
    front, rows = _front_speed(res)
    c, M = a * math.sqrt(k / m), 4 * L / 3 * math.sqrt(2 * h / k) / a
    q = force * 2 * L / (eta * M)
    v = q / math.sqrt(1 + (q / c) ** 2)
    assert front.direction == 1 and front.speed_m_s == pytest.approx(v, rel=5e-3)
    assert len(rows) == 1 and "φ⁴" in rows[0].note and abs(rows[0].rel_diff) < 5e-3


def test_launched_kdv_pulse_on_a_precompressed_hertz_chain(tmp_path):
    """Static load F0: ξ0 = (F0/A)^(2/3)/D; excess strain ε ξ0 sech²(n/W), W = sqrt(2/ε), at
    V = c0 sqrt(1 + ε/6), c0² = (3/2)(A D^(5/2)/m) ξ0^(1/2) (Nesterenko's law, first order in ε)."""
    A, D, m, F0, eps = 4.88e9, 0.00476, 4.5e-4, 2.0, 0.2
    sc = scene_from_dict({
        "name": "kdv", "solver": {"duration_s": 6e-4},
        "lattice": {"kind": "mass_chain", "n_units": 160, "spacing_m": D, "mass_kg": m,
                    "bond": {"law": "hertz", "stiffness_n_per_m_p": A, "exponent": 1.5}, "static_load_n": F0},
        "initial": {"launch": [{"kind": "hertz_kdv_pulse", "amplitude_ratio": eps, "center_site": 30}]}})
    res = report.analyze_run(run_scene(sc, run_dir=tmp_path / "kdv").path)
    p = res.pulses[0]
    xi0 = (F0 / A) ** (2 / 3) / D
    c0 = math.sqrt(1.5 * A * D**2.5 / m * math.sqrt(xi0))
    assert p.direction == 1 and p.amplitude == pytest.approx(-eps * xi0, rel=0.03)
    assert abs(p.speed_m_s) == pytest.approx(c0 * math.sqrt(1 + eps / 6), rel=3e-3)
    assert p.width_sech2_m == pytest.approx(math.sqrt(2 / eps) * D, rel=0.05)
    (row,) = [r for r in res.comparisons if r.item == "pulse 0" and r.quantity == "speed"]
    assert "precompressed" in row.note and abs(row.rel_diff) < 3e-3


def _toda_two_soliton_stretch(a, b, m, k1, k2, c1, c2, n, t):
    """r_n(t) from τ_n = 1 + e^η1 + e^η2 + A12 e^(η1+η2), e^(−b r_n) = τ_(n+1) τ_(n−1)/τ_n² (head-on:
    soliton 1 from the left moving right), η_i = 2κ_i(n − c_i) ∓ 2 sinh κ_i sqrt(ab/m) t, soliton 2's
    phase less ln A12 (soliton 1 lies on its left), written out from docs/physics.md §2."""
    s1, s2 = math.sinh(k1), math.sinh(k2)
    A12 = -((s1 + s2) ** 2 - math.sinh(k1 - k2) ** 2) / ((s1 - s2) ** 2 - math.sinh(k1 + k2) ** 2)
    w = math.sqrt(a * b / m) * t
    def ln_tau(j):
        e1 = 2 * k1 * (j - c1) - 2 * s1 * w
        e2 = 2 * k2 * (j - c2) + 2 * s2 * w - math.log(A12)
        return np.logaddexp.reduce([np.zeros_like(j), e1, e2, math.log(A12) + e1 + e2])
    return -(ln_tau(n + 1) + ln_tau(n - 1) - 2 * ln_tau(n)) / b


def test_exact_toda_two_soliton_launched_mid_collision_evolves_as_the_exact_solution(tmp_path):
    """Launched overlapping (asymptotic centres on the same site, where the sum of two single
    solitons is off by 11 % of the peak), the chain follows the exact two-soliton through and
    after the collision, to 1e-4 of the peak."""
    import xarray as xr

    a, b, m, k1, k2, c1, c2, T = 1.0, 100.0, 0.01, 1.0, 0.5, 150.0, 150.0, 0.3
    sc = scene_from_dict({
        "name": "toda2", "solver": {"duration_s": T, "accuracy": 1e-7}, "output": {"n_frames": 31},
        "lattice": {"kind": "mass_chain", "n_units": 300, "spacing_m": 0.01, "mass_kg": m,
                    "bond": {"law": "toda", "a_n": a, "b_per_m": b}},
        "initial": {"launch": [{"kind": "toda_two_soliton", "kappa": [k1, k2], "center_site": [c1, c2],
                                "direction": [1, -1]}]}})
    with xr.open_dataset(run_scene(sc, run_dir=tmp_path / "t2").path) as ds:
        u = ds["u"].values
    n = np.arange(299) + 0.5  # bond n joins sites n and n+1
    for j, t in ((0, 0.0), (10, 0.1), (30, T)):
        exact = _toda_two_soliton_stretch(a, b, m, k1, k2, c1, c2, n, t)
        assert np.max(np.abs(np.diff(u[j]) - exact)) < 1e-4 * np.max(np.abs(exact)), t
    single = lambda k, c: -np.log1p(math.sinh(k) ** 2 / np.cosh(k * (n - c)) ** 2) / b  # noqa: E731
    r0 = _toda_two_soliton_stretch(a, b, m, k1, k2, c1, c2, n, 0.0)
    assert np.max(np.abs(r0 - single(k1, c1) - single(k2, c2))) > 0.1 * np.max(np.abs(r0))
