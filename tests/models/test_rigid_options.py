"""Options of the rigid-unit lattices: parameter variation, magnets (tristable units), excitations
that target any set of units (points, lines, both ends, launched soliton pairs, prescribed rotation).
"""

import math

import numpy as np
import pytest
from conftest import LEGO_CHAIN

from flexmm.assemble import build_problem
from flexmm.config import ConfigError, scene_from_dict
from flexmm.integrators.common import MODE_DISPLACEMENT
from flexmm.models import MODELS
from flexmm.models.magnets import MU0_OVER_4PI, face_magnets

LEGO = LEGO_CHAIN
MAGNET_SHEET = {"kind": "rotating_squares_sheet", "a_m": 0.02, "k_long_n_per_m": 5e4, "k_shear_n_per_m": 5e4,
                "k_rot_n_m_per_rad": 0.01, "mass_kg": 0.005,
                "magnets": {"moment_a_m2": 0.253, "recess_m": 0.003}}


def scene(lattice, **sections):
    return scene_from_dict({"name": "t", "lattice": lattice, "solver": {"duration_s": 1e-3}, **sections})


# ---------------------------------------------------------------- variation (rules: tests/models/test_variation.py)
def test_chain_variation_reaches_the_tables():
    lattice = dict(LEGO, n_units=5, variation=[
        {"kind": "interface", "target": "k_long_n_per_m", "position": 3, "value": 2 * LEGO["k_long_n_per_m"]},
        {"kind": "defects", "target": "inertia_kg_m2", "sites": [0], "value": 2 * LEGO["inertia_kg_m2"]}])
    system = MODELS["rotating_squares_chain"].build(scene(lattice).lattice)
    hprm, sprm = system.args[2], system.args[3]
    np.testing.assert_allclose(hprm[:, 4], [1, 1, 1.5, 2])  # k_l per hinge / base k_l
    np.testing.assert_allclose(sprm[:, 1], 0.0)  # n_v = 1 but s_v = 0: no lateral stretch term
    alpha2 = LEGO["inertia_kg_m2"] / (LEGO["mass_kg"] * LEGO["a_m"] ** 2)
    np.testing.assert_allclose(system.mass[5:], [2 * alpha2] + [alpha2] * 4)


@pytest.mark.parametrize("variation, message", [
    ({"kind": "gradient", "target": "mass_kg", "start": 1, "end": 2, "first": 4, "last": 2}, "first < last"),
    ({"kind": "interface", "target": "mass_kg", "position": 9, "value": 1}, "1 ≤ position ≤ 7"),
    ({"kind": "defects", "target": "mass_kg", "sites": [12], "value": 1}, "outside 0..7"),
    ({"kind": "random", "target": "mass_kg", "seed": 1}, "exactly one of std or relative_std"),
    ({"kind": "gradient", "target": "spring", "start": 1, "end": 2}, "theta0_rad"),
])
def test_variation_config_errors(variation, message):
    with pytest.raises(ConfigError, match=message):
        scene(dict(LEGO, n_units=8, variation=[variation]))


# ---------------------------------------------------------------- magnets
def test_dipole_pair_energy_matches_the_point_dipole_formula():
    """Two magnet units far apart: the kernel's energy is Σ μ0/(4π r³)[m1·m2 − 3(m1·r̂)(m2·r̂)]."""
    lattice = dict(MAGNET_SHEET, n_rows=1, n_cols=2, theta0_rad=0.2, ligament_length_m=0.1)
    system = MODELS["rotating_squares_sheet"].build(scene(lattice).lattice)
    q = np.zeros(system.ndof)
    q[4:] = [0.3, -0.1]  # θ of the two units
    a, sc = 0.02, system.scales
    pos, dirs = face_magnets(0.003 / a)
    expected = 0.0
    centres = [np.zeros(2), np.array([a * math.cos(0.2) + 0.1, 0.0])]
    phis = [0.2 + 0.3, -(0.2 - 0.1)]  # φ = σ(θ0 + θ), σ = +1, −1
    signs = [1.0, -1.0]  # attract: σ = +1 units point out, σ = −1 in
    mags = []
    for c, phi, s in zip(centres, phis, signs):
        rot = np.array([[math.cos(phi), -math.sin(phi)], [math.sin(phi), math.cos(phi)]])
        mags.append([(c + a * rot @ p, s * 0.253 * rot @ d) for p, d in zip(pos, dirs)])
    for r1, m1 in mags[0]:
        for r2, m2 in mags[1]:
            r = r2 - r1
            rn = np.linalg.norm(r)
            expected += MU0_OVER_4PI / rn**3 * (m1 @ m2 - 3 * (m1 @ r / rn) * (m2 @ r / rn))
    bare = MODELS["rotating_squares_sheet"].build(scene(dict(lattice, magnets=None)).lattice)
    magnets = (system.energy(q, system.args) - bare.energy(q, bare.args)) * sc.energy
    assert magnets == pytest.approx(expected, rel=1e-9)


