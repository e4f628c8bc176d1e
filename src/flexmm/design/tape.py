"""The gradient's one checkpointing tape: a forward run that keeps checkpoints (or every state),
then one reverse sweep over its segments, replayed from the checkpoints, for any differentiable
integrator through a small contract (``Steps``; the integrators' own in ``design.steps``).

Memory: a run whose kept states (``Steps.state_bytes`` each) fit in the budget keeps them all
and the reverse sweep reads them (no replay); a longer one keeps (q, v, f, t) every ``segment``
steps (default ⌈√nsteps⌉, or what the integrator's fast path asks: ``Steps.segment``) and the
reverse sweep replays one segment at a time, so a run of N steps keeps about 2√N states plus its
records (a 1e6-step run of a 100-unit chain: 10 MB instead of 4.8 GB), for one more forward run.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from functools import cached_property
from typing import Callable

import numpy as np

from flexmm.errors import FlexmmError

#: a run whose states fit in this many MB keeps them all (no replay); larger runs checkpoint
MEMORY_MB = 256.0
#: a chain's default segment is shortened so that its replayed states take at most this many MB
#: (they are read back by the reverse sweep from cache, not memory), down to ``ENGINE_MIN_STEPS``
#: steps and as long as the checkpoints stay within the memory budget
SEGMENT_MB = 8.0
#: the shortest default segment of a chain (the engine's fused forward kernel stops at most this often,
#: ``steps.ChainColumns``)
ENGINE_MIN_STEPS = 8
#: a tiled chain's segment (``steps.UniformChain``; a window's halo grows with it)
TILE_STEPS = 32


class GradientError(FlexmmError):
    """A problem whose run cannot be differentiated (an unsupported model or term)."""


@dataclass
class Raw:
    """The differentiable arrays of a problem (nondimensional): model tables ``t1``, ``t2``,
    ``minv`` and ``damp`` (ndof,), contact rows ``con`` (C, 3), drive rows ``drv`` (D, 4; ground
    friction's rows (F₊, v_ε, F₋, 0) among them), the initial state ``q0``, ``v0``, and the
    dashpot coefficients ``dash`` (P,; last, and empty by default, so arrays built without it
    still construct: ``Trajectory.bind`` checks its size against the dashpots). A gradient has
    the same structure."""

    t1: np.ndarray
    t2: np.ndarray
    minv: np.ndarray
    damp: np.ndarray
    con: np.ndarray
    drv: np.ndarray
    q0: np.ndarray
    v0: np.ndarray
    dash: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def zeros(self) -> Raw:
        return Raw(*(np.zeros_like(getattr(self, f.name)) for f in fields(self)))

    def items(self):
        return ((f.name, getattr(self, f.name)) for f in fields(self))

    def dot(self, other: Raw) -> float:
        return float(sum(np.vdot(a, getattr(other, k)) for k, a in self.items()))

    def axpy(self, a: float, other: Raw) -> Raw:
        return Raw(*(x + a * getattr(other, k) for k, x in self.items()))

    def slope(self, other: Raw, step: float) -> Raw:
        """(self − other) / step, zero where the two are equal (also equal infinities)."""
        return Raw(*(np.where(x == getattr(other, k), 0.0, (x - getattr(other, k)) / step)
                     for k, x in self.items()))


@dataclass
class Records:
    """(q, v, f) at the observed DOFs, one row per recorded step (nondimensional)."""

    q: np.ndarray
    v: np.ndarray
    f: np.ndarray


#: an objective maps the records (and the raw arrays) to (value, dJ/dq, dJ/dv, dJ/df, dJ/draw or None)
Objective = Callable[[Records, Raw], tuple]


@dataclass
class Adjoints:
    """The reverse sweep's arrays: the objective's adjoints of the records (dq, dv, df: (samples,
    obs)), the state's (lq, lv, lf: (ndof,), entering as those of the run's last state) and the
    parameters' (g1, g2, gcon, gdrv, gdash: zero, shaped as the raw arrays)."""

    dq: np.ndarray
    dv: np.ndarray
    df: np.ndarray
    lq: np.ndarray
    lv: np.ndarray
    lf: np.ndarray
    g1: np.ndarray
    g2: np.ndarray
    gcon: np.ndarray
    gdrv: np.ndarray
    gdash: np.ndarray


