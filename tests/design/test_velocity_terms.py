"""``flexmm design`` and ``flexmm fit`` with dashpots and ground friction: ``--check-gradient``
on tiny specs whose variables include the dashpot coefficient and the friction level."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import yaml
from conftest import LEGO_CHAIN
from typer.testing import CliRunner

from flexmm.cli import app
from flexmm.design.fit import load_fit, solve, synthetic_table, write_table
from flexmm.design.optimize import check_gradient, load_design

CHAIN = {"name": "dashpot_impact", "lattice": {
    **LEGO_CHAIN, "n_units": 8, "theta0_rad": 0.0, "left": "driven", "right": "fixed"},
    "excitation": {"kind": "impact", "end": "left", "velocity_m_s": 2.0, "angular_velocity_rad_s": 100.0,
                   "striker": {"mass_kg": 0.02, "contact_stiffness_n_per_m": 1.0e7, "exponent": 1.5}},
    "damping": {"viscous": {"damping_ratio": 0.01}, "dashpot_n_s_per_m": 0.3},
    "solver": {"duration_s": 0.004}}
MASS = {"name": "friction_pull", "lattice": {
    "kind": "mass_chain", "n_units": 8, "spacing_m": 0.01, "mass_kg": 0.01, "left": "driven", "right": "free",
    "bond": {"law": "polynomial", "k1_n_per_m": 100.0, "k2_n_per_m2": 2e3, "k3_n_per_m3": 1e5},
    "friction": {"force_n": 0.05, "regularisation_m_s": 0.05}},
    "excitation": {"kind": "boundary_displacement", "end": "left", "amplitude_m": 2e-3, "duration_s": 0.047,
                   "shape": "smooth_step"},
    "damping": {"dashpot_n_s_per_m": 0.05},
    "solver": {"duration_s": 0.2}}
DASHPOT = {"name": "dashpot", "path": "damping.dashpot_n_s_per_m", "initial": 0.3, "bounds": [0.01, 3.0]}


def _design(tmp_path: Path, scene: dict, variables: list, objective: list) -> Path:
    spec = {"name": "velocity_terms", "scene": copy.deepcopy(scene), "variables": variables,
            "objective": objective, "optimizer": {"max_iterations": 3}}
    path = tmp_path / "design.yaml"
    path.write_text(yaml.safe_dump(spec, sort_keys=False))
    return path


def test_design_check_gradient_with_dashpots(tmp_path):
    """A struck chain with dashpots: the peak force on the wall w.r.t. the dashpot coefficient
    (a scene path) and per-unit masses; the CLI prints the worst relative error last."""
    path = _design(tmp_path, CHAIN, [
        DASHPOT,
        {"name": "mass", "target": "mass_kg", "profile": "linear", "initial": [4e-3, 5e-3], "bounds": [1e-3, 2e-2]}],
        [{"kind": "peak_force", "region": {"end": "right"}}])
    res = CliRunner().invoke(app, ["design", str(path), "--check-gradient"])
    assert res.exit_code == 0, res.output
    last = res.output.strip().splitlines()[-1]
    assert last.startswith("worst relative error:") and float(last.split(":")[1]) < 1e-6


def test_design_gradient_with_friction(tmp_path):
    """A chain of masses on a rough floor pulled at one end: the energy reaching the far sites
    w.r.t. the friction level (per site, a linear profile), its regularisation velocity and
    the dashpots."""
    dp = load_design(_design(tmp_path, MASS, [
        {"name": "dashpot", "path": "damping.dashpot_n_s_per_m", "initial": 0.05, "bounds": [0.0, 1.0]},
        {"name": "level", "target": "friction.force_n", "profile": "linear", "initial": [0.04, 0.06],
         "bounds": [0.0, 1.0]},
        {"name": "v_eps", "path": "lattice.friction.regularisation_m_s", "initial": 0.05, "bounds": [0.01, 1.0]}],
        [{"kind": "energy", "region": {"sites": [5, 6, 7]}, "goal": "maximize"}]))
    _, g, fd, err = check_gradient(dp)
    assert np.all(g != 0.0) and np.all(err < 1e-6), (g, fd, err)


def _fit(tmp_path: Path) -> Path:
    scene = copy.deepcopy(CHAIN)
    (tmp_path / "scene.yaml").write_text(yaml.safe_dump(scene))
    table = synthetic_table(copy.deepcopy(scene), "u", [2, 4, 6], 1e-4, 41, noise=0.0, seed=3)
    write_table(table, tmp_path / "trace.csv", "mm")
    spec = {"name": "dashpot_fit", "scene": "scene.yaml",
            "data": {"file": "trace.csv", "field": "u", "unit": "mm", "sigma": 1e-3},
            "parameters": [DASHPOT | {"initial": 0.4},
                           {"name": "zeta", "path": "damping.viscous.damping_ratio", "initial": 0.015,
                            "bounds": [0.0, 0.2]}]}
    path = tmp_path / "fit.yaml"
    path.write_text(yaml.safe_dump(spec, sort_keys=False))
    return path


def test_fit_check_gradient_and_recovery_with_dashpots(tmp_path):
    """``flexmm fit --check-gradient`` with a dashpot coefficient as a parameter, and a
    noise-free fit (exact Jacobian from the tangent sweep) that recovers it."""
    path = _fit(tmp_path)
    res = CliRunner().invoke(app, ["fit", str(path), "--check-gradient"])
    assert res.exit_code == 0, res.output
    last = res.output.strip().splitlines()[-1]
    assert last.startswith("worst relative error:") and float(last.split(":")[1]) < 1e-6
    result = solve(load_fit(path))
    np.testing.assert_allclose(result.x, [0.3, 0.01], rtol=1e-6)
