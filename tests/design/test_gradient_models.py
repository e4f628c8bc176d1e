"""Gradients through runs of the models of ``design.kernels_extra``: each part of their tables.

``test_gradient.py`` checks every raw block of these scenes along one random direction; a
block that packs several tables (the sheet's t2: θ0, magnet moments, core, offsets, magnet
positions, joints, loads; the loaded chain's: sites, loads) is checked here part by part, so that a small part
cannot hide behind a large one. Also: magnets held closed in their cores (the core's
parameters), harmonic oscillators (no scene), forward tangents of each new model kind, and
``flexmm design --check-gradient`` on the small specs of ``tests/design/specs``.
"""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from design.test_gradient import SCENES, _central, _directions, _objective, _problem
from flexmm.assemble import build_problem
from flexmm.cli import app
from flexmm.config import scene_from_dict
from flexmm.design.gradient import (
    GradientError,
    Raw,
    Trajectory,
    check_differentiable,
    trajectory_of,
)
from flexmm.design.kernels import sheet_grid
from flexmm.design.kernels_extra import sheet_offsets
from flexmm.integrators.common import empty_terms
from flexmm.models.harmonic import HarmonicArgs
from flexmm.models.predeform import fire_relax

SPECS = Path(__file__).resolve().parent / "specs"


def _sections(args, t2_size: int) -> dict[str, slice]:
    """The named parts of a packed t2 vector."""
    if hasattr(args, "dipoles"):
        n, o_s, o_core, o_off, o_pos, o_j, o_l, size = sheet_offsets(args)
        assert size == t2_size
        parts = {"theta0": slice(0, n), "moments": slice(o_s, o_core), "core": slice(o_core, o_off),
                 "offsets": slice(o_off, o_pos), "positions": slice(o_pos, o_j), "joints": slice(o_j, o_l),
                 "loads": slice(o_l, size)}
    else:  # loaded chain
        m = args.chain.site_prm.size
        parts = {"sites": slice(0, m), "loads": slice(m, t2_size)}
    return {k: s for k, s in parts.items() if s.stop > s.start}


def _check_sections(traj, raw, objective, skip=()) -> dict[str, float]:
    """Adjoint vs central differences along a random direction in each part of t2; the errors."""
    _, grad, _ = traj.gradient(raw, objective, segment=7)
    rng = np.random.default_rng(7)
    errors = {}
    for name, part in _sections(traj.args, raw.t2.size).items():
        if name in skip:
            continue
        d = np.zeros_like(raw.t2)
        d[part] = rng.normal(size=part.stop - part.start) * np.maximum(np.abs(raw.t2[part]), 1e-2)
        fd = _central(traj, raw, raw.t2, raw.t2.copy(), d, objective)
        adj = float(np.vdot(grad.t2, d))
        errors[name] = abs(adj - fd) / abs(fd)
        assert errors[name] < 1e-6, (name, adj, fd)
    return errors


@pytest.mark.parametrize("name, skip", [
    ("sheet-magnets-rotation-damped", ("core",)),  # open: no magnet inside its core (next test)
    ("linkage-deploy-damped", ()),
    ("chain-loaded-pull", ()),
])
def test_each_part_of_packed_tables(name, skip):
    traj, raw = trajectory_of(_problem(name), nsteps=200, stride=5)
    assert len(_sections(traj.args, raw.t2.size)) >= 2
    if hasattr(traj.args, "dipoles"):
        assert sheet_grid(traj.args, raw.q0.size) is None  # the grid's column form has no magnets or joints
    _check_sections(traj, raw, _objective((traj.n_samples, traj.obs.size)), skip)