class Steps:
    """One differentiable integrator bound to one point ``raw`` of a ``Trajectory``: what the tape
    drives. A new integrator implements, on arrays of its own layout:

    1. ``state_bytes``: the bytes of one state a keep-all tape keeps (q, v, f and what its reverse
       step reads: velocity Verlet's f_a, a splitting's stage forces, the midpoint velocity);
    2. ``forward(seg, scratch, keep)``: the run from raw.q0, v0 with checkpoints (q, v, f, t) every
       ``seg`` steps and the records, returning (``Records``, (CQ, CV, CF, CT, seg)); ``keep``
       (with seg = 1): also what ``kept`` hands the reverse step;
    3. ``kept(checkpoints)`` and ``replay(checkpoints, c, m)``: the states of the whole run, or of
       the m steps from checkpoint c, as its ``reverse`` reads them;
    4. ``begin(adjoints)``, ``reverse(states, k0, m)``: the reverse of steps k0 + m → k0, adjoints
       in place; ``end(checkpoints)``: the gradient (``Raw``), after the reverse of the start;
    5. ``tangent(directions, records, TQ, TV, TF)``: the forward (tangent-linear) run.

    Optional: ``budget_mb`` (the memory a keep-all tape may take), ``segment`` (the default
    segment), ``sweep_segment`` (a fused replay and reverse of one segment). Fast paths are
    subclasses chosen by ``steps.steps_of`` from one table.
    """

    #: the bytes of one state of a keep-all tape (besides its time)
    state_bytes: int = 0

    def __init__(self, traj, raw: Raw, form: tuple):
        self.traj, self.raw, self.form = traj, raw, form
        self.adj: Adjoints | None = None

    @cached_property
    def n(self) -> int:
        return self.raw.q0.size

    def budget_mb(self, memory_mb: float) -> float:
        return memory_mb

    def segment(self, nsteps: int, memory_mb: float, asked: int | None) -> int:
        """The checkpoint segment of a tape that does not keep every state."""
        return asked or default_segment(nsteps)

    def forward(self, seg: int, scratch: bool = False, keep: bool = False) -> tuple[Records, tuple]:
        raise NotImplementedError

    def kept(self, checkpoints: tuple) -> tuple:
        raise NotImplementedError

    def replay(self, checkpoints: tuple, c: int, m: int) -> tuple:
        raise NotImplementedError

    def begin(self, adj: Adjoints) -> None:
        self.adj = adj

    def reverse(self, states: tuple, k0: int, m: int) -> None:
        raise NotImplementedError

    def sweep_segment(self, checkpoints: tuple, c: int, k0: int, m: int) -> None:
        self.reverse(self.replay(checkpoints, c, m), k0, m)

    def end(self, checkpoints: tuple) -> Raw:
        raise NotImplementedError

    def tangent(self, directions: list[Raw], rec: Records, TQ, TV, TF) -> None:
        raise NotImplementedError


def default_segment(nsteps: int) -> int:
    """⌈√nsteps⌉ steps (at least 1)."""
    return max(1, math.isqrt(max(nsteps, 1)))


