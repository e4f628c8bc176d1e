"""Shared helpers for the mass-chain tests: run a problem in memory, read switching times."""

from __future__ import annotations

import numpy as np

from flexmm.assemble import build_problem
from flexmm.config import scene_from_dict
from flexmm.integrators.runner import integrate


def problem_from(lattice: dict, duration_s: float, **extra):
    """Build a Problem from a lattice dict plus optional scene sections."""
    return build_problem(scene_from_dict({"name": "t", "lattice": lattice,
                                          "solver": {"duration_s": duration_s, **extra.pop("solver", {})},
                                          **extra}))


def run_in_memory(problem, n_frames: int = 400):
    """Integrate with the scene's integrator; return (t (F,), q (F, ndof), v (F, ndof), acc)."""
    tr = integrate(problem, problem.scene.solver.integrator, h=problem.dt, n_frames=n_frames + 1,
                   check_energy=False)
    return tr.t, tr.q, tr.v, tr.acc


def crossing_times(t: np.ndarray, s: np.ndarray, level: float = 0.5) -> np.ndarray:
    """First time each column of s (F, n) crosses ``level`` upwards (linear interpolation); nan if never."""
    out = np.full(s.shape[1], np.nan)
    for i in range(s.shape[1]):
        j = np.flatnonzero(s[:, i] > level)
        if j.size and j[0] > 0:
            k = j[0]
            out[i] = t[k - 1] + (level - s[k - 1, i]) / (s[k, i] - s[k - 1, i]) * (t[k] - t[k - 1])
    return out


def peak_times(t: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Time of the maximum of each column of y (F, n), refined by a parabola."""
    out = np.full(y.shape[1], np.nan)
    dt = t[1] - t[0]
    for i in range(y.shape[1]):
        k = int(np.argmax(y[:, i]))
        if 0 < k < len(t) - 1:
            a, b, c = y[k - 1, i], y[k, i], y[k + 1, i]
            den = a - 2 * b + c
            out[i] = t[k] + (0.5 * (a - c) / den * dt if den < 0 else 0.0)
    return out
