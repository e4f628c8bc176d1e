"""Exact gradients through velocity Verlet (flexmm.design): adjoint vs central finite differences.

Every scene is small (a few units, 200 steps) so finite differences over random directions in
each block of raw arrays are cheap; the adjoint must match them to 1e-6 relative (central
differences themselves are good to ~1e-9 here). Scenes cover every model kind with gradient
kernels (rotating-squares chain, loaded chain and sheet, the sheet with magnets, the bistable
linkage, rotating triangles, chains of masses), on-site damping, dashpots between units, ground
friction, prescribed displacements and applied forces (half-sine, Gaussian, smooth step,
harmonic), a striker contact, fixed ends and checkpointed reverse sweeps.
"""

from __future__ import annotations

import copy
import dataclasses
import math

import numpy as np
import pytest
from conftest import LEGO_CHAIN, LEGO_SHEET

from flexmm.assemble import build_problem
from flexmm.config import scene_from_dict
from flexmm.design import sweeps
from flexmm.design import steps as fast
from flexmm.design.gradient import GradientError, Trajectory, raw_of, trajectory_of
from flexmm.design.steps import ENGINE_SITES, TILE_SITES, ChainColumns, UniformChain, UniformSheet
from flexmm.design.tape import ENGINE_MIN_STEPS, MEMORY_MB, SEGMENT_MB, TILE_STEPS, chain_segment, tile_segment
from flexmm.design.kernels import N_R, N_V, chain_columns, chain_force_columns
from flexmm.design.sweeps import FORM_CHAIN, FORM_TABLES
from flexmm.integrators.common import MODE_FRICTION, SHAPES
from flexmm.integrators.stepper import make_stepper
from flexmm.models.hinge import BLOCK, H_SIGN, S_KG, ChainArgs, chain_force

CHAIN = dict(LEGO_CHAIN, n_units=6, theta0_rad=0.2)
MASS = {"kind": "mass_chain", "n_units": 6, "spacing_m": 0.01, "mass_kg": 0.01,
        "bond": {"law": "polynomial", "k1_n_per_m": 100.0, "k2_n_per_m2": 2e3, "k3_n_per_m3": 1e5}}

SHEET = dict(LEGO_SHEET, n_rows=3, n_cols=4, theta0_rad=0.15)
#: configs/j_magnets_transition_wave.yaml's units (a 2 × 3 strip)
MAGNETS = {"kind": "rotating_squares_sheet", "n_rows": 2, "n_cols": 3, "a_m": 0.02, "k_long_n_per_m": 5e4,
           "k_shear_n_per_m": 5e4, "k_rot_n_m_per_rad": 0.01, "mass_kg": 0.005,
           "magnets": {"moment_a_m2": 0.253, "recess_m": 0.003, "polarity": "attract"}}
#: configs/k_linkage_transition_wave.yaml's bars and joints (3 columns)
LINKAGE = {"kind": "bistable_linkage", "n_cols": 3, "bar_length_m": 0.02, "theta0_rad": 1.0472,
           "theta_deployed_rad": 0.4363, "mass_kg": 0.002, "k_pin_n_per_m": 1e5, "released_energy_j": 1.5,
           "barrier_fraction": 0.3}
TRIANGLES = {"a_m": 0.02, "theta0_rad": 0.1, "k_long_n_per_m": 71690, "k_shear_n_per_m": 7169,
             "k_rot_n_m_per_rad": 0.5735, "mass_kg": 4.52e-3}

