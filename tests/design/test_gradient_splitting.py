"""Exact gradients through the symplectic splittings PEFRL and BM6 (``design.splitting``) and the
implicit midpoint rule (``design.midpoint``; its own checks: test_gradient_midpoint).

The scenes, objective, directions and central differences are ``test_gradient``'s (velocity
Verlet): the adjoint of each method must match central differences of the same discrete run
to 1e-6 relative on every model kind, with damping (exact damped kicks), prescribed and applied
drives at the stage times, the striker contact and checkpointed reverse sweeps (the midpoint
rule also with dashpots and ground friction, which it solves implicitly); the forward sweep of a
splitting must be the engine's run; and the gradient of a smooth objective must converge to the
continuous one at each method's order as h → 0.
"""

from __future__ import annotations

import copy
import dataclasses

import numpy as np
import pytest
import yaml

from flexmm.assemble import build_problem
from flexmm.config import scene_from_dict
from flexmm.design import splitting, tape
from flexmm.design.fit import load_fit, solve
from flexmm.design.gradient import GradientError, Trajectory, trajectory_of
from flexmm.design.optimize import check_gradient, load_design
from flexmm.integrators import INTEGRATORS
from flexmm.integrators.common import total_force
from flexmm.integrators.stepper import make_stepper
from flexmm.models.hinge import H_KT

from . import test_fit
from .test_design import SCENE as DESIGN_SCENE
from .test_design import TERMS, VARIABLES
from .test_gradient import SCENES, _assert_same_gradients, _central, _directions, _objective, _problem

SPLITTINGS = ("pefrl", "blanes_moan6")
#: the methods with an adjoint besides velocity Verlet
ADJOINTS = (*SPLITTINGS, "implicit_midpoint")
#: test_gradient's scenes: every model kind, damping, each drive shape and mode, the striker
NAMES = ["chain-displacement-damped", "chain-force-shaker", "chain-gaussian-rotation", "mass-smooth-step-damped",
         "mass-striker", "sheet-tilted-pulse-damped"]
#: velocity-dependent terms: the midpoint rule only (a splitting refuses them)
VELOCITY_NAMES = ["chain-dashpots-damped", "mass-friction-dashpots", "sheet-dashpots"]


#: the default run's cases: each method on a chain, each model kind and drive kind once, velocity
#: terms once; every other pair of scene and method is ``slow`` (compiling their kernels is most
#: of their cost)
DEFAULT_FD = {("chain-displacement-damped", "pefrl"), ("chain-force-shaker", "blanes_moan6"),
              ("chain-gaussian-rotation", "implicit_midpoint"), ("chain-displacement-damped", "implicit_midpoint"),
              ("mass-striker", "pefrl"), ("sheet-tilted-pulse-damped", "blanes_moan6"),
              ("chain-dashpots-damped", "implicit_midpoint")}
FD_CASES = ([(n, i) for i in ADJOINTS for n in NAMES] + [(n, "implicit_midpoint") for n in VELOCITY_NAMES]
            + [("chain-loaded-pull", i) for i in ADJOINTS] + [("chain-striker", "pefrl")])


@pytest.mark.parametrize(("name", "integrator"), [c if c in DEFAULT_FD else pytest.param(*c, marks=pytest.mark.slow)
                                                  for c in FD_CASES])
def test_adjoint_matches_central_differences(name, integrator):
    problem = _problem(name)
    traj, raw = trajectory_of(problem, nsteps=120, stride=5, integrator=integrator)
    objective = _objective((traj.n_samples, traj.obs.size))
    value, grad, _ = traj.gradient(raw, objective, segment=7)  # 18 checkpointed segments
    assert value == pytest.approx(traj.value(raw, objective), rel=1e-13)
    rng = np.random.default_rng(0)
    for block, d in _directions(raw, rng, traj.terms.drv_shape, traj.terms.drv_mode).items():
        arr = getattr(raw, block)
        if not np.any(arr):  # e.g. no damping: a direction of unit size (1e-4 is lost in rounding)
            d = d / np.abs(d).max()
        base = arr.copy()
        fd = _central(traj, raw, arr, base, d, objective)
        adj = float(np.vdot(getattr(grad, block), d))
        assert abs(adj - fd) < 1e-6 * abs(fd), (block, adj, fd)