def test_magnet_unit_is_tristable():
    """Relaxed from three guesses, four squares around a void settle open or closed either way."""
    states = []
    for guess in (0.05, 0.7, -0.7):
        lattice = dict(MAGNET_SHEET, n_rows=2, n_cols=2, predeform={"theta_guess_rad": guess})
        system = MODELS["rotating_squares_sheet"].build(scene(lattice).lattice)
        theta = system.q0[8:]
        assert np.ptp(theta) < 1e-6
        states.append(theta.mean())
    assert abs(states[0]) < 1e-6
    assert states[1] == pytest.approx(-states[2], rel=1e-6)
    assert 0.75 < states[1] < math.pi / 4 + 0.02  # the faces touch: the void is closed


# ---------------------------------------------------------------- excitations
def test_combined_drives_append_and_rotation_drive_prescribes_theta():
    lattice = dict(MAGNET_SHEET, n_rows=2, n_cols=4, left="driven", right="driven")
    exc = {"kind": "combined", "parts": [
        {"kind": "boundary_displacement", "end": "left", "shape": "smooth_step", "amplitude_rad": 0.7,
         "duration_s": 0.01},
        {"kind": "boundary_displacement", "end": "right", "shape": "smooth_step", "amplitude_rad": -0.7,
         "duration_s": 0.01}]}
    problem = build_problem(scene(lattice, excitation=exc, solver={"duration_s": 1e-3, "dt_s": 1e-6}))
    s, terms = problem.system, problem.terms
    theta_dofs = [s.dof("theta", i) for i in (0, 4, 3, 7)]
    assert terms.drv_dof.tolist() == theta_dofs
    assert np.all(terms.drv_mode == MODE_DISPLACEMENT)
    assert terms.drv_prm[:, 0].tolist() == [0.7, 0.7, -0.7, -0.7]
    assert np.all(s.inv_mass[theta_dofs] == 0) and s.inv_mass[s.dof("u", 0)] > 0


def test_kicks_points_and_edges():
    lattice = dict(MAGNET_SHEET, n_rows=2, n_cols=3, magnets=None)
    exc = {"kind": "kicks", "kicks": [{"sites": [4], "velocity_x_m_s": 1.0, "velocity_y_m_s": -2.0},
                                      {"end": "top", "angular_velocity_rad_s": 10.0}]}
    s = build_problem(scene(lattice, excitation=exc)).system
    v, sc = s.v0, s.scales
    assert v[s.dof("u", 4)] * sc.velocity == pytest.approx(1.0)
    assert v[s.dof("v", 4)] * sc.velocity == pytest.approx(-2.0)
    assert np.count_nonzero(v[: 2 * s.n_sites]) == 2
    np.testing.assert_allclose(v[[s.dof("theta", i) for i in (3, 4, 5)]] / sc.time_s, 10.0)
    top = build_problem(scene(dict(lattice, top="driven"), excitation={
        "kind": "impact", "end": "top", "velocity_m_s": 1.0, "sites": [5]})).system
    assert top.v0[top.dof("v", 5)] < 0 and np.count_nonzero(top.v0) == 1  # pushed down, into the sheet


def test_launched_solitons_superpose():
    lattice = dict(LEGO, n_units=200)
    first = {"amplitude_rad": 0.5, "center_site": 60}
    second = {"amplitude_rad": -0.5, "center_site": 140, "direction": -1}
    a, both = (build_problem(scene(lattice, excitation={"kind": "solitons", "pulses": pulses})).system
               for pulses in ([first], [first, second]))
    n = 200
    q_b, v_b = both.q0 - a.q0, both.v0 - a.v0  # what the second pulse added
    assert a.q0[n + 60] == pytest.approx(0.5) and q_b[n + 140] == pytest.approx(-0.5)
    assert np.max(np.abs(q_b[n : n + 100])) < 1e-3  # each pulse is localised where it was put
    assert v_b[n + 141] * q_b[n + 141] < 0  # moving left: its right (trailing) flank relaxes
    assert v_b[n + 139] * q_b[n + 139] > 0  # and its left (leading) flank rises


@pytest.mark.parametrize("excitation, message", [
    ({"kind": "impact", "end": "top", "velocity_m_s": 1.0}, "ends are left, right"),
    ({"kind": "kicks", "kicks": [{"sites": [50], "angular_velocity_rad_s": 1.0}]}, "outside 0..9"),
    ({"kind": "solitons", "pulses": [{"amplitude_rad": 0.5, "center_site": 10}]}, "outside 0..9"),
    ({"kind": "kicks", "kicks": [{"end": "left", "sites": [1]}]}, "exactly one of end or sites"),
])
def test_excitation_targets_are_validated(excitation, message):
    with pytest.raises(ConfigError, match=message):
        scene(dict(LEGO, n_units=10), excitation=excitation)
