"""Every shipped rigid-unit scene shows its phenomenon, in numbers (slow: each runs a scene).

Measurements live in rigid_scene_checks.py; docs/scenes.md quotes the measured values.
"""

import math

import numpy as np
import pytest
from conftest import LEGO_PARAMETERS
from rigid_scene_checks import (
    front_positions,
    row_fields,
    run,
    run_edited,
    sound_bullet,
    track,
    wall_position,
)

from flexmm.analysis.measure.oblique import fold_axis, wave_groups
from flexmm.linear.sheet import acoustic_modes
from flexmm.sweep.observe import observe_run
from flexmm.theory.rotating import (
    RotatingChainND,
    amplitude_gap,
    lego_parameters,
    soliton_speed,
)

pytestmark = pytest.mark.slow
LEGO_T = (LEGO_PARAMETERS["mass_kg"] / LEGO_PARAMETERS["k_long_n_per_m"]) ** 0.5  # time unit sqrt(m/k_l) of the LEGO chain (s)


# ---------------------------------------------------------------- (a) 2D rotating squares
def test_scene_a_planar_vector_soliton_keeps_speed_and_shape(tmp_path):
    scene, ds, _ = run("a_sheet_planar_vector_soliton", tmp_path)
    theta = row_fields(ds, "theta")[:, 0, :]
    t = ds["time"].values
    times, pos, amp = track(theta, t, 20, 290, 0.6 * t[-1], t[-1])  # once the pulse has formed
    speed = np.polyfit(times, pos, 1)[0] / (1e4 / 1e-3) ** 0.5  # units of c0 = a sqrt(k_l/m)
    assert np.ptp(amp) < 0.05 * amp.mean()  # constant amplitude (it breathes by ≈ ±2 %)
    assert 0.3 < amp.mean() < 0.4
    assert 0.7 < speed < 0.85  # subsonic
    fit = np.polyval(np.polyfit(times, pos, 1), times)
    assert np.max(np.abs(pos - fit)) < 1.0  # constant speed, within a unit
    u = row_fields(ds, "u")[-1, 0, :]
    assert np.min(np.diff(u)) < -0.05 * scene.lattice.a_m  # a compression pulse travels with it


def test_scene_a_sound_bullet_stays_collimated(tmp_path):
    r = sound_bullet(tmp_path)
    theta_w, strain_w = np.asarray(r["theta_width"]), np.asarray(r["strain_width"])
    assert np.all(theta_w <= 20)  # the rotation beam stays ≈ the 11-unit push wide over 100 units
    assert np.all(np.asarray(r["theta_peak"]) > 0.2)
    assert strain_w[-1] > theta_w[-1]  # while the compression it travels with spreads


def test_scene_a_oblique_push_separates_into_the_two_acoustic_modes(tmp_path):
    """At 26.6° to the lattice axes the push splits into a fast and a slow group whose speeds and
    polarisations are those of the sheet's two long-wave acoustic modes (Bloch analysis of the
    Hessian, flexmm.linear.sheet); along the x axis it stays one longitudinal group."""
    scene, ds, result = run("a_sheet_mode_separation", tmp_path)
    lat = scene.lattice
    c0 = lat.a_m * math.sqrt(lat.k_long_n_per_m / lat.unit_mass_kg)
    (c_slow, p_slow), (c_fast, p_fast) = acoustic_modes(lat, math.atan2(lat.skew_cols, lat.n_rows))
    fast, slow = wave_groups(ds)  # exactly two groups
    assert fast.speed_m_s == pytest.approx(c_fast * c0, rel=0.03)
    assert slow.speed_m_s == pytest.approx(c_slow * c0, rel=0.03)
    assert abs(fold_axis(fast.polarisation_deg - p_fast)) < 4.0
    assert abs(fold_axis(slow.polarisation_deg - p_slow)) < 4.0
    assert min(fast.energy_fraction, slow.energy_fraction) > 0.1
    assert fast.position_m - slow.position_m > 100 * lat.a_m  # separated by > 100 spacings
    assert np.abs(ds["theta"].values[-1]).max() > 0.05  # both carry rotation: vector waves
    obs = observe_run(result.path)  # what a sweep over such scenes records: the fast group
    assert obs["kind"] == "modes" and obs["speed"] == pytest.approx(fast.speed_m_s, rel=1e-12)
    assert obs["speed_theory"] == pytest.approx(c_fast * c0, rel=1e-9)

    _, ds, _ = run("a_sheet_mode_separation", tmp_path / "axis", ["lattice.skew_cols=0", "excitation.angle_deg=0"])
    groups = wave_groups(ds)
    (_, _), (c_long, _) = acoustic_modes(lat.model_copy(update={"skew_cols": 0}), 0.0)
    assert groups and all(abs(g.polarisation_deg) < 5.0 for g in groups)  # longitudinal only
    assert all(g.speed_m_s > 0.85 * c_long * c0 for g in groups)  # no slow (transverse) group