SCENES = {
    "sheet-tilted-pulse-damped": {
        "lattice": dict(SHEET, left="driven"),
        "excitation": {"kind": "boundary_displacement", "end": "left", "amplitude_m": 1e-3, "angle_deg": 20.0,
                       "duration_s": 1e-3, "shape": "half_sine"},
        "damping": {"viscous": {"damping_ratio": 0.05}},
        "imperfection": {"kind": "random_rotation", "std_rad": 0.01, "seed": 2},
        "solver": {"duration_s": 3e-3}},
    "sheet-dashpots": {
        "lattice": dict(SHEET, left="driven"),
        "excitation": {"kind": "boundary_displacement", "end": "left", "amplitude_m": 1e-3, "angle_deg": 20.0,
                       "duration_s": 1e-3, "shape": "half_sine"},
        "damping": {"viscous": {"damping_ratio": 0.02}, "dashpot_n_s_per_m": 0.5},
        "imperfection": {"kind": "random_rotation", "std_rad": 0.01, "seed": 2},
        "solver": {"duration_s": 3e-3}},
    "chain-displacement-damped": {
        "lattice": dict(CHAIN, left="driven", right="fixed"),
        "excitation": {"kind": "boundary_displacement", "end": "left", "amplitude_m": 1e-3,
                       "duration_s": 1e-3, "shape": "half_sine"},
        "damping": {"viscous": {"damping_ratio": 0.05}},
        "imperfection": {"kind": "rotation_seed", "theta_rad": 0.01, "sites": [2]},
        "solver": {"duration_s": 3e-3}},
    "chain-gaussian-rotation": {
        "lattice": dict(CHAIN, left="driven", right="free"),
        "excitation": {"kind": "boundary_displacement", "end": "left", "amplitude_rad": 0.3,
                       "duration_s": 4e-4, "shape": "gaussian"},
        "solver": {"duration_s": 3e-3}},
    "chain-force-shaker": {
        "lattice": dict(CHAIN, left="free", right="fixed"),
        "excitation": {"kind": "shaker", "end": "left", "amplitude_n": 5.0, "frequency_hz": 2000.0,
                       "ramp_cycles": 1.0},
        "damping": {"viscous": {"coefficient_n_s_per_m": 0.2}},
        "solver": {"duration_s": 3e-3}},
    "mass-smooth-step-damped": {
        "lattice": dict(MASS, left="driven", right="fixed"),
        "excitation": {"kind": "boundary_displacement", "end": "left", "amplitude_m": 2e-3,
                       "duration_s": 0.05, "shape": "smooth_step"},
        "damping": {"viscous": {"damping_ratio": 0.02}},
        "solver": {"duration_s": 0.3}},
    "chain-dashpots-damped": {
        "lattice": dict(CHAIN, left="driven", right="fixed"),
        "excitation": {"kind": "boundary_displacement", "end": "left", "amplitude_m": 1e-3,
                       "duration_s": 1e-3, "shape": "half_sine"},
        "damping": {"viscous": {"damping_ratio": 0.02}, "dashpot_n_s_per_m": 0.5},
        "imperfection": {"kind": "rotation_seed", "theta_rad": 0.01, "sites": [2]},
        "solver": {"duration_s": 3e-3}},
    "mass-friction-dashpots": {
        "lattice": dict(MASS, left="driven", right="free",
                        friction={"force_n": 0.05, "regularisation_m_s": 0.05}),
        "excitation": {"kind": "boundary_displacement", "end": "left", "amplitude_m": 2e-3,
                       "duration_s": 0.047, "shape": "smooth_step"},  # ends between steps (C³ there)
        "damping": {"viscous": {"damping_ratio": 0.05}, "dashpot_n_s_per_m": 0.05},
        "solver": {"duration_s": 0.3}},
    "sheet-magnets-rotation-damped": {
        "lattice": dict(MAGNETS, left="driven", theta0_rad=0.05),
        "excitation": {"kind": "boundary_displacement", "end": "left", "amplitude_rad": 0.3,
                       "duration_s": 2e-3, "shape": "smooth_step"},
        "damping": {"viscous": {"damping_ratio": 0.02}},
        "solver": {"duration_s": 3e-3}},
    "linkage-deploy-damped": {  # the first joint switches
        "lattice": dict(LINKAGE, left="driven"),
        "excitation": {"kind": "boundary_displacement", "end": "left", "amplitude_rad": -0.6,
                       "duration_s": 6e-4, "shape": "smooth_step"},
        "damping": {"viscous": {"damping_ratio": 0.02}},
        "solver": {"duration_s": 1.2e-3}},
    "chain-loaded-pull": {  # predeformed by constant end loads
        "lattice": dict(CHAIN, theta0_rad=0.05, predeform={
            "loads": [{"end": "left", "force_n": 0.2}, {"end": "right", "force_n": 0.2}], "theta_guess_rad": 0.1}),
        "excitation": {"kind": "boundary_force", "end": "left", "amplitude_n": -1.0, "duration_s": 2e-3,
                       "shape": "half_sine"},
        "solver": {"duration_s": 5e-3}},
    "triangles-chain-push": {
        "lattice": {"kind": "rotating_triangles_chain", "n_units": 6, **TRIANGLES, "left": "driven"},
        "excitation": {"kind": "boundary_displacement", "end": "left", "amplitude_m": 1e-3, "duration_s": 2e-3,
                       "shape": "gaussian"},
        "solver": {"duration_s": 6e-3}},
    "triangles-sheet-damped": {
        "lattice": {"kind": "rotating_triangles_sheet", "n_rows": 2, "n_cols": 4, **TRIANGLES, "left": "driven",
                    "bottom": "periodic", "top": "periodic",
                    "variation": [{"kind": "gradient", "target": "k_rot_n_m_per_rad", "start": 0.4, "end": 0.8}]},
        "excitation": {"kind": "boundary_displacement", "end": "left", "amplitude_m": 1e-3, "duration_s": 2e-3,
                       "shape": "half_sine"},
        "damping": {"viscous": {"damping_ratio": 0.03}},
        "solver": {"duration_s": 6e-3}},
    "chain-striker": {  # a striker's DOF after the chain's, a Hertzian contact between them
        "lattice": dict(CHAIN, left="free", right="fixed"),
        "excitation": {"kind": "impact", "end": "left", "velocity_m_s": 0.5,
                       "striker": {"mass_kg": 0.05, "contact_stiffness_n_per_m": 1e6, "exponent": 1.5}},
        "damping": {"viscous": {"damping_ratio": 0.02}},
        "solver": {"duration_s": 3e-3}},
    "mass-striker": {
        "lattice": dict(MASS, left="free", right="fixed"),
        "excitation": {"kind": "impact", "end": "left", "velocity_m_s": 0.5,
                       "striker": {"mass_kg": 0.05, "contact_stiffness_n_per_m": 3e4, "exponent": 1.5}},
        "solver": {"duration_s": 0.01}},
}


