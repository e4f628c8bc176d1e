"""Largest linear frequency ω_max of a built system and the step-size limits it sets (docs/physics.md §3).

ω_max² is the largest eigenvalue of M^{-1/2} K M^{-1/2} over the free DOFs, with K the
Hessian of the energy at a reference state (rest by default), obtained from central
differences of the compiled force (``flexmm.linalg.force_hessian``). One-sided contacts (a
striker) enter with their stiffness at the expected peak overlap, p k δ^(p−1), since a Hertz
contact stiffens with overlap. The eigenvalue itself is ``flexmm.linalg.top_eigenvalue``: dense
for small systems, Lanczos otherwise. A lattice of more than ``BOUND_MIN_DOFS`` DOFs, where
Lanczos's few hundred force evaluations over the whole lattice cost more than many of its runs,
takes ω_max from bounds instead (``flexmm.linalg.banded_bounds``, O(10) force evaluations): the
Gershgorin bound, which is ≥ the true ω_max, when it is within ``BOUND_MARGIN`` of the lower
bound of a window of the lattice, else (a bound that loose, or a lattice not banded) Lanczos.

A fixed-step explicit method is linearly stable while h ω_max ≤ its ``stability_limit``
(harmonic oscillator; ``harmonic_limit`` recomputes it from the compiled method).
Softening or contact laws change ω_max along the motion, so ``trajectory_omega_max`` also
samples ω_max along a short pilot run (used by ``flexmm stability``).
"""

from __future__ import annotations

import math

import numpy as np

from flexmm.errors import FlexmmError
from flexmm.integrators.common import Terms
from flexmm.linalg import (
    DENSE_LIMIT,
    banded_bounds,
    force_hessian,
    top_eigenpair,
    top_eigenvalue,
    warm_lanczos,
)
from flexmm.models.base import System

#: lattices above this many DOFs take ω_max from bounds (smaller ones: the whole-lattice solve)
BOUND_MIN_DOFS = 100_000
#: the bound is used when upper/lower ≤ 1 + this (in ω); a step from it is at most this much shorter
BOUND_MARGIN = 0.02
GRID_STEP = 2e-4  # scan of h·ω in ``harmonic_limit``: Blanes–Moan's band at hω ≈ π is 9e-4 wide


def _contact_stiffness(system: System, terms: Terms) -> list[tuple[int, int, float]]:
    out = []
    for (i, j), (k, p, _) in zip(terms.con_ij, terms.con_prm):
        if p == 1.0:
            out.append((int(i), int(j), float(k)))
            continue
        delta = _peak_overlap(system, k, p, int(i))  # all the striker's kinetic energy stored
        out.append((int(i), int(j), float(p * k * delta ** (p - 1.0))))
    return out


def _peak_overlap(system: System, k: float, p: float, i: int) -> float:
    """Overlap of a power-law contact when all the striker's kinetic energy is stored in it:
    ½ M v² = k δ^(p+1)/(p+1)."""
    e_kin = 0.5 * system.mass[i] * system.v0[i] ** 2
    return ((p + 1.0) * e_kin / k) ** (1.0 / (p + 1.0)) if e_kin > 0 else 0.0


def reached_state(system: System, terms: Terms, q_ref: np.ndarray | None = None) -> np.ndarray | None:
    """The compressed state a stiffening striker contact (exponent > 1) drives the lattice to, or None.

    Every longitudinal bond is given the striker's peak overlap δ (energy balance,
    ``_peak_overlap``): u_m = u_ref,m − d δ (x_m − x_j)/a from the struck site j, d the contact's
    direction. A lattice whose stiffness vanishes at rest (a Hertz chain: a sonic vacuum) has its
    fastest mode there, not at rest; for other lattices the uniform compression is a bound on what
    the wave can reach (docs/physics.md §3).
    """
    best = None
    for (i, j), (k, p, d) in zip(terms.con_ij, terms.con_prm):
        if p <= 1.0:
            continue
        delta = _peak_overlap(system, k, p, int(i))
        if delta > 0 and (best is None or delta > best[0]):
            best = (delta, int(j), d)
    if best is None:
        return None
    delta, j, d = best
    n = system.n_sites
    f = system.field_index(system.longitudinal_field)
    if j >= system.ndof or j // n != f or f * n + n > system.ndof:
        return None
    x = np.asarray(system.site_coords.get("x", np.arange(n) * system.spacing_m), float)
    q = np.zeros(system.ndof) if q_ref is None else np.array(q_ref, float)
    q[f * n : (f + 1) * n] -= d * delta * (x - x[j - f * n]) / system.spacing_m
    return q


