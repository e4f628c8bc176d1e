"""Integrate a built problem in memory with any registered method (no dataset, no progress).

Used by the stability scan, the work–precision benchmark and the tests: the same
``advance`` interface as the controller, with frames at uniform times kept as arrays, a
blow-up check at each frame, wall time measured after a compile warm-up, and the counters
of the accumulator (force evaluations, steps).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from flexmm.integrators import INTEGRATORS, IntegratorSpec
from flexmm.integrators import parallel
from flexmm.integrators.common import ACC_STEPS, apply_prescribed, contact_energy
from flexmm.integrators.runaway import RunawayGuard



@dataclass
class Trajectory:
    """Frames of a run: t (F,), q and v (F, ndof), the final accumulator and what it cost."""

    t: np.ndarray
    q: np.ndarray
    v: np.ndarray
    acc: np.ndarray
    status: str  # 'finished' or 'failed' (non-finite state or runaway energy)
    wall_s: float  # integration only (compile excluded)
    threads: int = 1
    cpu_s: float = 0.0  # process CPU time of the integration (all threads)
    counters: dict = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.status == "finished"


def _spec(integrator) -> IntegratorSpec:
    return INTEGRATORS[integrator] if isinstance(integrator, str) else integrator


def energy(problem, q: np.ndarray, v: np.ndarray) -> float:
    """Kinetic + potential (+ contact) energy, nondimensional."""
    s, terms = problem.system, problem.terms
    return float(s.kinetic_energy(v) + s.energy(q, s.args) + contact_energy(q, terms["con_ij"], terms["con_prm"]))


def integrate(problem, integrator, *, h: float | None = None, rtol: float | None = None,
              atol: float | None = None, max_step: float | None = None, t_end: float | None = None,
              n_frames: int = 2, threads: int = 1, q0: np.ndarray | None = None,
              v0: np.ndarray | None = None, check_energy: bool = True) -> Trajectory:
    """Run ``integrator`` from the problem's initial state (or q0, v0) to ``t_end``.

    Fixed-step methods take ``h`` (rounded down so every frame interval holds whole steps);
    adaptive ones take ``rtol`` (and ``atol``, ``max_step``), or ``h`` for fixed steps.
    Frames are at k·t_end/(n_frames − 1). A non-finite state or an energy above
    energy that runs away (flexmm.integrators.runaway) stops the run as 'failed'.
    """
    spec = _spec(integrator)
    s = problem.system
    t_end = problem.duration if t_end is None else t_end
    terms = problem.terms_tuple()
    adaptive = spec.adaptive and rtol is not None
    acc = spec.new_acc(s.ndof, rtol=rtol, atol=atol, max_step=max_step) if adaptive else spec.new_acc(s.ndof)
    advance, force, used = parallel.kernels(spec, s.force, threads)
    interval = t_end / (n_frames - 1)
    if adaptive:
        h_run, per_frame = interval, 1
    else:
        per_frame = max(1, math.ceil(interval / h - 1e-9))
        h_run = interval / per_frame
    q = (s.q0 if q0 is None else q0).copy()
    v = (s.v0 if v0 is None else v0).copy()
    f = np.zeros_like(q)
    apply_prescribed(q, v, 0.0, *terms[4:])
    spec.init(force, s.args, q, v, 0.0, f, terms)
    # compile / warm up on copies (one step), so wall time is integration only
    advance(force, s.args, q.copy(), v.copy(), f.copy(), s.inv_mass, problem.damp, terms, 0.0,
            h_run, 1, acc.copy())
    guard = RunawayGuard(s, terms, energy(problem, q, v))
    ts, qs, vs = np.zeros(n_frames), np.zeros((n_frames, s.ndof)), np.zeros((n_frames, s.ndof))
    qs[0], vs[0] = q, v
    status, k, t = "finished", 0, 0.0
    wall = cpu = 0.0
    for k in range(1, n_frames):
        t0, c0 = time.perf_counter(), time.process_time()
        t = advance(force, s.args, q, v, f, s.inv_mass, problem.damp, terms, t, h_run, per_frame, acc)
        wall += time.perf_counter() - t0
        cpu += time.process_time() - c0
        ts[k], qs[k], vs[k] = t, q, v
        bad = not (np.isfinite(q).all() and np.isfinite(v).all())
        if not bad and check_energy:
            e = energy(problem, q, v)
            bad = guard.runaway(e, acc[1])
        if bad:
            status = "failed"
            break
        if check_energy:
            guard.record(int(acc[ACC_STEPS]) if adaptive else k * per_frame, e)
    n = k + 1
    return Trajectory(ts[:n], qs[:n], vs[:n], acc, status, wall, used, cpu, spec.counters(acc))


def run_fixed(problem, integrator, h: float, t_end: float | None = None, n_frames: int = 2, **kw) -> Trajectory:
    """Fixed steps of about ``h`` (see ``integrate``)."""
    return integrate(problem, integrator, h=h, t_end=t_end, n_frames=n_frames, **kw)
