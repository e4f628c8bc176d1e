"""Shared helpers for the mass-chain tests: run a problem in memory, read switching times."""

from __future__ import annotations

import numpy as np

from flexmm.assemble import build_problem
from flexmm.config import scene_from_dict, load_scene
from flexmm.integrators import INTEGRATORS


def problem_from(lattice: dict, duration_s: float, **extra):
    """Build a Problem from a lattice dict plus optional scene sections."""
    return build_problem(scene_from_dict({"name": "t", "lattice": lattice,
                                          "solver": {"duration_s": duration_s, **extra.pop("solver", {})},
                                          **extra}))


def run_in_memory(problem, n_frames: int = 400):
    """Integrate with the scene's integrator; return (t (F,), q (F, ndof), v (F, ndof), work)."""
    s = problem.system
    spec = INTEGRATORS[problem.scene.solver.integrator]
    terms = problem.terms_tuple()
    q, v = s.q0.copy(), s.v0.copy()
    f, acc = np.zeros_like(q), np.zeros(2)
    spec.init(s.force, s.args, q, v, 0.0, f, terms)
    per = max(1, int(np.ceil(problem.duration / problem.dt / n_frames)))
    h = problem.duration / (per * n_frames)
    t, ts, qs, vs = 0.0, [0.0], [q.copy()], [v.copy()]
    for _ in range(n_frames):
        t = spec.advance(s.force, s.args, q, v, f, s.inv_mass, problem.damp, terms, t, h, per, acc)
        ts.append(t)
        qs.append(q.copy())
        vs.append(v.copy())
    return np.array(ts), np.array(qs), np.array(vs), acc


def run_config(path: str, overrides: list[str] | None = None, n_frames: int = 400):
    """Load a scene file and integrate it in memory; returns (problem, t, q, v)."""
    problem = build_problem(load_scene(path, overrides or []))
    t, q, v, _ = run_in_memory(problem, n_frames)
    return problem, t, q, v


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