def hessian_operator(system: System, terms: Terms, q_ref: np.ndarray | None = None):
    """Matrix-free Hessian-vector product K x at ``q_ref`` (default: rest), contacts included."""
    q_ref = np.zeros(system.ndof) if q_ref is None else q_ref
    kx = force_hessian(system.force, system.args, q_ref)
    contacts = _contact_stiffness(system, terms)
    if not contacts:
        return kx

    def matvec(x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, float).ravel()
        y = kx(x)
        for i, j, k in contacts:
            d = x[i] - x[j]
            y[i] += k * d
            y[j] -= k * d
        return y

    return matvec


def dynamical_operator(system: System, terms: Terms, q_ref: np.ndarray | None = None):
    """(x ↦ M^{-1/2} K M^{-1/2} x on all DOFs, the free DOFs): zero weight on held DOFs, so its
    spectrum is that over the free DOFs plus zeros."""
    w = np.sqrt(np.maximum(system.inv_mass, 0.0))
    kx = hessian_operator(system, terms, q_ref)
    return (lambda x: w * kx(w * x)), np.flatnonzero(system.inv_mass > 0)


def omega_max(system: System, terms: Terms, q_ref: np.ndarray | None = None) -> float:
    """Largest angular frequency of small oscillations about ``q_ref`` (nondimensional)."""
    op, free = dynamical_operator(system, terms, q_ref)
    if free.size > BOUND_MIN_DOFS:
        bounds = banded_bounds(op, system.n_sites, system.ndof, (1 + BOUND_MARGIN) ** 2)
        if bounds is not None and bounds[0] > 0 and bounds[1] <= (1 + BOUND_MARGIN) ** 2 * bounds[0]:
            return float(np.sqrt(bounds[1]))
    lam = top_eigenvalue(op, system.ndof, free, DENSE_LIMIT)
    return float(np.sqrt(max(lam, 0.0)))


def top_mode(system: System, terms: Terms, q_ref: np.ndarray | None = None) -> tuple[float, np.ndarray]:
    """(ω_max, shape (ndof,)): the fastest small-oscillation mode about ``q_ref`` (default rest).

    The shape x solves K x = ω_max² M x (held DOFs 0), scaled to max |x| = 1. Exciting this mode
    alone is the sharpest test of a method's linear stability limit (``stability_scan``).
    """
    op, free = dynamical_operator(system, terms, q_ref)
    lam, y = top_eigenpair(op, system.ndof, free, DENSE_LIMIT)
    shape = np.sqrt(np.maximum(system.inv_mass, 0.0)) * y
    return float(np.sqrt(max(lam, 0.0))), shape / np.max(np.abs(shape))


def trajectory_omega_max(problem, n_samples: int = 8, duration_fraction: float = 1.0) -> tuple[float, float]:
    """Max of ω_max over ``n_samples`` states of a pilot run (velocity Verlet at a safe step).

    The pilot covers ``duration_fraction`` of the scene; returns (max ω_max, time of the max).
    Covers softening or stiffening laws and contacts whose stiffness at rest says little.
    """
    from flexmm.integrators.runner import run_fixed

    t_end = problem.duration * duration_fraction
    w0 = problem.omega_max
    h = 0.2 * 2.0 / w0 if w0 > 0 else problem.dt
    traj = run_fixed(problem, "velocity_verlet", h, t_end, n_frames=n_samples + 1)
    best, when = w0, 0.0
    for t, q in zip(traj.t[1:], traj.q[1:]):
        if not np.all(np.isfinite(q)):
            break
        w = omega_max(problem.system, problem.terms, q)
        if w > best:
            best, when = w, float(t)
    return best, when


def harmonic_limit(spec, *, hi: float = 6.0, steps: int = 1, tol: float = 1e-6,
                   growth_per_step: float = 0.0) -> float:
    """Largest h ω for which ``spec``'s one-step map of x'' = −ω² x has spectral radius ≤ e^g.

    The map is measured by running the compiled ``advance`` from (1, 0) and (0, 1) (ω = 1);
    the first h (scanning in steps of ``GRID_STEP``, fine enough for the narrow resonance bands
    of splitting methods near hω = π, then bisecting) with ln(radius) > g + 1e-12 is returned, g =
    ``growth_per_step``. With g = 0 this is the registry's ``stability_limit`` computed from the
    method itself; with g > 0 it is where the amplitude grows faster than g per step (the limit
    a measurement with that detection threshold sees, ``stability_scan``).
    """
    from flexmm.integrators.common import empty_terms
    from flexmm.models.harmonic import HarmonicArgs

    terms = empty_terms()
    args = HarmonicArgs(np.ones(1))
    minv, damp = np.ones(1), np.zeros(1)

    def radius(h: float) -> float:
        cols = []
        for q0, v0 in ((1.0, 0.0), (0.0, 1.0)):
            q, v, f = np.array([q0]), np.array([v0]), np.zeros(1)
            spec.init(args, q, v, 0.0, f, terms)
            spec.advance(args, q, v, f, minv, damp, terms, 0.0, h, steps, spec.new_acc(1))
            cols.append([q[0], v[0]])
        return float(np.max(np.abs(np.linalg.eigvals(np.array(cols).T))))

    def grows(h: float) -> bool:
        return math.log(radius(h)) > growth_per_step + 1e-12

    grid = np.arange(0.01, hi, GRID_STEP)
    b = next((h for h in grid if grows(h)), None)
    if b is None:
        return math.inf
    a = b - GRID_STEP
    while b - a > tol:
        m = 0.5 * (a + b)
        a, b = (a, m) if grows(m) else (m, b)
    return 0.5 * (a + b)


