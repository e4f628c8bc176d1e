"""Predeformation (flexmm.models.predeform): static equilibrium under applied strain or load.

Oracles: the rotating mechanism (uniaxial strain closes the sheet isotropically, Poisson ratio −1,
θ from cos(θ0+θ) = (1+ε) cos θ0), the buckling law of a compressed chain (F a sin θ = (4+2n_v) k_θ θ,
docs/physics.md §1.2: F_c = 4k_θ/a for n_v = 0), and energy conservation of the loaded dynamics.
"""

import math

import numpy as np
import pytest
from conftest import LEGO_CHAIN
from scipy import optimize

from flexmm.api import run_scene
from flexmm.assemble import SceneError, build_problem
from flexmm.config import scene_from_dict
from flexmm.io.run_dataset import open_run
from flexmm.models import MODELS

LEGO = LEGO_CHAIN
SHEET = {"kind": "rotating_squares_sheet", "a_m": 0.01, "k_long_n_per_m": 1e4, "k_shear_n_per_m": 3e3,
         "k_rot_n_m_per_rad": 2e-4, "areal_density_kg_m2": 20.0}


def build(lattice: dict):
    scene = scene_from_dict({"name": "t", "lattice": lattice, "solver": {"duration_s": 1e-3}})
    return MODELS[lattice["kind"]].build(scene.lattice)


def test_uniaxial_strain_closes_the_sheet_isotropically():
    eps, theta0 = -0.05, 0.2
    system = build(dict(SHEET, n_rows=10, n_cols=10, theta0_rad=theta0, predeform={"strain_x": eps}))
    n, q = system.n_sites, system.q0
    assert system.predeformation.residual < 1e-10
    col, row = system.site_coords["col"], system.site_coords["row"]
    inner = (col >= 3) & (col <= 6) & (row >= 3) & (row <= 6)  # away from the free and held edges
    x, y = system.site_coords["x"] / 0.01, system.site_coords["y"] / 0.01
    eps_x = np.polyfit(x[inner & (row == 5)], q[:n][inner & (row == 5)], 1)[0]
    eps_y = np.polyfit(y[inner & (col == 5)], q[n : 2 * n][inner & (col == 5)], 1)[0]
    assert eps_x == pytest.approx(eps, rel=0.02)  # the end units take a little of the strain
    assert eps_y == pytest.approx(eps_x, rel=0.03)  # Poisson ratio −1 (x also strains the hinges a bit)
    theta = math.acos((1 + eps_y) * math.cos(theta0)) - theta0  # the free direction is pure mechanism
    np.testing.assert_allclose(q[2 * n :][inner], theta, rtol=2e-3)
    # the strained ends are held during the dynamics
    for s in system.ends["left"] + system.ends["right"]:
        assert system.inv_mass[s] == 0 and system.inv_mass[2 * n + s] > 0


@pytest.mark.parametrize("ratio", [0.8, 1.15])
def test_compressed_chain_buckles_past_the_critical_load(ratio):
    n_v, n = 0, 80
    k_rot, a = LEGO["k_rot_n_m_per_rad"], LEGO["a_m"]
    f_c = (4 + 2 * n_v) * k_rot / a
    force = ratio * f_c
    system = build(dict(LEGO, n_units=n, theta0_rad=0.0, n_lateral=n_v, predeform={
        "loads": [{"end": "left", "force_n": force}, {"end": "right", "force_n": force}],
        "theta_guess_rad": 0.2}))
    theta_mid = system.q0[n + n // 2]
    if ratio < 1:
        assert abs(theta_mid) < 1e-4  # from a 0.2 rad guess; the soft mode limits the precision
    else:
        expected = optimize.brentq(lambda t: math.sin(t) / t - 1 / ratio, 1e-6, 3.0)
        assert theta_mid == pytest.approx(expected, rel=0.01)


def test_loaded_chain_keeps_its_state_and_energy(tmp_path):
    """Started from the relaxed state with the loads on, nothing moves; an impact conserves E."""
    lattice = dict(LEGO, n_units=40, theta0_rad=0.05, predeform={
        "loads": [{"end": "left", "force_n": 0.2}, {"end": "right", "force_n": 0.2}], "theta_guess_rad": 0.1})
    rest = run_scene(scene_from_dict({"name": "rest", "lattice": lattice, "solver": {"duration_s": 0.02},
                                      "output": {"n_frames": 5}}), run_dir=tmp_path / "rest")
    ds = open_run(rest.path)
    assert np.max(np.abs(ds["theta"].values[-1] - ds["theta"].values[0])) < 1e-5  # θ_s ≈ 0.14 rad
    hit = run_scene(scene_from_dict({"name": "hit", "lattice": lattice, "solver": {"duration_s": 0.05},
                                     "excitation": {"kind": "impact", "end": "left", "velocity_m_s": -0.5},
                                     "output": {"n_frames": 11}}), run_dir=tmp_path / "hit")
    e = open_run(hit.path)["total_energy"].values  # includes the load potential −F·u
    kinetic0 = 0.5 * LEGO["mass_kg"] * 0.5**2
    assert np.max(np.abs(e - e[0])) < 5e-3 * kinetic0  # Verlet's O(h²) fluctuation, no drift


def test_unbalanced_load_is_reported():
    with pytest.raises(ValueError, match="did not converge"):
        build(dict(LEGO, n_units=6, predeform={"loads": [{"end": "left", "force_n": 0.1}], "max_steps": 2000}))


def test_displacement_drive_on_a_predeformed_end_is_refused():
    lattice = dict(LEGO, n_units=10, theta0_rad=0.05, left="driven", predeform={
        "loads": [{"end": "left", "force_n": 0.1}, {"end": "right", "force_n": 0.1}]})
    scene = scene_from_dict({"name": "t", "lattice": lattice, "solver": {"duration_s": 1e-3},
                             "excitation": {"kind": "boundary_displacement", "end": "left",
                                            "amplitude_m": 1e-4, "duration_s": 1e-3}})
    with pytest.raises(SceneError, match="predeformed"):
        build_problem(scene)