def _problem(name: str):
    data = {"name": "grad"} | copy.deepcopy(SCENES[name])
    problem = build_problem(scene_from_dict(data))
    if "striker" in problem.system.extra_dofs:
        # start in contact: a Hertz contact closing at δ = 0 makes the run only C¹ in its
        # inputs (the adjoint is still exact, but central differences converge too slowly there)
        idx, _ = problem.system.extra_dofs["striker"]
        problem.system.q0[idx] += 2e-4
    return problem


def _objective(shape, seed=1):
    """A smooth objective of every record: weighted squares of q and f, linear in v."""
    rng = np.random.default_rng(seed)
    wq, wv, wf = (rng.normal(size=shape) for _ in range(3))

    def objective(rec, raw):
        value = 0.5 * np.sum(wq * rec.q**2) + 0.1 * np.sum(wv * rec.v) + 0.3 * np.sum(wf * rec.f**2)
        return value, wq * rec.q, 0.1 * wv, 0.6 * wf * rec.f, None

    return objective


def _directions(raw, rng, raw_shapes, modes=None):
    """A random direction per raw block (zero on discrete columns and held DOFs' m⁻¹; with the
    drives' ``modes``, friction rows vary F₊ and F₋ alike, so symmetric friction stays smooth)."""
    out = {}
    for name, arr in raw.items():
        if arr.size == 0:
            continue
        finite = np.isfinite(arr)
        scale = max(np.abs(arr[finite]).max(initial=0.0), 1e-2)
        d = rng.normal(size=arr.shape) * np.maximum(np.abs(np.where(finite, arr, 0.0)), 1e-2 * scale)
        if name == "t1" and arr.ndim == 2 and arr.shape[1] == 7:
            d[:, H_SIGN] = 0.0  # the checkerboard sign is discrete
        if name == "minv":
            d[arr == 0.0] = 0.0
        if name == "con":
            d[:, 2] = 0.0  # contact direction ±1
        d[~np.isfinite(arr)] = 0.0  # e.g. a drive that never stops
        if name == "drv":  # harmonic drives: amplitude and ω only (ramp and stop times are fixed)
            d[raw_shapes == SHAPES["harmonic"], 2:] = 0.0
            if modes is not None:
                fr = modes == MODE_FRICTION
                d[fr, 2] = d[fr, 0]
                d[fr, 3] = 0.0
        if np.any(d):
            out[name] = d
    return out


def _central(traj, raw, arr, base, d, objective):
    """Central difference of J along d at the step where it is most stable.

    Steps 1e-3 … 1e-7: truncation error falls and rounding error grows as the step shrinks;
    the plateau is where consecutive estimates agree best (chosen without the adjoint).
    """

    def diff(e):
        arr[...] = base + e * d
        jp = traj.value(raw, objective)
        arr[...] = base - e * d
        jm = traj.value(raw, objective)
        arr[...] = base
        return (jp - jm) / (2 * e)

    est = [diff(e) for e in (1e-3, 1e-4, 1e-5, 1e-6, 1e-7)]
    k = min(range(len(est) - 1), key=lambda i: abs(est[i + 1] - est[i]))
    return 0.5 * (est[k] + est[k + 1])