class UnstableStepError(FlexmmError):
    """dt is above the integrator's stable limit (a user error unless forced)."""


def resolve_dt(spec, w_max: float, solver, time_s: float, rate_limit: float = 0.0) -> tuple[float, float, list[str]]:
    """(dt, stable dt, notes) for a scene's solver block (nondimensional times).

    Fixed-step explicit methods: stable = limit/ω_max (and ≤ 1/rate_limit for explicit
    friction); dt = ``dt_fraction`` × stable unless ``dt_s`` is given, which must not exceed it
    (``UnstableStepError`` with both numbers, unless ``allow_unstable``). A-stable methods have
    no limit; their automatic dt is ``dt_fraction`` × 2/ω_max (the accuracy scale of the fastest
    mode). Adaptive methods: dt is only the largest step (``dt_s``) or, if absent, the linear
    limit, reported for information.
    """
    notes: list[str] = []
    stable = spec.stability_limit / w_max if w_max > 0 else math.inf
    if rate_limit > 0:
        stable = min(stable, 1.0 / rate_limit)
    if spec.adaptive:
        dt = solver.dt_s / time_s if solver.dt_s is not None else stable
        what = "largest step" if solver.dt_s is not None else "no step limit (error control)"
        notes.append(f"{spec.name}: adaptive (rtol {solver.rtol or 1e-6:g}); {what}")
        return dt, stable, notes
    if solver.dt_s is not None:
        dt = solver.dt_s / time_s
        if dt > stable:
            msg = (
                f"solver.dt_s = {solver.dt_s:.4g} s exceeds the stable limit of {spec.name} "
                f"({spec.stability_limit:g}/ω_max = {stable * time_s:.4g} s, "
                f"ω_max = {w_max / time_s:.4g} rad/s)"
            )
            if not solver.allow_unstable:
                raise UnstableStepError(msg + "; lower dt or set solver.allow_unstable: true")
            notes.append("WARNING: " + msg)
        return dt, stable, notes
    scale = stable if math.isfinite(stable) else (2.0 / w_max if w_max > 0 else math.inf)
    if not math.isfinite(scale):
        raise UnstableStepError("cannot pick dt: no stiffness at rest (ω_max = 0, e.g. an uncompressed "
                                "Hertz chain); set solver.dt_s")
    dt = solver.dt_fraction * scale
    basis = "stable limit" if math.isfinite(stable) else f"2/ω_max ({spec.name} has no stability limit)"
    notes.append(f"dt chosen as {solver.dt_fraction} x {basis} = {dt * time_s:.4g} s")
    return dt, stable, notes


class StiffnessTracker:
    """ω_max of the current state along a run, cheaply: a few Lanczos iterations (``iters``, 2 force
    evaluations each) on M^{-1/2} K(q) M^{-1/2}, warm-started from the previous top Ritz vector.

    The stiffness changes on the time scale of the motion (a contact closing, a wave front
    passing), slow against a frame interval of a resolved run, so the top mode of the last frame
    is a good start and a handful of iterations tracks it (the top Ritz value is a lower bound that
    the warm start makes tight: tests/integrators/test_stiffness_tracking.py compares it with the
    dense ω_max). ``seconds`` is the time spent, reported with the run.
    """

    def __init__(self, system: System, terms: Terms, iters: int = 6, seed: int = 0):
        self.system, self.terms, self.iters = system, terms, iters
        self.w = np.sqrt(np.maximum(system.inv_mass, 0.0))
        self.x = np.random.default_rng(seed).standard_normal(system.ndof) * self.w
        self.seconds = 0.0

    def omega(self, q: np.ndarray) -> float:
        import time

        t0 = time.perf_counter()
        kx = hessian_operator(self.system, self.terms, q)
        w = self.w
        m = max(2, min(self.iters, int(np.count_nonzero(w))))
        lam, self.x = warm_lanczos(lambda x: w * kx(w * x), self.x, m)
        self.seconds += time.perf_counter() - t0
        return float(math.sqrt(max(lam, 0.0)))
