"""The tape's one compiled forward loop (``run``): N steps of any differentiable integrator with
checkpoints every ``seg`` steps and records every ``stride`` steps — the gradient's forward run
(from the start) and its replay of a segment (from a checkpoint, every state kept).

The integrator is the type of the loop's first argument, its step contract: ``VerletStep``
(``integrators.verlet.step``), ``SplitStep`` (``splitting.split_step``: the engine's splitting
step, or a uniform chain's or sheet's) or ``MidpointStep`` (``integrators.implicit.step``, its
Newton iteration to ``rtol``). Three functions, dispatched on that type at compile time (numba
``overload``: one specialisation of the loop per integrator, no compiled function passed as an
argument), give what differs:

- ``_scratch``: the step's work arrays;
- ``_state_force``: the force recorded with a state (the carried force, or for a drift-first
  splitting and the midpoint rule the total force at the state, one more evaluation);
- ``_step``: one step in place, keeping what the reverse step reads in row k (k + 1 for velocity
  Verlet's f_a, ``verlet.step_force``) of K if it has rows: velocity Verlet's f_a of the step
  into each state, a splitting's stage forces, the midpoint velocity; returns (t', converged).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba.core import types
from numba.extending import overload

from flexmm._jit import JIT_OPTIONS, NO_JIT, jit
from flexmm.design.splitting import _total_force, split_step
from flexmm.design.sweeps import _checkpoint, _record
from flexmm.integrators import verlet
from flexmm.integrators.common import free_damping, total_force
from flexmm.integrators.implicit import step as midpoint_step


class VerletStep(NamedTuple):
    """Velocity Verlet (``integrators.verlet.step``) with the per-DOF factors K, P, S
    (``design.sweeps``)."""

    args: tuple
    terms: tuple
    kick: np.ndarray
    pre: np.ndarray
    post: np.ndarray


class SplitStep(NamedTuple):
    """A kick/drift splitting (``design.splitting.split_step``): its ``Uniform``, kick and drift
    coefficients, kick factors E, G, and whether it is kick-first."""

    args: tuple
    terms: tuple
    uni: tuple
    kicks: np.ndarray
    drifts: np.ndarray
    E: np.ndarray
    G: np.ndarray
    fsal: bool


class MidpointStep(NamedTuple):
    """The implicit midpoint rule (``integrators.implicit.step``), Newton to ``rtol``."""

    args: tuple
    terms: tuple
    minv: np.ndarray
    damp: np.ndarray
    rtol: float


@jit
def _verlet_scratch(s, q):
    return verlet.scratch(s.terms, q.shape[0])


@jit
def _split_scratch(s, q):
    return np.empty(q.shape[0])


@jit
def _midpoint_scratch(s, q):
    n = q.shape[0]
    return free_damping(s.damp, s.minv), np.empty((14, n)), np.zeros(2), np.empty(n)  # (acc: the ledger only)


@jit
def _verlet_state_force(s, w, q, v, f, t, k):
    return f


@jit
def _split_state_force(s, w, q, v, f, t, k):
    if k == 0 or s.fsal:  # (at the start: the caller's force)
        return f
    _total_force(s.args, s.terms, s.uni, q, t, w)
    return w


@jit
def _midpoint_state_force(s, w, q, v, f, t, k):
    if k == 0:
        return f
    fr = w[3]
    total_force(s.args, q, v, t, fr, s.terms)
    return fr


@jit
def _verlet_step(s, w, q, v, f, t, h, K, k):
    g, fa, u = w
    t = verlet.step(s.args, s.terms, s.kick, s.pre, s.post, q, v, f, t, h, g, fa, u)
    if K.shape[0] > 0 and fa.shape[0] > 0:
        K[k + 1, :] = fa
    return t, True


@jit
def _split_step(s, w, q, v, f, t, h, K, k):
    return split_step(s.args, s.terms, s.uni, s.kicks, s.drifts, s.E, s.G, s.fsal, q, v, f, t, h,
                      K[k if K.shape[1] > 0 else 0]), True


@jit
def _midpoint_step(s, w, q, v, f, t, h, K, k):
    cd, work, acc, _ = w
    if not midpoint_step(s.args, s.terms, s.minv, s.damp, cd, q, v, f, t, h, acc, work, s.rtol):
        return t, False
    if K.shape[0] > 0:
        K[k, :] = work[7]
    return t + h, True


_IMPLS = {
    VerletStep: (_verlet_scratch, _verlet_state_force, _verlet_step),
    SplitStep: (_split_scratch, _split_state_force, _split_step),
    MidpointStep: (_midpoint_scratch, _midpoint_state_force, _midpoint_step),
}


def _scratch(s, q):
    return _IMPLS[type(s)][0](s, q)


def _state_force(s, w, q, v, f, t, k):
    return _IMPLS[type(s)][1](s, w, q, v, f, t, k)


def _step(s, w, q, v, f, t, h, K, k):
    return _IMPLS[type(s)][2](s, w, q, v, f, t, h, K, k)


if not NO_JIT:

    def _impl(s, i):
        if isinstance(s, types.BaseNamedTuple) and s.instance_class in _IMPLS:
            return _IMPLS[s.instance_class][i]
        return None

    @overload(_scratch, jit_options=JIT_OPTIONS)
    def _scratch_overload(s, q):
        fn = _impl(s, 0)
        return None if fn is None else (lambda s, q: fn(s, q))

    @overload(_state_force, jit_options=JIT_OPTIONS)
    def _state_force_overload(s, w, q, v, f, t, k):
        fn = _impl(s, 1)
        return None if fn is None else (lambda s, w, q, v, f, t, k: fn(s, w, q, v, f, t, k))

    @overload(_step, jit_options=JIT_OPTIONS)
    def _step_overload(s, w, q, v, f, t, h, K, k):
        fn = _impl(s, 2)
        return None if fn is None else (lambda s, w, q, v, f, t, h, K, k: fn(s, w, q, v, f, t, h, K, k))


@jit
def run(s, q, v, f, t, h, nsteps, seg, stride, obs, CQ, CV, CF, CT, K, Rq, Rv, Rf):
    """Run ``nsteps`` of the integrator ``s`` from (q, v, f, t) (f: the force at the start) in
    place; checkpoint (q, v, f, t) every ``seg`` steps (rows of CQ, CV, CF, CT), record (q, v,
    force)[obs] every ``stride`` steps (rows of Rq, Rv, Rf), keep what the reverse step reads in
    K (``_step``; with seg = 1 and no records: the replay of a segment). Returns (t, the first
    step that did not converge or −1)."""
    w = _scratch(s, q)
    for k in range(nsteps + 1):
        if k % seg == 0:
            _checkpoint(q, v, f, t, CQ, CV, CF, CT, k // seg)
        if k % stride == 0:
            _record(q, v, _state_force(s, w, q, v, f, t, k), obs, Rq, Rv, Rf, k // stride)
        if k < nsteps:
            t, ok = _step(s, w, q, v, f, t, h, K, k)
            if not ok:
                return t, k
    return t, -1