# ---------------------------------------------------------------- (b) LEGO chain
def test_scene_b_amplitude_gap(tmp_path):
    a_min = amplitude_gap(lego_parameters(n_v=1))  # 0.12 rad
    _, ds, _ = run("b_lego_amplitude_gap", tmp_path)
    middle = np.abs(ds["theta"].values[:, 180:221]).max()
    assert middle < a_min  # no rotational soliton (|θ| ≥ A_min) reaches the middle
    _, ds, _ = run("b_lego_amplitude_gap", tmp_path / "above", [
        "excitation.velocity_m_s=3.0", "excitation.angular_velocity_rad_s=300.0", "solver.duration_s=0.75"])
    assert np.abs(ds["theta"].values[:, 180:221]).max() > 0.25  # above the gap a soliton arrives


def _halves(ds, n: int, frames: slice):
    t = ds["time"].values / LEGO_T
    theta = ds["theta"].values
    left = track(theta[frames], t[frames], 2, n // 2, 0, np.inf)
    right = track(theta[frames], t[frames], n // 2, n - 2, 0, np.inf)
    return left, right


def test_scene_b_opposite_sign_solitons_repel(tmp_path):
    _, ds, _ = run("b_lego_collision_opposite_sign", tmp_path)
    (tl, pl, al), (tr, pr, ar) = _halves(ds, 200, slice(-30, None))
    assert np.all(al > 0.8 * 0.5) and np.all(ar < -0.8 * 0.5)  # each keeps its sign and ≥ 80 %
    assert np.polyfit(tl, pl, 1)[0] < -0.03 and np.polyfit(tr, pr, 1)[0] > 0.03  # moving apart


def test_scene_b_same_sign_solitons_pass_through(tmp_path):
    _, ds, _ = run("b_lego_collision_same_sign", tmp_path)
    (tl, pl, al), (tr, pr, ar) = _halves(ds, 200, slice(-30, None))
    assert al.mean() == pytest.approx(0.4, rel=0.1)  # the 0.4 rad pulse is now on the left ...
    assert ar.mean() == pytest.approx(0.6, rel=0.1)  # ... and the 0.6 rad one on the right
    assert np.polyfit(tl, pl, 1)[0] < 0 < np.polyfit(tr, pr, 1)[0]


def test_scene_interface_reflects_and_transmits(tmp_path):
    _, ds, _ = run("lego_stiffness_interface", tmp_path)
    theta, t = ds["theta"].values, ds["time"].values / LEGO_T
    late = slice(-20, None)
    _, p_tr, a_tr = track(theta[late], t[late], 140, 258, 0, np.inf)
    _, p_re, a_re = track(theta[late], t[late], 2, 125, 0, np.inf)
    assert 0.15 < a_tr.mean() < 0.45  # a smaller soliton is transmitted ...
    assert a_re.mean() > 0.08  # ... and a pulse of the same sign reflected
    assert p_tr[-1] > p_tr[0] and p_re[-1] < p_re[0]


def test_scene_gradient_follows_the_local_speed_law(tmp_path):
    """The soliton climbs the k_θ gradient adiabatically: its transit time from unit 100 to 230
    equals ∫ dx / c(A(x); local k_θ) with the measured amplitude A(x) (docs/physics.md §1.3 speed law);
    pointwise the speed lags the local law and overshoots it by up to ≈ 15 %."""
    scene, ds, _ = run("lego_stiffness_gradient", tmp_path)
    theta, t = ds["theta"].values, ds["time"].values / LEGO_T
    times, pos, amp = track(theta, t, 5, 250, 300, 2700)
    base, lat = lego_parameters(n_v=1), scene.lattice
    inside = (pos >= 100) & (pos <= 230)
    x, a = pos[inside], amp[inside]
    k_rot = lat.k_rot_n_m_per_rad * (1 + np.clip((x - 80) / (259 - 80), 0, 1))
    c = [float(soliton_speed(RotatingChainND(0.0, base.Ks, k / (lat.k_long_n_per_m * lat.a_m**2),
                                             base.alpha2, 1, 0), ai)) for k, ai in zip(k_rot, a)]
    predicted = np.sum(np.diff(x) / (0.5 * (np.asarray(c[1:]) + np.asarray(c[:-1]))))
    measured = times[inside][-1] - times[inside][0]
    assert measured == pytest.approx(predicted, rel=0.05)
    assert a[-1] < 0.9 * amp[0]  # it loses amplitude as the lattice stiffens ...
    assert (x[-1] - x[-6]) / (times[inside][-1] - times[inside][-6]) > 1.3 * (pos[5] - pos[0]) / (times[5] - times[0])


# ---------------------------------------------------------------- (j) magnets
@pytest.mark.parametrize("spin, state", [(500.0, 1), (-500.0, -1), (300.0, 0)])
def test_scene_j_tristable_unit(tmp_path, spin, state):
    """The shipped spin (+500 rad/s) closes the unit; −500 closes it the other way; 300 is too weak."""

    def set_spin(data):
        data["excitation"]["kicks"][0]["angular_velocity_rad_s"] = spin

    ds = run_edited("j_magnets_tristable_unit", tmp_path, set_spin)
    final = ds["theta"].values[-1]
    assert np.ptp(final) < 1e-3
    assert final.mean() == pytest.approx(state * math.pi / 4, abs=0.02)


def test_scene_j_transition_wave_closes_the_strip(tmp_path):
    _, ds, _ = run("j_magnets_transition_wave", tmp_path)
    theta, t = ds["theta"].values, ds["time"].values
    nc = int(ds["col"].max()) + 1
    front = front_positions(theta[:, :nc], 0.39)
    sel = (front > 12) & (front < 45)
    coef = np.polyfit(t[sel], front[sel], 1)
    resid = front[sel] - np.polyval(coef, t[sel])
    assert np.max(np.abs(resid)) <= 2.0  # steady front: within two units of a straight line
    assert coef[0] * 0.02 > 0.5  # ≈ 1 m/s
    assert np.all(np.abs(theta[-1] - math.pi / 4) < 0.05)  # every unit closed


def test_scene_j_domain_wall_stays_put(tmp_path):
    _, ds, _ = run("j_magnets_domain_wall", tmp_path)
    theta, t = ds["theta"].values, ds["time"].values
    nc = int(ds["col"].max()) + 1
    late = t > 0.6 * t[-1]
    walls = [wall_position(row[:nc]) for row in theta[late]]
    assert np.ptp(walls) < 1.0  # within one unit
    final = theta[-1, :nc]
    assert np.all(np.abs(final[:10] - math.pi / 4) < 0.05) and np.all(np.abs(final[-10:] + math.pi / 4) < 0.05)


# ---------------------------------------------------------------- (k) linkage
def test_scene_k_linkage_deploys(tmp_path):
    scene, ds, _ = run("k_linkage_transition_wave", tmp_path)
    lat = scene.lattice
    theta = ds["theta"].values
    nc = lat.n_cols
    switch = lat.theta_deployed_rad - lat.theta0_rad
    front = front_positions(theta[:, :nc], 0.5 * switch)
    assert np.all(np.diff(front) >= 0) and front[-1] == nc - 1  # the wave sweeps the whole strip
    assert np.all(np.abs(theta[-1] - switch) < 0.03)
    x = ds["x"].values[:nc] + ds["u"].values[-1, :nc]
    expected = (nc - 1) * lat.bar_length_m * math.cos(lat.theta_deployed_rad)
    assert x[-1] - x[0] == pytest.approx(expected, rel=0.01)  # deployed length


# predeformed squares (rarefaction soliton, cnoidal shaker): test_predeformed_scenes.py
