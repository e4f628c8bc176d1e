"""Skew-periodic sheets (oblique plane waves) and tilted boundary drives."""

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from flexmm.assemble import SceneError, build_problem
from flexmm.config import ConfigError, scene_from_dict
from flexmm.config.rigid import RotatingSquaresSheet
from flexmm.models.rotating_sheet import build, hinge_pairs

REPO = Path(__file__).resolve().parents[2]


def _data(**lattice):
    data = yaml.safe_load((REPO / "configs" / "a_sheet_mode_separation.yaml").read_text())
    data["lattice"].update(n_cols=lattice.pop("n_cols", 40), **lattice)
    data["solver"]["duration_s"] = 0.001
    return data


def test_skew_wrap_joins_top_row_to_shifted_bottom_row():
    a, b, axis = hinge_pairs(4, 10, False, True, skew=2)
    wrap = [(i, j) for i, j, ax in zip(a, b, axis) if ax == 1 and i >= 30]
    assert wrap == [(30 + c, c + 2) for c in range(8)]  # columns 8, 9 have no partner (x not periodic)
    a, b, axis = hinge_pairs(4, 10, True, True, skew=2)
    wrap = [(i, j) for i, j, ax in zip(a, b, axis) if ax == 1 and i >= 30]
    assert wrap == [(30 + c, (c + 2) % 10) for c in range(10)]


def test_skew_torus_is_invariant_under_a_two_row_shift():
    """On the skew torus, moving every unit up two rows (the top rows re-enter at the bottom
    ``skew_cols`` columns further right) maps the lattice onto itself: forces of a random state
    move with it. A wrong wrap (e.g. unshifted) breaks this."""
    lat = RotatingSquaresSheet.model_validate(_data(right="periodic", left="periodic")["lattice"])
    system = build(lat)
    nr, nc = lat.n_rows, lat.n_cols
    n = nr * nc
    row, col = np.divmod(np.arange(n), nc)
    wrapped = row + 2 >= nr
    dest = ((row + 2) % nr) * nc + (col + np.where(wrapped, lat.skew_cols, 0)) % nc
    perm = np.concatenate([dest + f * n for f in range(3)])
    rng = np.random.default_rng(3)
    q = 0.05 * rng.standard_normal(3 * n)
    shifted = np.empty_like(q)
    shifted[perm] = q
    f, f_shifted = np.zeros(3 * n), np.zeros(3 * n)
    system.force(q, system.args, f)
    system.force(shifted, system.args, f_shifted)
    assert np.max(np.abs(f_shifted[perm] - f)) < 1e-12 * np.max(np.abs(f))
    wrong = RotatingSquaresSheet.model_validate(_data(right="periodic", left="periodic", skew_cols=0)["lattice"])
    system = build(wrong)
    system.force(q, system.args, f)
    system.force(shifted, system.args, f_shifted)
    assert np.max(np.abs(f_shifted[perm] - f)) > 1e-3 * np.max(np.abs(f))


def test_tilted_drive_moves_u_and_v_by_cos_and_sin():
    problem = build_problem(scene_from_dict(_data()))
    t = problem.terms
    n = problem.system.n_sites
    amp = t.drv_prm[:, 0]
    u_rows, v_rows = t.drv_dof < n, (t.drv_dof >= n) & (t.drv_dof < 2 * n)
    ang = math.radians(26.565)
    assert np.allclose(amp[u_rows], 0.01 / 0.01 * math.cos(ang)) and np.allclose(amp[v_rows], math.sin(ang))
    assert u_rows.sum() == v_rows.sum() == 4


@pytest.mark.parametrize("lattice, fragment", [
    (dict(skew_cols=1), "same parity"),
    (dict(skew_cols=2, bottom="free", top="free"), "set bottom and top to periodic"),
])
def test_skew_config_errors(lattice, fragment):
    with pytest.raises(ConfigError, match=fragment):
        scene_from_dict(_data(**lattice))


def test_tilted_drive_on_a_chain_is_a_scene_error():
    data = yaml.safe_load((REPO / "configs" / "lego_vector_soliton.yaml").read_text())
    data["excitation"] = dict(kind="boundary_displacement", end="left", amplitude_m=0.001, duration_s=0.001,
                              angle_deg=30.0)
    with pytest.raises(SceneError, match="no y motion"):
        build_problem(scene_from_dict(data))