@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.slow)
                                  if n in ("mass-friction-dashpots", "linkage-deploy-damped") else n
                                  for n in sorted(SCENES)])
def test_adjoint_matches_central_differences(name):
    problem = _problem(name)
    traj, raw = trajectory_of(problem, nsteps=200, stride=5)
    objective = _objective((traj.n_samples, traj.obs.size))
    value, grad, _ = traj.gradient(raw, objective, segment=7)  # 29 checkpointed segments
    assert value == pytest.approx(traj.value(raw, objective), rel=1e-13)
    rng = np.random.default_rng(0)
    worst = 0.0
    for block, d in _directions(raw, rng, traj.terms.drv_shape, traj.terms.drv_mode).items():
        arr = getattr(raw, block)
        base = arr.copy()
        fd = _central(traj, raw, arr, base, d, objective)
        adj = float(np.vdot(getattr(grad, block), d))
        err = abs(adj - fd) / abs(fd)
        worst = max(worst, err)
        assert err < 1e-6, (block, adj, fd)
    assert worst < 1e-6


@pytest.mark.parametrize("name", ["chain-displacement-damped", "mass-striker", "chain-dashpots-damped",
                                  "mass-smooth-step-damped", "mass-friction-dashpots", "sheet-dashpots"])
def test_forward_sweep_is_the_engine_run(name):
    """The differentiated run is the Stepper's velocity-Verlet run: both take ``verlet.step``'s
    passes and force (``verlet.step_force``), so a damped run is the same bit for bit; an
    undamped one to rounding (the engine adds the two half kicks between steps as one)."""
    problem = _problem(name)
    traj, raw = trajectory_of(problem, nsteps=120, stride=120)
    rec, _ = traj.run(raw)
    stepper = make_stepper(problem, "velocity_verlet", h=traj.h)
    stepper.advance(120)
    if np.any(raw.damp * raw.minv != 0.0):
        np.testing.assert_array_equal(rec.q[-1], stepper.q)
        np.testing.assert_array_equal(rec.v[-1], stepper.v)
        np.testing.assert_array_equal(rec.f[-1], stepper.f)
    np.testing.assert_allclose(rec.q[-1], stepper.q, rtol=0, atol=1e-12 * np.abs(stepper.q).max())
    np.testing.assert_allclose(rec.v[-1], stepper.v, rtol=0, atol=1e-12 * np.abs(stepper.v).max())


def test_column_force_is_the_chain_force():
    """The column sweeps' force is ``hinge.chain_force`` bit for bit (a graded chain longer than
    one of its blocks, lateral stretch on part of it)."""
    rng = np.random.default_rng(4)
    n = BLOCK + 300
    hprm = np.abs(rng.normal(1.0, 0.2, size=(n - 1, 7)))
    hprm[:, H_SIGN] = np.where(np.arange(n - 1) % 2, -1.0, 1.0)
    sprm = np.abs(rng.normal(0.3, 0.1, size=(n, 3)))
    sprm[: n // 2, S_KG] = 0.0
    idx = np.arange(n - 1)
    args = ChainArgs(idx, idx + 1, hprm, sprm, np.empty(n), np.empty(n))
    q = rng.normal(scale=0.05, size=2 * n)
    expected = np.empty(2 * n)
    chain_force(q, args, expected)
    got = np.empty(2 * n)
    chain_force_columns(q, chain_columns(hprm, sprm), True, np.empty((N_R, n + 1)), got)
    np.testing.assert_array_equal(got, expected)


@pytest.mark.parametrize("name", ["chain-displacement-damped", "chain-force-shaker", "sheet-tilted-pulse-damped",
                                  "chain-dashpots-damped", pytest.param("chain-loaded-pull", marks=pytest.mark.slow),
                                  "chain-striker"])
def test_column_sweeps_match_the_general_sweeps(name):
    """Same records bit for bit, same gradient to rounding, checkpointed or not (chains: the
    column sweeps, uniform or not — with dashpots the general run and the column reverse step,
    with constant loads and with a striker's DOF and contact too; grid sheets: the general sweeps
    with the grid's hinges in column form)."""
    traj, raw = trajectory_of(_problem(name), nsteps=120, stride=3)
    assert traj.form(raw)[0] != FORM_TABLES
    general = dataclasses.replace(traj, column_sweeps=False)
    objective = _objective((traj.n_samples, traj.obs.size), seed=2)
    _, ref, rec_ref = general.gradient(raw, objective)
    for path in (traj, dataclasses.replace(traj, uniform_sweeps=False)):
        for segment in (None, 11):
            _, grad, rec = path.gradient(raw, objective, segment=segment)
            np.testing.assert_array_equal(rec.q, rec_ref.q)
            np.testing.assert_array_equal(rec.f, rec_ref.f)
            for (k, a), (_, b) in zip(grad.items(), ref.items()):
                np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12 * np.abs(b).max(initial=0.0), err_msg=k)


