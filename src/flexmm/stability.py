"""Largest linear frequency ω_max of a built system and the step-size limits it sets (docs/physics.md §3).

ω_max² is the largest eigenvalue of M^{-1/2} K M^{-1/2} over the free DOFs, with K the
Hessian of the energy at a reference state (rest by default), obtained from central
differences of the compiled force: K x ≈ −(F(q + εx) − F(q − εx)) / 2ε. One-sided contacts (a
striker) enter with their stiffness at the expected peak overlap, p k δ^(p−1), since a Hertz
contact stiffens with overlap. Small systems are diagonalised densely; larger ones by Lanczos
(the top Ritz value, a lower bound converging like 1/m² in the m iterations at a band edge).

A fixed-step explicit method is linearly stable while h ω_max ≤ its ``stability_limit``
(harmonic oscillator; ``harmonic_limit`` recomputes it from the compiled method).
Softening or contact laws change ω_max along the motion, so ``trajectory_omega_max`` also
samples ω_max along a short pilot run (used by ``flexmm stability``).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import eigvalsh_tridiagonal

from flexmm._blas import single_blas_thread
from flexmm._jit import jit
from flexmm.errors import FlexmmError
from flexmm.models.base import System
from flexmm.integrators.common import Terms
from flexmm.models.kernels import model_force

DENSE_LIMIT = 400
LANCZOS_MAX_ITER = 600
LANCZOS_RTOL = 1e-6
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
    """Matrix-free Hessian-vector product K x at ``q_ref`` (default: rest)."""
    q_ref = np.zeros(system.ndof) if q_ref is None else q_ref
    fp, fm = np.zeros(system.ndof), np.zeros(system.ndof)
    contacts = _contact_stiffness(system, terms)

    def matvec(x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, float).ravel()
        scale = np.max(np.abs(x))
        if scale == 0:
            return np.zeros_like(x)
        eps = 1e-6 / scale
        system.force(q_ref + eps * x, system.args, fp)
        system.force(q_ref - eps * x, system.args, fm)
        y = -(fp - fm) / (2 * eps)
        for i, j, k in contacts:
            d = x[i] - x[j]
            y[i] += k * d
            y[j] -= k * d
        return y

    return matvec


def lanczos_max(op, n: int, *, max_iter: int = LANCZOS_MAX_ITER, rtol: float = LANCZOS_RTOL,
                seed: int = 0) -> float:
    """Largest eigenvalue of the symmetric operator ``op`` (n × n), by plain Lanczos.

    No reorthogonalisation: the top Ritz value still converges to λ_max (lost orthogonality
    only adds copies). Stops when it changes by less than ``rtol`` (relative) over 10
    iterations, or after ``max_iter`` iterations. ``op`` is either a Python callable or a
    tuple ``(step, state)`` for the compiled form used by ``omega_max``.
    """
    rng = np.random.default_rng(seed)
    x = rng.standard_normal(n)
    x /= math.sqrt(np.sum(x * x))
    x_prev = np.zeros(n)
    alpha, beta = np.zeros(max_iter), np.zeros(max_iter)
    b, history, it = 0.0, [], 0
    while it < min(max_iter, n):
        k1 = min(it + 10, max_iter, n)
        if callable(op):
            for k in range(it, k1):
                w = op(x) - b * x_prev
                alpha[k] = float(np.sum(w * x))  # np.sum, not BLAS: a threaded dot spin-waits
                w -= alpha[k] * x
                b = beta[k] = math.sqrt(float(np.sum(w * w)))
                if b == 0.0:
                    k1 = k + 1
                    break
                x_prev, x = x, w / b
        else:
            step, state = op
            b, k1 = step(*state, x, x_prev, b, alpha, beta, it, k1)
        it = k1
        top = float(eigvalsh_tridiagonal(alpha[:it], beta[: it - 1], select="i",
                                         select_range=(it - 1, it - 1))[0])
        history.append(top)
        if b <= 1e-14 * abs(top) or (len(history) > 1 and abs(top - history[-2]) <= rtol * abs(top)):
            break
    return history[-1]


@jit
def _lanczos_steps(args, q_ref, w, con_ij, con_k, fp, fm, qt, r, x, x_prev, b, alpha, beta, k0, k1):
    """Lanczos iterations k0..k1−1 on W K W (W = M^{-1/2}, K by central differences of force)."""
    n = x.shape[0]
    for it in range(k0, k1):
        scale = 0.0
        for k in range(n):
            r[k] = w[k] * x[k]
            scale = max(scale, abs(r[k]))
        eps = 1e-6 / scale if scale > 0.0 else 1.0
        for k in range(n):
            qt[k] = q_ref[k] + eps * r[k]
        model_force(qt, args, fp)
        for k in range(n):
            qt[k] = q_ref[k] - eps * r[k]
        model_force(qt, args, fm)
        for c in range(con_ij.shape[0]):
            i, j = con_ij[c, 0], con_ij[c, 1]
            d = con_k[c] * (r[i] - r[j]) * 2.0 * eps
            fp[i] -= d
            fp[j] += d
        a = 0.0
        for k in range(n):
            r[k] = -w[k] * (fp[k] - fm[k]) / (2.0 * eps) - b * x_prev[k]
            a += r[k] * x[k]
        bb = 0.0
        for k in range(n):
            r[k] -= a * x[k]
            bb += r[k] * r[k]
        alpha[it] = a
        b = np.sqrt(bb)
        beta[it] = b
        if b == 0.0:
            return b, it + 1
        for k in range(n):
            x_prev[k] = x[k]
            x[k] = r[k] / b
    return b, k1


def _dense_dynamical_matrix(system: System, terms: Terms, free: np.ndarray, q_ref=None) -> np.ndarray:
    """M^{-1/2} K M^{-1/2} over the free DOFs (n_free, n_free), symmetrised, column by column."""
    w = np.sqrt(system.inv_mass[free])
    kx = hessian_operator(system, terms, q_ref)
    full = np.zeros(system.ndof)

    def column(y):
        full[:] = 0.0
        full[free] = w * y
        return w * kx(full)[free]

    a = np.column_stack([column(e) for e in np.eye(free.size)])
    return 0.5 * (a + a.T)


def omega_max(system: System, terms: Terms, q_ref: np.ndarray | None = None) -> float:
    """Largest angular frequency of small oscillations about ``q_ref`` (nondimensional)."""
    free = np.flatnonzero(system.inv_mass > 0)
    if free.size == 0:
        return 0.0
    n = free.size
    if n <= DENSE_LIMIT:
        with single_blas_thread():  # small dense problem: BLAS threads only cost
            lam = np.linalg.eigvalsh(_dense_dynamical_matrix(system, terms, free, q_ref))[-1]
    else:
        # full-size operator W K W with W = M^{-1/2} (0 on held DOFs): same top eigenvalue,
        # no gathers (held DOFs only add zero eigenvalues)
        w = np.sqrt(np.maximum(system.inv_mass, 0.0))
        contacts = _contact_stiffness(system, terms)
        con_ij = np.array([[i, j] for i, j, _ in contacts], np.int64).reshape(-1, 2)
        con_k = np.array([k for _, _, k in contacts], float)
        q0 = np.zeros(system.ndof) if q_ref is None else np.asarray(q_ref, float)
        scratch = [np.zeros(system.ndof) for _ in range(4)]
        state = (system.args, q0, w, con_ij, con_k, *scratch)
        lam = lanczos_max((_lanczos_steps, state), system.ndof)
    return float(np.sqrt(max(lam, 0.0)))


def top_mode(system: System, terms: Terms, q_ref: np.ndarray | None = None) -> tuple[float, np.ndarray]:
    """(ω_max, shape (ndof,)): the fastest small-oscillation mode about ``q_ref`` (default rest).

    The shape x solves K x = ω_max² M x (held DOFs 0), scaled to max |x| = 1. Dense for small
    systems, else ARPACK (``eigsh``) on the matrix-free M^{-1/2} K M^{-1/2}. Exciting this mode
    alone is the sharpest test of a method's linear stability limit (``stability_scan``).
    """
    from scipy.sparse.linalg import LinearOperator, eigsh

    free = np.flatnonzero(system.inv_mass > 0)
    w = np.sqrt(system.inv_mass[free])
    if free.size <= DENSE_LIMIT:
        with single_blas_thread():
            lam, vec = np.linalg.eigh(_dense_dynamical_matrix(system, terms, free, q_ref))
        lam, y = lam[-1], vec[:, -1]
    else:
        kx = hessian_operator(system, terms, q_ref)
        full = np.zeros(system.ndof)

        def matvec(y):
            full[:] = 0.0
            full[free] = w * np.ravel(y)
            return w * kx(full)[free]

        op = LinearOperator((free.size, free.size), matvec=matvec, dtype=float)
        v0 = np.random.default_rng(0).standard_normal(free.size)  # not orthogonal to a staggered mode
        lam, vec = eigsh(op, k=1, which="LA", tol=1e-10, v0=v0)
        lam, y = lam[0], vec[:, 0]
    shape = np.zeros(system.ndof)
    shape[free] = w * y
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
        n = w.size
        m = max(2, min(self.iters, int(np.count_nonzero(w))))
        basis = np.zeros((m, n))
        alpha, beta = np.zeros(m), np.zeros(m)
        x = self.x / max(math.sqrt(float(np.sum(self.x * self.x))), 1e-300)
        k_used = m
        for k in range(m):
            basis[k] = x
            r = w * kx(w * x)
            alpha[k] = float(np.sum(r * x))
            r -= basis[: k + 1].T @ (basis[: k + 1] @ r)  # full reorthogonalisation (m is small)
            beta[k] = math.sqrt(float(np.sum(r * r)))
            if beta[k] <= 1e-14 * max(abs(alpha[k]), 1e-300):
                k_used = k + 1
                break
            x = r / beta[k]
        t = np.diag(alpha[:k_used]) + np.diag(beta[: k_used - 1], 1) + np.diag(beta[: k_used - 1], -1)
        lam, vec = np.linalg.eigh(t)
        self.x = basis[:k_used].T @ vec[:, -1]
        self.seconds += time.perf_counter() - t0
        return float(math.sqrt(max(lam[-1], 0.0)))
