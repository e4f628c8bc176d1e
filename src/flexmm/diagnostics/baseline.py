"""scipy.integrate.solve_ivp on flexmm's equations: the baseline a user would otherwise pick.

The right-hand side wraps the compiled acceleration (model force, contacts, dashpots, drives,
friction, on-site damping; ``integrators.common.acceleration``) in a Python function of
y = [q, v]: y' = [v, a(q, v, t)], prescribed DOFs following their waveform. Frames come
from solve_ivp's own dense output (``t_eval``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp

from flexmm.integrators.common import acceleration, apply_prescribed

METHODS = ("RK45", "DOP853", "LSODA")


def make_rhs(problem):
    """(rhs(t, y), counter) for ``problem``; ``counter[0]`` counts calls (= force evaluations)."""
    s = problem.system
    terms = problem.terms
    n = s.ndof
    f, a = np.zeros(n), np.zeros(n)
    q, v = np.zeros(n), np.zeros(n)
    counter = [0]

    def rhs(t, y):
        counter[0] += 1
        q[:] = y[:n]
        v[:] = y[n:]
        acceleration(s.args, terms, s.inv_mass, problem.damp, t, q, v, f, a)
        return np.concatenate([v, a])

    return rhs, counter


@dataclass
class IvpRun:
    t: np.ndarray
    q: np.ndarray  # (F, ndof)
    v: np.ndarray
    status: str
    wall_s: float
    cpu_s: float  # process CPU time (includes BLAS threads of LSODA's linear algebra)
    force_evaluations: int
    message: str


def run(problem, method: str, rtol: float, atol: float, times: np.ndarray) -> IvpRun:
    """solve_ivp(method, rtol, atol) from the problem's initial state, frames at ``times``."""
    s = problem.system
    n = s.ndof
    q0, v0 = s.q0.copy(), s.v0.copy()
    apply_prescribed(q0, v0, 0.0, *problem.terms.drives)
    rhs, counter = make_rhs(problem)
    rhs(0.0, np.concatenate([q0, v0]))  # compile outside the timing
    counter[0] = 0
    t0, c0 = time.perf_counter(), time.process_time()
    sol = solve_ivp(rhs, (float(times[0]), float(times[-1])), np.concatenate([q0, v0]), method=method,
                    rtol=rtol, atol=atol, t_eval=times)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    y = sol.y.T if sol.success else np.full((times.size, 2 * n), np.nan)
    return IvpRun(times, y[:, :n], y[:, n:], "finished" if sol.success else "failed", wall, cpu,
                  counter[0], sol.message)