@pytest.mark.parametrize("name,free", [("chain-force-shaker", True), ("chain-displacement-damped", False)])
def test_uniform_sweeps_match_the_general_sweeps(name, free):
    """A uniform chain's reverse sweep (scalar parameters; integrator factors scalar per field
    when both ends are free, per-DOF columns with a fixed or driven end), damped and driven
    (an applied force; a prescribed displacement), equals the general sweeps' and the column
    sweeps' gradient to rounding, checkpointed or not, the objective entering every 3 steps."""
    problem = _problem(name)
    if free:
        data = {"name": "grad"} | copy.deepcopy(SCENES[name])
        data["lattice"]["right"] = "free"
        problem = build_problem(scene_from_dict(data))
    traj, raw = trajectory_of(problem, nsteps=120, stride=3)
    args, terms, kick, pre, post = traj.bind(raw)
    uniform = traj.steps(raw)
    assert type(uniform) is UniformChain
    u, fac = uniform.u, uniform.fac
    assert all(isinstance(x, float) for x in fac) == free
    states = []
    loads = traj._columns(raw)[2:]
    for replay, extra in ((sweeps.chain_uniform_replay, (u, False, *loads, fac)),
                          (sweeps.chain_replay, traj._columns(raw))):
        _, (CQ, CV, CF, CT, _) = traj.run(raw, segment=50)
        SQ, SV, ST = np.empty((51, raw.q0.size)), np.empty((51, raw.q0.size)), np.empty(51)
        if replay is sweeps.chain_replay:
            replay(*extra, terms, kick, pre, post, CQ[1], CV[1], CF[1], CT[1], traj.h, 50, SQ, SV, ST)
        else:
            SF = np.empty((51, raw.q0.size))
            replay(*extra, terms, CQ[1], CV[1], CF[1], CT[1], traj.h, 50, SQ, SV, SF, ST,
                   np.empty((51, 2, raw.t2.shape[0])), np.empty((N_V, raw.t2.shape[0] + 1)))
            np.testing.assert_array_equal(SF[-1], CF[2])  # the kept forces are the run's
        np.testing.assert_array_equal(SQ[-1], CQ[2])  # the replay ends on the next checkpoint
        states.append((SQ, SV, ST))
    for a, b in zip(*states):  # the uniform replay is the column replay, bit for bit
        np.testing.assert_array_equal(a, b)
    objective = _objective((traj.n_samples, traj.obs.size), seed=4)
    refs = [dataclasses.replace(traj, column_sweeps=False), dataclasses.replace(traj, uniform_sweeps=False)]
    _assert_same_gradients(traj, refs, raw, objective)


@pytest.mark.parametrize("excitation", ["shaker", "displacement"])
def test_uniform_sheet_sweeps_match_the_general_sweeps(excitation):
    """A uniform grid sheet's reverse sweep (the shared hinge law as scalars, signs per hinge;
    integrator factors scalar per field under an applied force, per-DOF columns with a driven
    edge), damped and driven, equals the general sweeps' and the grid columns' gradient to
    rounding, checkpointed or not, the objective entering every 3 steps."""
    data = {"name": "grad"} | copy.deepcopy(SCENES["sheet-tilted-pulse-damped"])
    data.pop("imperfection")
    if excitation == "shaker":
        data["lattice"]["left"] = "free"
        data["excitation"] = {"kind": "shaker", "end": "left", "amplitude_n": 5.0, "frequency_hz": 2000.0,
                              "ramp_cycles": 1.0}
    traj, raw = trajectory_of(build_problem(scene_from_dict(data)), nsteps=120, stride=3)
    raw.v0[:] = np.random.default_rng(6).normal(scale=0.01, size=raw.v0.size)  # moving from the start
    sheet = traj.steps(raw)
    assert type(sheet) is UniformSheet and all(isinstance(x, float) for x in sheet.fac) == (excitation == "shaker")
    objective = _objective((traj.n_samples, traj.obs.size), seed=7)
    refs = [dataclasses.replace(traj, column_sweeps=False), dataclasses.replace(traj, uniform_sweeps=False)]
    assert refs[1].form(raw)[0] == sweeps.FORM_GRID and type(refs[1].steps(raw)) is fast.Verlet
    _assert_same_gradients(traj, refs, raw, objective)