@pytest.mark.parametrize("integrator", SPLITTINGS)
@pytest.mark.parametrize("name", ["chain-displacement-damped", "mass-striker", "sheet-tilted-pulse-damped"])
def test_forward_sweep_is_the_engine_run(name, integrator):
    """The differentiated run is the Stepper's run of that integrator, frame by frame bit for bit
    (both step with ``integrators.splitting.split_step``), and the recorded force is the total
    force at the recorded state (drift-first PEFRL evaluates it there; a kick-first method
    records its last stage's, at a stage time equal to the step's to rounding)."""
    problem = _problem(name)
    traj, raw = trajectory_of(problem, nsteps=120, stride=40, integrator=integrator)
    rec, _ = traj.run(raw)
    stepper = make_stepper(problem, integrator, h=traj.h)
    f = np.empty_like(stepper.q)
    for j in range(1, 4):
        stepper.advance(40)
        np.testing.assert_array_equal(rec.q[j], stepper.q)
        np.testing.assert_array_equal(rec.v[j], stepper.v)
        total_force(stepper.args, stepper.q, stepper.v, stepper.t, f, stepper.terms)
        np.testing.assert_allclose(rec.f[j], f, rtol=0, atol=1e-12 * np.abs(f).max())


@pytest.mark.parametrize("integrator", SPLITTINGS)
@pytest.mark.parametrize("name", ["chain-force-shaker", "sheet-tilted-pulse-damped"])
def test_uniform_forces_give_the_engine_run_bit_for_bit(name, integrator):
    """A uniform chain's or grid sheet's stage forces from its shared law (``splitting.Uniform``:
    ``kernels.chain_uniform_force``, the sheet's grid path with the law as scalars) are the
    model's: the forward sweep is the Stepper's run bit for bit."""
    problem = _problem(name)
    traj, raw = trajectory_of(problem, nsteps=120, stride=40, integrator=integrator)
    assert traj.steps(raw).uni.kind == (splitting.UNI_SHEET if name.startswith("sheet") else splitting.UNI_CHAIN)
    rec, _ = traj.run(raw)
    stepper = make_stepper(problem, integrator, h=traj.h)
    for j in range(1, 4):
        stepper.advance(40)
        np.testing.assert_array_equal(rec.q[j], stepper.q)
        np.testing.assert_array_equal(rec.v[j], stepper.v)


@pytest.mark.parametrize("integrator", ADJOINTS)
def test_checkpointing_does_not_change_the_gradient(integrator):
    traj, raw = trajectory_of(_problem("chain-force-shaker"), nsteps=96, stride=4, integrator=integrator)
    objective = _objective((traj.n_samples, traj.obs.size))
    _, ref, _ = traj.gradient(raw, objective)  # every state kept
    for segment in (1, 13, 96):
        _, grad, _ = traj.gradient(raw, objective, segment=segment)
        for (k, a), (_, b) in zip(grad.items(), ref.items()):
            np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12 * np.abs(b).max(initial=0.0), err_msg=k)


@pytest.mark.parametrize("integrator", SPLITTINGS)
def test_kept_stage_forces_give_the_recomputed_gradient(integrator):
    """The reverse sweep reading the stage forces the replay kept gives the same bits as
    recomputing each step's stages (prescribed displacement, damping; all kept and segments; the
    general reverse sweep, which takes either)."""
    traj, raw = trajectory_of(_problem("chain-displacement-damped"), nsteps=60, stride=4, integrator=integrator)
    traj = dataclasses.replace(traj, uniform_sweeps=False)
    objective = _objective((traj.n_samples, traj.obs.size))
    kicks, drifts, fsal = traj._split
    stages = drifts.size if fsal else drifts.size - 1
    for segment in (None, 13):
        recomputing = traj.steps(raw)
        recomputing.stages = False
        v_ref, ref, _ = tape.gradient(recomputing, objective, segment, 256.0)
        value, grad, _ = tape.gradient(traj.steps(raw), objective, segment, 256.0)
        assert traj._scratch["stages"].shape == (60 if segment is None else 13, stages, raw.q0.size)
        assert value == v_ref
        for (k, a), (_, b) in zip(grad.items(), ref.items()):
            np.testing.assert_array_equal(a, b, err_msg=k)


#: scenes with every DOF free, whose kick factors are scalars per field (``splitting.field_factors``)
FREE = ("chain-shaker-free", "sheet-shaker")


def _uniform_problem(name: str):
    """A test scene whose chain or grid sheet is uniform; ``chain-shaker-free``: the shaken chain
    with its right end free; ``sheet-shaker``: the sheet under an applied force on its free left
    edge instead of a prescribed tilt."""
    if name not in FREE:
        return _problem(name)
    if name == "chain-shaker-free":
        data = {"name": "grad"} | copy.deepcopy(SCENES["chain-force-shaker"])
        data["lattice"]["right"] = "free"
        return build_problem(scene_from_dict(data))
    data = {"name": "grad"} | copy.deepcopy(SCENES["sheet-tilted-pulse-damped"])
    data["lattice"]["left"] = "free"
    data["excitation"] = {"kind": "shaker", "end": "left", "amplitude_n": 5.0, "frequency_hz": 2000.0,
                          "ramp_cycles": 1.0}
    return build_problem(scene_from_dict(data))


