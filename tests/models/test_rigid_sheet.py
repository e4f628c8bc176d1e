"""The 2D rotating-squares sheet (docs/physics.md §1.2): geometry, the rotating mechanism, the planar
reduction to the chain, ends and dataset coordinates.

Kernel oracles (−∇E, numpy reference, Σ F = 0) run on the sheet examples of tests/conftest.py via
tests/models/test_hinge_kernel.py.
"""

import math

import numpy as np
import pytest

from flexmm.api import run_scene
from flexmm.config import ConfigError, scene_from_dict
from flexmm.io.run_dataset import open_run
from flexmm.models import MODELS
from flexmm.models.rotating_sheet import theory_parameters

SHEET = {"kind": "rotating_squares_sheet", "a_m": 0.01, "k_long_n_per_m": 1e4, "k_shear_n_per_m": 3e3,
         "k_rot_n_m_per_rad": 2e-3, "areal_density_kg_m2": 20.0}


def build(**lattice):
    scene = scene_from_dict({"name": "t", "lattice": dict(SHEET, **lattice), "solver": {"duration_s": 1e-3}})
    return MODELS[scene.lattice.kind].build(scene.lattice), scene.lattice


@pytest.mark.parametrize("ligament_m", [0.0, 0.002])
def test_uniform_counter_rotation_is_a_mechanism(ligament_m):
    """Uniform θ with the matching affine shrink leaves every hinge closed: only k_θ is loaded.

    The checkerboard sign of the vertical hinges (−σ_A) is what makes this hold; with the wrong
    sign their shear springs would stretch.
    """
    system, cfg = build(n_rows=5, n_cols=6, theta0_rad=0.2, ligament_length_m=ligament_m)
    n, a = system.n_sites, cfg.a_m
    theta = 0.13
    spacing = a * math.cos(0.2) + ligament_m
    stretch = (a * math.cos(0.2 + theta) + ligament_m) / spacing - 1.0
    q = np.zeros(system.ndof)
    q[:n] = system.site_coords["x"] / a * stretch
    q[n : 2 * n] = system.site_coords["y"] / a * stretch
    q[2 * n :] = theta
    n_hinges = (cfg.n_rows * (cfg.n_cols - 1) + cfg.n_cols * (cfg.n_rows - 1))
    k_theta = cfg.k_rot_n_m_per_rad / (cfg.k_long_n_per_m * a * a)
    assert system.energy(q, system.args) == pytest.approx(n_hinges * 0.5 * k_theta * (2 * theta) ** 2, rel=1e-12)
    f = np.zeros(system.ndof)
    system.force(q, system.args, f)
    assert np.max(np.abs(f[: 2 * n])) < 1e-13  # no hinge is stretched or sheared


def test_planar_state_with_v_held_gives_the_chain_forces():
    """Rows alike, v = 0, periodic in y: the sheet's u, θ forces are those of the chain with
    n_v = 2, s_v = 1 (each unit has one vertical hinge's worth of k_l a² G²/2 and k_θ(2θ)²/2)."""
    ks = 3e3
    sheet, cfg = build(n_rows=2, n_cols=9, theta0_rad=0.15, bottom="periodic", top="periodic")
    chain_cfg = scene_from_dict({"name": "c", "solver": {"duration_s": 1e-3}, "lattice": {
        "kind": "rotating_squares_chain", "n_units": 9, "a_m": 0.01, "theta0_rad": 0.15, "k_long_n_per_m": 1e4,
        "k_shear_n_per_m": ks, "k_rot_n_m_per_rad": 2e-3, "mass_kg": cfg.unit_mass_kg,
        "inertia_kg_m2": cfg.unit_inertia_kg_m2, "n_lateral": 2, "lateral_stretch": True}}).lattice
    chain = MODELS[chain_cfg.kind].build(chain_cfg)
    rng = np.random.default_rng(3)
    u, th = rng.normal(0, 0.05, 9), rng.normal(0, 0.3, 9)
    qs = np.concatenate([u, u, np.zeros(18), th, th])
    qc = np.concatenate([u, th])
    fs, fc = np.zeros(qs.size), np.zeros(qc.size)
    sheet.force(qs, sheet.args, fs)
    chain.force(qc, chain.args, fc)
    np.testing.assert_allclose(fs[:9], fc[:9], atol=1e-13)
    np.testing.assert_allclose(fs[36:45], fc[9:], atol=1e-13)
    assert sheet.energy(qs, sheet.args) == pytest.approx(2 * chain.energy(qc, chain.args), rel=1e-12)


def test_ends_coordinates_and_masses():
    system, cfg = build(n_rows=3, n_cols=4, theta0_rad=0.1, mass_kg=2e-3, areal_density_kg_m2=None)
    ends = system.ends
    assert ends["left"] == [0, 4, 8] and ends["right"] == [3, 7, 11]
    assert ends["bottom"] == [0, 1, 2, 3] and ends["top"] == [8, 9, 10, 11]
    h = 0.01 * math.cos(0.1)
    np.testing.assert_allclose(system.site_coords["x"], np.tile(np.arange(4), 3) * h)
    np.testing.assert_allclose(system.site_coords["y"], np.repeat(np.arange(3), 4) * h)
    assert system.site_coords["row"].tolist() == np.repeat(np.arange(3), 4).tolist()
    # inertia from the solid square of diagonal a: J = m a²/12, α² = 1/12
    assert theory_parameters(cfg).alpha2 == pytest.approx(1 / 12)
    assert system.grid_shape == (3, 4)
    fixed, _ = build(n_rows=3, n_cols=4, left="fixed")
    n = fixed.n_sites
    assert np.all(fixed.inv_mass[[0, 4, 8, n, n + 4, 2 * n + 8]] == 0)
    assert np.all(fixed.inv_mass[[1, n + 1, 2 * n + 1]] > 0)


@pytest.mark.parametrize("bad, message", [
    ({"left": "periodic"}, "both be periodic"),
    ({"n_cols": 5, "left": "periodic", "right": "periodic"}, "even n_cols"),
    ({"mass_kg": 1e-3}, "exactly one of mass_kg or areal_density_kg_m2"),
    ({"theta0_rad": 0.9}, "|θ0| < π/4"),
])
def test_sheet_config_errors(bad, message):
    with pytest.raises(ConfigError, match=message.replace("|", r"\|")):
        build(**dict({"n_rows": 2, "n_cols": 4}, **bad))


def test_dataset_has_row_and_col_as_indices(tmp_path):
    scene = scene_from_dict({"name": "sheet_io", "lattice": dict(SHEET, n_rows=2, n_cols=3),
                             "excitation": {"kind": "impact", "end": "bottom", "velocity_m_s": 0.1},
                             "solver": {"duration_s": 2e-3}, "output": {"n_frames": 3}})
    result = run_scene(scene, run_dir=tmp_path)
    ds = open_run(result.path)
    assert ds["x"].attrs["units"] == "m" and ds["y"].attrs["units"] == "m"
    assert ds["row"].attrs["units"] == "1" and ds["col"].attrs["units"] == "1"
    assert ds["row"].values.tolist() == [0, 0, 0, 1, 1, 1]
    # the bottom impact pushes the bottom row up (+y) and nothing along x at t = 0+
    assert np.all(ds["v_dot"].values[0, :3] > 0) and np.all(ds["v_dot"].values[0, 3:] == 0)