@pytest.mark.parametrize("name", ["chain-force-shaker", "chain-displacement-damped"])
def test_tiled_sweeps_are_the_whole_chain_sweeps(name, monkeypatch):
    """A long uniform chain's segments replayed and swept back window by window
    (``sweeps.chain_uniform_tiles``; here 200 units in windows of 64 interior sites) give the whole
    chain's gradient bit for bit — moving everywhere from the start, driven (an applied force; a
    prescribed displacement, with a fixed end: factors per DOF), damped, every third step
    observed at a scattered half of the DOFs. With halos one site a step (half the needed
    width) the windows' ends reach their interiors and the gradient differs."""
    data = {"name": "grad"} | copy.deepcopy(SCENES[name])
    data["lattice"]["n_units"] = 200
    problem = build_problem(scene_from_dict(data))
    obs = np.random.default_rng(3).permutation(problem.system.ndof)[: problem.system.ndof // 2]
    traj, raw = trajectory_of(problem, nsteps=60, stride=3, obs=obs)
    raw.v0[:] = np.random.default_rng(5).normal(scale=0.02, size=raw.v0.size)
    monkeypatch.setattr(fast, "TILE_MIN_SITES", 1)
    monkeypatch.setattr(fast, "TILE_SITES", 64)
    calls = []
    tiles = sweeps.chain_uniform_tiles
    monkeypatch.setattr(sweeps, "chain_uniform_tiles", lambda *a: calls.append(a[9]) or tiles(*a))
    whole = dataclasses.replace(traj, tiles=False)
    objective = _objective((traj.n_samples, traj.obs.size), seed=8)
    for segment in (5, 7):
        value, grad, _ = traj.gradient(raw, objective, segment=segment)
        assert calls[-1] == 0 and len(calls) == math.ceil(60 / segment)  # 60 steps
        calls.clear()
        ref_value, ref, _ = whole.gradient(raw, objective, segment=segment)
        assert value == ref_value
        for (k, a), (_, b) in zip(grad.items(), ref.items()):
            np.testing.assert_array_equal(a, b, err_msg=k)
    assert np.any(grad.drv != 0.0)
    monkeypatch.setattr(sweeps, "tile_halo", lambda steps: steps)
    _, short, _ = traj.gradient(raw, objective, segment=7)
    assert not all(np.array_equal(a, b) for (_, a), (_, b) in zip(short.items(), ref.items()))
    calls.clear()
    traj.gradient(raw, objective, segment=30)  # halos wider than half a window: the whole chain's sweeps
    assert not calls


def _assert_same_gradients(traj, refs, raw, objective):
    """traj's gradient equals each of refs' to rounding, checkpointed (segments of 11) or not."""
    for segment in (None, 11):
        _, grad, _ = traj.gradient(raw, objective, segment=segment)
        for other in refs:
            _, ref, _ = other.gradient(raw, objective, segment=segment)
            for (k, a), (_, b) in zip(grad.items(), ref.items()):
                np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12 * np.abs(b).max(initial=0.0), err_msg=k)


def test_engine_forward_is_the_column_forward():
    """A long damped chain under a prescribed displacement runs forward by the engine's fused
    kernel (``steps.ChainColumns._engine_run``): the same checkpoints and records bit for bit as
    ``sweeps.chain_forward``."""
    data = {"name": "grad"} | copy.deepcopy(SCENES["chain-displacement-damped"])
    data["lattice"]["n_units"] = ENGINE_SITES
    traj, raw = trajectory_of(build_problem(scene_from_dict(data)), nsteps=96, stride=32)
    steps = traj.steps(raw)
    assert isinstance(steps, ChainColumns)
    q = raw.q0.copy()
    assert steps._engine_run(q, raw.v0.copy(), np.zeros_like(q), 48, traj._buffers(q.size, 3), traj._records())
    rec, checkpoints = traj.run(raw, segment=48)
    rec_ref, ref = dataclasses.replace(traj, engine_forward=False).run(raw, segment=48)
    for a, b in zip((rec.q, rec.v, rec.f) + checkpoints[:4], (rec_ref.q, rec_ref.v, rec_ref.f) + ref[:4]):
        np.testing.assert_array_equal(a, b)