@pytest.mark.parametrize("integrator", SPLITTINGS)
@pytest.mark.parametrize("graded", [False, True])
@pytest.mark.parametrize("name", ["chain-displacement-damped", "chain-force-shaker", "chain-shaker-free",
                                  "sheet-tilted-pulse-damped", "sheet-shaker"])
def test_uniform_reverse_matches_the_general_reverse(name, graded, integrator, monkeypatch):
    """A uniform chain or grid sheet takes the reverse sweep with the uniform kernels per stage
    (``splitting.Uniform``), a graded one (k_θ varied per hinge) the column forms': either gives the
    general sweeps' gradient (the model's own adjoint kernel, kick factors per DOF) to rounding,
    damped, under a prescribed displacement or an applied force, with a held end (kick factors per
    DOF) or all DOFs free (scalars per field), every state kept or checkpointed, the objective
    entering every 3 steps (drift-first PEFRL reverses its recorded force there)."""
    traj, raw = trajectory_of(_uniform_problem(name), nsteps=60, stride=3, integrator=integrator)
    raw.v0[:] = np.random.default_rng(6).normal(scale=0.01, size=raw.v0.size)  # moving from the start
    if graded:
        raw.t1[:, H_KT] *= np.linspace(0.8, 1.2, raw.t1.shape[0])
    E = traj.steps(raw).method[2]
    assert E.shape[1] == ((2 if name.startswith("chain") else 3) if name in FREE else raw.q0.size)
    kinds = []
    reverse = splitting.reverse
    monkeypatch.setattr(splitting, "reverse", lambda *a: kinds.append(a[2].kind) or reverse(*a))
    objective = _objective((traj.n_samples, traj.obs.size), seed=4)
    refs = [dataclasses.replace(traj, column_sweeps=False), dataclasses.replace(traj, uniform_sweeps=False)]
    _assert_same_gradients(traj, refs, raw, objective)
    uniform = splitting.UNI_SHEET if name.startswith("sheet") else splitting.UNI_CHAIN
    assert set(kinds) == {splitting.UNI_NONE} | ({splitting.UNI_NONE} if graded else {uniform})


@pytest.mark.parametrize(("name", "integrator"), [
    pytest.param(n, i, marks=pytest.mark.slow) if (n, i) == ("mass-striker", "implicit_midpoint") else (n, i)
    for i in ADJOINTS for n in ("chain-displacement-damped", "mass-striker")]
    + [pytest.param("mass-friction-dashpots", "implicit_midpoint", marks=pytest.mark.slow)])
def test_tangent_matches_adjoint(name, integrator):
    """Forward sensitivities along a direction equal the adjoint gradient projected on it."""
    traj, raw = trajectory_of(_problem(name), nsteps=100, stride=5, integrator=integrator)
    objective = _objective((traj.n_samples, traj.obs.size), seed=3)
    _, grad, rec = traj.gradient(raw, objective)
    direction = raw.zeros()
    for block, d in _directions(raw, np.random.default_rng(5), traj.terms.drv_shape, traj.terms.drv_mode).items():
        setattr(direction, block, d)
    rec2, (tan,) = traj.sensitivities(raw, [direction])
    np.testing.assert_array_equal(rec2.q, rec.q)
    np.testing.assert_allclose(rec2.f, rec.f, rtol=0, atol=1e-13 * np.abs(rec.f).max())
    _, dq, dv, df, _ = objective(rec, raw)
    projected = np.sum(dq * tan.q) + np.sum(dv * tan.v) + np.sum(df * tan.f)
    assert projected == pytest.approx(grad.dot(direction), rel=1e-10)


