"""Integrate a built problem in memory with any registered method (no dataset, no progress).

Used by the stability scan, the work–precision benchmark and the tests: the controller's
``Stepper`` with frames at uniform times kept as arrays, its blow-up check at each frame,
wall time measured after the compile warm-up, and the accumulator's counters.
"""

from __future__ import annotations

import math

from dataclasses import dataclass, field

import numpy as np

from flexmm.integrators import INTEGRATORS
from flexmm.integrators.common import contact_energy
from flexmm.integrators.stepper import frame_chunks, make_stepper
from flexmm.models.kernels import model_energy



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


def energy(problem, q: np.ndarray, v: np.ndarray) -> float:
    """Kinetic + potential (+ contact) energy, nondimensional."""
    s, terms = problem.system, problem.terms
    return float(s.kinetic_energy(v) + model_energy(q, s.args) + contact_energy(q, terms.con_ij, terms.con_prm))


def integrate(problem, integrator, *, h: float | None = None, rtol: float | None = None,
              atol: float | None = None, max_step: float | None = None, t_end: float | None = None,
              n_frames: int = 2, threads: int = 1, q0: np.ndarray | None = None,
              v0: np.ndarray | None = None, check_energy: bool = True, ledger: bool = True) -> Trajectory:
    """Run ``integrator`` from the problem's initial state (or q0, v0) to ``t_end``.

    Fixed-step methods take ``h`` (rounded down so every frame interval holds whole steps);
    adaptive ones take ``rtol`` (and ``atol``, ``max_step``), or ``h`` for fixed steps.
    Frames are at k·t_end/(n_frames − 1). A non-finite state or an energy that runs away
    (flexmm.integrators.runaway) stops the run as 'failed'; ``ledger=False`` keeps only the
    blow-up checks (no energy-ledger balance: a stability measurement, not an accuracy one).
    """
    t_end = problem.duration if t_end is None else t_end
    spec = INTEGRATORS[integrator] if isinstance(integrator, str) else integrator
    adaptive = spec.adaptive and rtol is not None
    if adaptive:
        h_run, chunks = t_end / (n_frames - 1), [1] * (n_frames - 1)
    else:
        h_run, chunks = frame_chunks(t_end, h, n_frames)
    st = make_stepper(problem, spec, h=h_run, rtol=rtol if adaptive else None, atol=atol,
                      max_step=max_step, threads=threads, q0=q0, v0=v0, check_energy=check_energy,
                      drift_tol=None if ledger else math.inf)
    ts, qs, vs = [st.t], [st.q.copy()], [st.v.copy()]

    def keep(s) -> None:
        ts.append(s.t)
        qs.append(s.q.copy())
        vs.append(s.v.copy())

    outcome = st.run(chunks, keep)
    if not outcome.ok:  # keep the failed frame too (the callers look at where it broke)
        keep(st)
    return Trajectory(np.array(ts), np.array(qs), np.array(vs), st.acc, outcome.status, st.wall_s,
                      st.threads, st.cpu_s, st.ledger.counters())


def run_fixed(problem, integrator, h: float, t_end: float | None = None, n_frames: int = 2, **kw) -> Trajectory:
    """Fixed steps of about ``h`` (see ``integrate``)."""
    return integrate(problem, integrator, h=h, t_end=t_end, n_frames=n_frames, **kw)