def test_checkpoint_segment_does_not_change_the_gradient():
    traj, raw = trajectory_of(_problem("chain-force-shaker"), nsteps=240, stride=4)
    objective = _objective((traj.n_samples, traj.obs.size))
    _, g1, _ = traj.gradient(raw, objective, segment=1)
    _, g2, _ = traj.gradient(raw, objective, segment=240)
    _, g3, rec3 = traj.gradient(raw, objective)  # √N
    _, g4, rec4 = traj.gradient(raw, objective)  # again, in the arrays the last one left (``_scratch_array``)
    assert rec4.q is not rec3.q
    for (k, c), (_, d) in zip(g3.items(), g4.items()):
        np.testing.assert_array_equal(c, d, err_msg=k)
    for (k, a), (_, b), (_, c) in zip(g1.items(), g2.items(), g3.items()):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12 * np.abs(a).max(initial=0.0), err_msg=k)
        np.testing.assert_allclose(a, c, rtol=1e-12, atol=1e-12 * np.abs(a).max(initial=0.0), err_msg=k)


@pytest.mark.parametrize("nsteps,ndof,state", [(1000, 20_000, 4), (4000, 2000, 4), (10**6, 200, 4),
                                               (10**6, 20_000, 2), (1000, 200_000, 4)])
def test_chain_segment_fits_the_cache_with_bounded_memory(nsteps, ndof, state):
    """A chain's default segment: √N steps, or fewer where a segment's replayed states would pass
    SEGMENT_MB, never below ENGINE_MIN_STEPS nor so short that the checkpoints pass the memory
    budget (so a 10⁶-step run stays bounded)."""
    seg = chain_segment(nsteps, ndof, state * ndof * 8, MEMORY_MB)
    assert 1 <= seg <= max(1, math.isqrt(nsteps))
    fits = seg * state * ndof * 8 <= SEGMENT_MB * 1e6
    checkpoints_mb = (nsteps // seg + 1) * 3 * ndof * 8 / 1e6
    assert checkpoints_mb <= MEMORY_MB * 1.01 or seg == math.isqrt(nsteps)
    if not fits:  # too long for the cache only where the floors hold it
        assert seg in (math.isqrt(nsteps), ENGINE_MIN_STEPS) or checkpoints_mb >= 0.99 * MEMORY_MB


@pytest.mark.parametrize("nsteps,ndof", [(1000, 20_000), (10, 20_000), (10**6, 20_000), (10**7, 200_000)])
def test_tile_segment_is_bounded_in_memory(nsteps, ndof):
    """A tiled chain's segment: TILE_STEPS steps (at most the run), longer only where the
    checkpoints would pass the memory budget (a 10⁷-step run of 10⁵ units stays bounded); its
    windows hold their halos."""
    seg = tile_segment(nsteps, ndof, MEMORY_MB)
    assert 1 <= seg <= nsteps
    assert (nsteps // seg + 1) * 3 * ndof * 8 <= MEMORY_MB * 1e6
    assert seg == min(nsteps, TILE_STEPS) or seg > TILE_STEPS
    windows = sweeps.tile_windows(ndof // 2, TILE_SITES, sweeps.tile_halo(seg))
    a, b, a0 = windows.T
    length = min(ndof // 2, TILE_SITES + 2 * sweeps.tile_halo(seg))
    assert a[0] == 0 and b[-1] == ndof // 2 and np.all(a[1:] == b[:-1])  # the interiors tile the chain
    assert np.all((a0 >= 0) & (a0 + length <= ndof // 2))
    halo = sweeps.tile_halo(seg)
    assert np.all((a - a0 >= halo) | (a0 == 0)) and np.all((a0 + length - b >= halo) | (a0 + length == ndof // 2))


@pytest.mark.parametrize("name", ["chain-displacement-damped", "mass-striker", "chain-dashpots-damped", "mass-smooth-step-damped",
                                  "mass-friction-dashpots"])
def test_tangent_matches_adjoint(name):
    """Forward sensitivities along a direction equal the adjoint gradient projected on it."""
    traj, raw = trajectory_of(_problem(name), nsteps=100, stride=5)
    objective = _objective((traj.n_samples, traj.obs.size), seed=3)
    _, grad, rec = traj.gradient(raw, objective)
    rng = np.random.default_rng(5)
    dirs = _directions(raw, rng, traj.terms.drv_shape, traj.terms.drv_mode)
    direction = raw.zeros()
    for block, d in dirs.items():
        setattr(direction, block, d)
    rec2, (tan,) = traj.sensitivities(raw, [direction])
    np.testing.assert_array_equal(rec2.q, rec.q)
    _, dq, dv, df, _ = objective(rec, raw)
    projected = np.sum(dq * tan.q) + np.sum(dv * tan.v) + np.sum(df * tan.f)
    assert projected == pytest.approx(grad.dot(direction), rel=1e-10)


def test_velocity_terms_take_the_general_run_and_the_column_reverse():
    """A chain with dashpots runs forward by the general sweeps (the column run has no velocity
    terms) and reverses with the chain's column form, reading the G each state kept; raw arrays
    whose dashpot coefficients do not match the dashpots are refused."""
    traj, raw = trajectory_of(_problem("chain-dashpots-damped"), nsteps=4, stride=1)
    assert raw.dash.size == traj.terms.dash_ij.shape[0] > 0
    assert traj.columns(raw) and type(traj.steps(raw)) is fast.Verlet and traj.form(raw)[0] == FORM_CHAIN
    with pytest.raises(ValueError, match="dashpots"):
        traj.run(dataclasses.replace(raw, dash=raw.dash[:-1]))


def _anisotropic_friction(moving: bool):
    """The friction scene without its drive, friction 0.05 N forward and 0.08 N backward; if
    ``moving``, every site starts at ±0.1–0.3 m/s (signs mixed)."""
    data = {"name": "grad"} | copy.deepcopy(SCENES["mass-friction-dashpots"])
    data["lattice"] |= {"left": "free", "friction": data["lattice"]["friction"] | {"backward_force_n": 0.08}}
    data.pop("excitation")
    problem = build_problem(scene_from_dict(data))
    if moving:
        rng = np.random.default_rng(7)
        v0 = problem.system.v0
        v0[:] = rng.choice([-1.0, 1.0], v0.size) * rng.uniform(0.1, 0.3, v0.size) / problem.system.scales.velocity
    return problem


def test_anisotropic_friction_is_differentiated_while_moving():
    """F₊ ≠ F₋ on every site, varied independently; the sites' velocities change sign during the
    run (between steps), where the law is smooth: the adjoint matches central differences."""
    traj, raw = trajectory_of(_anisotropic_friction(True), nsteps=200, stride=5)
    rec, _ = traj.run(raw)
    assert np.sum(np.diff(np.sign(rec.v), axis=0) != 0) >= 3  # velocities cross zero
    objective = _objective((traj.n_samples, traj.obs.size))
    _, grad, _ = traj.gradient(raw, objective, segment=7)
    dirs = _directions(raw, np.random.default_rng(1), traj.terms.drv_shape)
    assert np.all(dirs["drv"][:, 0] != dirs["drv"][:, 2])
    for block, d in dirs.items():
        arr = getattr(raw, block)
        fd = _central(traj, raw, arr, arr.copy(), d, objective)
        adj = float(np.vdot(getattr(grad, block), d))
        assert abs(adj - fd) < 1e-6 * abs(fd), (block, adj, fd)


def test_anisotropic_friction_at_rest_is_refused():
    """Sites at rest under F₊ ≠ F₋ make the run non-differentiable (the slope of the law jumps at
    v = 0: one-sided differences disagree), so ``trajectory_of`` refuses it."""
    problem = _anisotropic_friction(False)
    with pytest.raises(GradientError, match="anisotropic ground friction"):
        trajectory_of(problem)
    s = problem.system
    traj = Trajectory(s.args, problem.terms, problem.dt, 100, 5, np.arange(s.ndof))
    raw = raw_of(s, problem.terms, problem.damp)
    objective = _objective((traj.n_samples, traj.obs.size))
    j0 = traj.value(raw, objective)
    e = 1e-7
    raw.v0[2] = e
    right = (traj.value(raw, objective) - j0) / e
    raw.v0[2] = -e
    left = (j0 - traj.value(raw, objective)) / e
    assert abs(right - left) > 0.1 * abs(left)