def chain_segment(nsteps: int, ndof: int, state_bytes: int, memory_mb: float) -> int:
    """A chain's checkpoint segment: ⌈√nsteps⌉ steps, or fewer so that a segment's replayed states
    (``state_bytes`` a step) take at most ``SEGMENT_MB``, but not fewer than ``ENGINE_MIN_STEPS``
    nor than keeps the checkpoints ((q, v, f) every segment) within ``memory_mb``."""
    seg = default_segment(nsteps)
    fit = max(ENGINE_MIN_STEPS, int(SEGMENT_MB * 1e6 // state_bytes))
    bounded = -(-(nsteps + 1) * 3 * ndof * 8 // int(memory_mb * 1e6))  # ceil: checkpoints within the budget
    return min(seg, max(fit, bounded))


def tile_segment(nsteps: int, ndof: int, memory_mb: float) -> int:
    """A tiled chain's checkpoint segment: ``TILE_STEPS`` steps (a window's halo grows with it;
    fewer checkpoints cut the forward run's time blocks less often), at most the run, but not
    fewer than keeps the checkpoints within ``memory_mb``."""
    seg = max(1, min(nsteps, TILE_STEPS))
    rows = int(memory_mb * 1e6 // (3 * ndof * 8))  # checkpoints (q, v, f) the budget holds
    bounded = -(-nsteps // (rows - 1)) if rows > 1 else nsteps  # nsteps // seg + 1 <= rows
    return max(seg, bounded)


def seed(steps: Steps, rec: Records, objective: Objective) -> tuple:
    """The objective's value and explicit gradient, and the reverse sweep's ``Adjoints``: the
    state's at the last step (its records') and zeroed parameter adjoints."""
    traj, raw, n = steps.traj, steps.raw, steps.n
    value, dq, dv, df, explicit = objective(rec, raw)
    dq, dv, df = (np.ascontiguousarray(np.broadcast_to(a, rec.q.shape), float) for a in (dq, dv, df))
    lq, lv, lf = np.zeros(n), np.zeros(n), np.zeros(n)
    j = traj.nsteps // traj.stride
    lq[traj.obs] += dq[j]
    lv[traj.obs] += dv[j]
    lf[traj.obs] += df[j]
    return value, explicit, Adjoints(dq, dv, df, lq, lv, lf, np.zeros_like(raw.t1), np.zeros_like(raw.t2),
                                     np.zeros_like(raw.con), np.zeros_like(raw.drv), np.zeros_like(raw.dash))


def gradient(steps: Steps, objective: Objective, segment: int | None = None,
             memory_mb: float = MEMORY_MB) -> tuple[float, Raw, Records]:
    """(J, dJ/draw, records) by one forward run and one reverse sweep of ``steps``.

    If no ``segment`` is asked for and every state fits in ``steps.budget_mb(memory_mb)``, the
    forward run keeps them all and the reverse sweep reads them; otherwise it keeps checkpoints
    every ``segment`` steps (default ``steps.segment``) and the reverse sweep replays one segment
    at a time, from the last.
    """
    N = steps.traj.nsteps
    keep_all = segment is None and (N + 1) * (steps.state_bytes + 8) <= steps.budget_mb(memory_mb) * 1e6
    seg = 1 if keep_all else steps.segment(N, memory_mb, segment)
    rec, checkpoints = steps.forward(seg, scratch=True, keep=keep_all)
    value, explicit, adj = seed(steps, rec, objective)
    steps.begin(adj)
    if keep_all:
        steps.reverse(steps.kept(checkpoints), 0, N)
    else:
        for c in range((N - 1) // seg if N else -1, -1, -1):
            steps.sweep_segment(checkpoints, c, c * seg, min(seg, N - c * seg))
    grad = steps.end(checkpoints)
    if explicit is not None:
        grad = grad.axpy(1.0, explicit)
    return float(value), grad, rec


def sensitivities(steps: Steps, directions: list[Raw]) -> tuple[Records, list[Records]]:
    """Records and their derivatives along each raw direction (one forward tangent run)."""
    traj = steps.traj
    rec = traj._records()
    shape = (len(directions), traj.n_samples, traj.obs.size)
    TQ, TV, TF = np.empty(shape), np.empty(shape), np.empty(shape)
    steps.tangent(directions, rec, TQ, TV, TF)
    return rec, [Records(TQ[m], TV[m], TF[m]) for m in range(len(directions))]


def stack(raw: Raw, directions: list[Raw], name: str) -> np.ndarray:
    """The directions' arrays ``name`` stacked (first axis: the direction)."""
    return np.ascontiguousarray(np.stack([getattr(d, name) for d in directions]) if directions else
                                np.zeros((0,) + getattr(raw, name).shape))