def test_magnets_held_in_their_cores():
    """From the closed equilibrium of the magnet strip (facing magnets inside their core radius,
    found by FIRE) with small random velocities: every block, and each part of t2 (the core's
    r_c, k_c included, whose product is nonzero only there)."""
    data = {"name": "closed"} | copy.deepcopy(SCENES["sheet-magnets-rotation-damped"])
    data["lattice"]["left"] = "free"
    del data["excitation"]
    problem = build_problem(scene_from_dict(data))
    s = problem.system
    n, length = s.n_sites, s.scales.length_m
    q = np.zeros(s.ndof)
    q[:n] = -0.3 * s.site_coords["x"] / length  # centres drawn together, units rotated shut
    q[n : 2 * n] = -0.3 * s.site_coords["y"] / length
    q[2 * n :] = 0.7
    _, resid = fire_relax(s.args, q, np.ones(s.ndof), 0.01, 0.05, 1e-10, 200000)
    assert resid < 1e-10 and np.all(s.args.theta0 + q[2 * n :] > 0.75)  # shut: θ0 + θ ≈ π/4
    s.q0 = q
    s.v0 = np.random.default_rng(3).normal(0.0, 0.01, s.ndof)
    traj, raw = trajectory_of(problem, nsteps=200, stride=5)
    objective = _objective((traj.n_samples, traj.obs.size))
    _, grad, _ = traj.gradient(raw, objective, segment=7)
    core = _sections(traj.args, raw.t2.size)["core"]
    assert np.all(grad.t2[core] != 0.0)
    rng = np.random.default_rng(0)
    for block, d in _directions(raw, rng, traj.terms.drv_shape).items():
        arr = getattr(raw, block)
        fd = _central(traj, raw, arr, arr.copy(), d, objective)
        assert abs(float(np.vdot(getattr(grad, block), d)) - fd) < 1e-6 * abs(fd), block
    _check_sections(traj, raw, objective)


def test_harmonic_oscillators():
    """Damped oscillators x'' = −k x − c x' (no scene builds them): stiffnesses, masses, damping
    and the initial state."""
    rng = np.random.default_rng(2)
    k = np.linspace(0.5, 2.0, 4)
    traj = Trajectory(HarmonicArgs(k), empty_terms(), 0.1, 200, 5, np.arange(4))
    raw = Raw(k.copy(), np.zeros(0), rng.uniform(0.5, 2.0, 4), np.full(4, 0.05), np.zeros((0, 3)),
              np.zeros((0, 4)), rng.normal(size=4), rng.normal(size=4))
    objective = _objective((traj.n_samples, 4))
    _, grad, _ = traj.gradient(raw, objective, segment=7)
    for block, d in _directions(raw, rng, traj.terms.drv_shape).items():
        arr = getattr(raw, block)
        fd = _central(traj, raw, arr, arr.copy(), d, objective)
        assert abs(float(np.vdot(getattr(grad, block), d)) - fd) < 1e-6 * abs(fd), block


@pytest.mark.parametrize("name", ["sheet-magnets-rotation-damped", "linkage-deploy-damped", "chain-loaded-pull",
                                  "triangles-sheet-damped"])
def test_tangent_matches_adjoint(name):
    """Forward sensitivities (``model_tangent``) along a direction in every block equal the
    adjoint gradient (``model_adjoint``) projected on it."""
    traj, raw = trajectory_of(_problem(name), nsteps=100, stride=5)
    objective = _objective((traj.n_samples, traj.obs.size), seed=3)
    _, grad, rec = traj.gradient(raw, objective)
    direction = raw.zeros()
    for block, d in _directions(raw, np.random.default_rng(5), traj.terms.drv_shape).items():
        setattr(direction, block, d)
    _, (tan,) = traj.sensitivities(raw, [direction])
    _, dq, dv, df, _ = objective(rec, raw)
    projected = np.sum(dq * tan.q) + np.sum(dv * tan.v) + np.sum(df * tan.f)
    assert projected == pytest.approx(grad.dot(direction), rel=1e-10)


@pytest.mark.parametrize("spec", ["magnet_strip", "linkage_deploy", "loaded_chain_pull", "triangle_strip"])
def test_check_gradient_cli_on_each_model(spec):
    """Scene variables (magnet moment and recess, joint law, masses, stiffness ramps, damping, drive)
    through the builder and the run: the worst relative error, printed last, below 1e-6."""
    res = CliRunner().invoke(app, ["design", str(SPECS / f"{spec}.yaml"), "--check-gradient"])
    assert res.exit_code == 0, res.output
    last = res.output.strip().splitlines()[-1]
    assert last.startswith("worst relative error:") and float(last.split(":")[1]) < 1e-6


def test_magnets_with_their_own_rest_angles_are_refused():
    """Gradients take θ0 as one parameter per unit (the sheet's and its magnets'): a system whose
    magnets hold other rest angles is refused with a message, not differentiated wrongly."""
    problem = _problem("sheet-magnets-rotation-damped")
    dip = problem.system.args.dipoles
    problem.system.args = problem.system.args._replace(dipoles=dip[:4] + (dip[4] + 0.01,) + dip[5:])
    with pytest.raises(GradientError, match="magnets' rest angles differ"):
        check_differentiable(problem.system, problem.terms)