def test_gradient_converges_at_each_methods_order():
    """dJ/d(raw) of a smooth objective (records at four fixed times, a prescribed Gaussian rotation
    at the stage times) against the finest BM6 run: the measured order over a range of h where
    the error is asymptotic and above rounding is 2, 4, 6 (the midpoint rule 2) within 0.3
    (measured: the midpoint rule 1.99, 5.4e-2 … 8.7e-4 at 64 … 512 steps). (Not the damping's
    gradient: BM6's order conditions hold for forces of q only, docs/physics.md §3.)"""
    problem = _problem("chain-gaussian-rotation")
    T = problem.duration

    def gradient(integrator, n):
        traj, raw = trajectory_of(problem, nsteps=n, stride=n // 4, h=T / n, integrator=integrator)
        _, g, _ = traj.gradient(raw, _objective((traj.n_samples, traj.obs.size)))
        return np.concatenate([getattr(g, k).ravel() for k in ("t1", "t2", "minv", "drv", "q0", "v0")])

    ref = gradient("blanes_moan6", 1024)
    for integrator, steps in (("velocity_verlet", [64, 128, 256, 512]), ("implicit_midpoint", [64, 128, 256, 512]),
                              ("pefrl", [32, 48, 64, 96, 128]),
                              ("blanes_moan6", [16, 24, 32, 48, 64])):
        err = [np.linalg.norm(gradient(integrator, n) - ref) / np.linalg.norm(ref) for n in steps]
        order = -np.polyfit(np.log(steps), np.log(err), 1)[0]
        assert abs(order - INTEGRATORS[integrator].order) < 0.3, (integrator, order, err)
        assert max(err) < 1e-1 and min(err) > 1e-13  # on the asymptotic range, above rounding


def test_integrators_without_adjoint_and_rk4_kicks_are_refused():
    problem = _problem("chain-force-shaker")
    for name in ("rk4", "dopri5"):
        with pytest.raises(GradientError, match="velocity_verlet, pefrl, blanes_moan6"):
            trajectory_of(problem, integrator=name)
    data = {"name": "grad"} | copy.deepcopy(SCENES["mass-smooth-step-damped"])
    data["damping"] = {"dashpot_n_s_per_m": 0.1}
    dashpots = build_problem(scene_from_dict(data))
    s = dashpots.system
    with pytest.raises(GradientError, match="dashpots"):
        Trajectory(s.args, dashpots.terms, dashpots.dt, 10, 1, [0], integrator="pefrl")


def _with(scene: dict, integrator: str) -> dict:
    return copy.deepcopy(scene) | {"solver": dict(scene["solver"], integrator=integrator)}


@pytest.mark.parametrize("integrator", ["pefrl", "implicit_midpoint"])
def test_design_differentiates_the_scenes_integrator(tmp_path, integrator):
    spec = {"name": "small_design", "scene": _with(DESIGN_SCENE, integrator), "variables": VARIABLES,
            "objective": [TERMS["peak_force"], TERMS["energy"]], "optimizer": {"max_iterations": 3}}
    path = tmp_path / "design.yaml"
    path.write_text(yaml.safe_dump(spec, sort_keys=False))
    design = load_design(path)
    assert design.traj.integrator == integrator
    _, _, _, err = check_gradient(design)
    assert np.all(err < 1e-6), err
    spec["scene"]["solver"]["integrator"] = "rk4"
    path.write_text(yaml.safe_dump(spec, sort_keys=False))
    with pytest.raises(GradientError, match="has no adjoint"):
        load_design(path)


@pytest.mark.parametrize("integrator", ["pefrl", "implicit_midpoint"])
def test_fit_recovers_the_parameters(tmp_path, monkeypatch, integrator):
    """A PEFRL or midpoint scene fitted to its own noise-free trace (exact Jacobian from the
    method's tangents)."""
    monkeypatch.setattr(test_fit, "SCENE", _with(test_fit.SCENE, integrator))
    fit = load_fit(test_fit._spec(tmp_path))
    assert fit.traj.integrator == integrator
    result = solve(fit)
    np.testing.assert_allclose(result.x, [test_fit.TRUE["k_rot"], test_fit.TRUE["zeta"]], rtol=1e-6)



@pytest.mark.parametrize(("name", "integrator"), [
    ("chain-displacement-damped", "pefrl"), ("chain-displacement-damped", "implicit_midpoint"),
    ("sheet-tilted-pulse-damped", "pefrl"),
    pytest.param("sheet-tilted-pulse-damped", "implicit_midpoint", marks=pytest.mark.slow)])
def test_column_forms_give_the_tables_gradient(name, integrator):
    """The reverse sweep's force adjoint in column form (a chain-ordered chain, a grid sheet) and
    the model's own adjoint kernel give the same gradient (PEFRL's reverse and the midpoint rule's,
    its Hessian products in the linear solve too, take either)."""
    traj, raw = trajectory_of(_problem(name), nsteps=60, stride=3, integrator=integrator)
    objective = _objective((traj.n_samples, traj.obs.size), seed=2)
    _, ref, _ = dataclasses.replace(traj, column_sweeps=False).gradient(raw, objective)
    _, grad, _ = traj.gradient(raw, objective)
    for (k, a), (_, b) in zip(grad.items(), ref.items()):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12 * np.abs(b).max(initial=0.0), err_msg=k)
