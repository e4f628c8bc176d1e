"""Pulse shapes and least-squares fits of a sampled profile.

Shapes (z = (x − x0)/W):

- ``sech``:  A sech z — the rotating-chain soliton at θ0 = 0 (docs/physics.md §1.3);
- ``sech2``: A sech² z — softening-chain and KdV-like solitary waves (docs/physics.md §2);
- ``kg``:    A/(b + (1 − b) cosh z), b < 1 — the §1.3 profile 1/(D1 + D2 cosh z) written with its
  peak A = 1/(D1 + D2) and b = D1 A, so that b = 0 is sech.

``W`` is the parameter of the shape, not a full width; the FWHM of each fitted shape is returned
as well (``fwhm``), in the units of x.

``fit_profile`` solves the least-squares problem by Levenberg–Marquardt with the shapes' analytic
Jacobians (``shape_jacobian``), converged far tighter than the fit's use needs (``fit_profiles``:
many profiles at once, each with its own steps, in one vectorised iteration); the parameters
are bounded (centre within the samples, W within 10⁻³–10³ of its guess, b ≤ 0.95), and a
solution outside the bounds, or a solve that does not converge, is redone by
``scipy.optimize.curve_fit`` within them (imported only then: it is slow to import, and an
analysis fits hundreds of profiles).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


def _sech(z):
    e = np.exp(-np.abs(z))
    return 2 * e / (1 + e * e)


def sech(x, A, x0, W):
    """A sech((x − x0)/W)."""
    return A * _sech((x - x0) / W)


def sech2(x, A, x0, W):
    """A sech²((x − x0)/W)."""
    return A * _sech((x - x0) / W) ** 2


def kg(x, A, x0, W, b):
    """A/(b + (1 − b) cosh((x − x0)/W)) = 1/(D1 + D2 cosh) with D1 = b/A, D2 = (1 − b)/A."""
    s = _sech((x - x0) / W)
    return A * s / (b * s + (1 - b))


SHAPES = {"sech": sech, "sech2": sech2, "kg": kg}


def shape_fwhm(shape: str, W: float, b: float = 0.0) -> float:
    """Full width at half maximum of a shape with parameter W (and b for 'kg')."""
    if shape == "sech":
        return 2 * W * math.acosh(2.0)
    if shape == "sech2":
        return 2 * W * math.acosh(math.sqrt(2.0))
    # A/(b + (1 − b) cosh z) = A/2  <=>  cosh z = (2 − b)/(1 − b)
    return 2 * W * math.acosh((2 - b) / (1 - b))


@dataclass
class ProfileFit:
    """Result of fitting one shape: parameters, their standard errors, FWHM and rms residual."""

    shape: str
    amplitude: float
    center: float
    W: float
    b: float
    W_stderr: float
    fwhm: float
    rms_residual: float
    ok: bool

    @classmethod
    def failed(cls, shape: str) -> "ProfileFit":
        nan = float("nan")
        return cls(shape, nan, nan, nan, nan, nan, nan, nan, False)


def shape_jacobian(shape: str, x: np.ndarray, p) -> tuple[np.ndarray, np.ndarray]:
    """The shape's values at ``x`` for parameters ``p`` (A, x0, W[, b]) and their derivatives
    (..., len(p)); written with sech and tanh, so nothing overflows far from the centre.

    One problem: x (n,), p (k,) -> (n,), (n, k); a batch: x (m, n), p (m, k) -> (m, n), (m, n, k).
    """
    p = np.asarray(p, float)
    A, x0, W = p[..., 0, None], p[..., 1, None], p[..., 2, None]
    z = (x - x0) / W
    e = np.exp(-2 * np.abs(z))
    s = 2 * np.sqrt(e) / (1 + e)  # sech z
    t = np.sign(z) * (1 - e) / (1 + e)  # tanh z
    if shape == "sech":
        f, dA = A * s, s
        dz = -f * t
    elif shape == "sech2":
        dA = s * s
        f = A * dA
        dz = -2 * f * t
    else:  # kg: A s / (b s + 1 - b)
        b = p[..., 3, None]
        E = b * s + 1 - b
        dA = s / E
        f = A * dA
        dz = -A * (1 - b) * t * s / (E * E)
    cols = [dA, -dz / W, -dz * z / W]
    if shape == "kg":
        cols.append(A * s * (1 - s) / (E * E))
    return f, np.stack(cols, axis=-1)


def _least_squares(shape: str, x: np.ndarray, y: np.ndarray, mask: np.ndarray, p0: np.ndarray,
                   max_iter: int = 100) -> list:
    """Levenberg–Marquardt (Marquardt's diagonal scaling) of m problems at once.

    x, y, mask (m, n): the samples of each problem (``mask`` False on the padding of the shorter
    ones), p0 (m, k). Each problem takes its own steps and damping, as if solved alone. Returns per
    problem (p, J at p on its samples, sum of squares), or None if it did not converge (or met a
    singular or non-finite step).
    """
    m, k = p0.shape
    eye = np.eye(k)

    padded = not mask.all()

    def residual(rows, pp):
        f, J = shape_jacobian(shape, x[rows], pp)
        r = f - y[rows]
        if padded:
            r, J = np.where(mask[rows], r, 0.0), np.where(mask[rows, :, None], J, 0.0)
        return r, J, np.array([r[0] @ r[0]]) if m == 1 else np.einsum("ij,ij->i", r, r)

    p = np.array(p0, float)
    r, J, cost = residual(slice(None), p)
    lam = np.full(m, 1e-3)
    g, H, d = np.zeros((m, k)), np.zeros((m, k, k)), np.zeros((m, k))
    out: list = [None] * m
    live, fresh, steps = np.ones(m, bool), np.ones(m, bool), np.zeros(m, int)

    def done(i, converged: bool) -> None:
        out[i] = (p[i].copy(), J[i][mask[i]], float(cost[i])) if converged else None
        live[i] = False

    while live.any():
        new = np.flatnonzero(live & fresh)  # a step was taken: the normal equations at the new p
        if new.size:
            if m == 1:  # one (often long) profile: BLAS's products, as a fit of it alone
                g[0], H[0] = J[0].T @ r[0], J[0].T @ J[0]
            else:
                JT = J[new].transpose(0, 2, 1)
                g[new] = (JT @ r[new][..., None])[..., 0]
                H[new] = JT @ J[new]
            dd = np.diagonal(H[new], axis1=1, axis2=2)
            bad = ~np.all(np.isfinite(H[new]), axis=(1, 2)) | (dd.max(axis=1) <= 0)
            for i in new[bad]:
                done(i, False)
            d[new] = np.maximum(dd, 1e-12 * dd.max(axis=1, keepdims=True))
            fresh[new] = False
        a = np.flatnonzero(live)
        if not a.size:
            break
        try:
            step = np.linalg.solve(H[a] + lam[a, None, None] * eye * d[a, None, :], -g[a][..., None])[..., 0]
        except np.linalg.LinAlgError:  # one singular system: solve them one by one
            step = np.full((a.size, k), np.nan)
            for j, i in enumerate(a):
                try:
                    step[j] = np.linalg.solve(H[i] + lam[i] * np.diag(d[i]), -g[i])
                except np.linalg.LinAlgError:
                    done(i, False)
            keep = live[a]
            a, step = a[keep], step[keep]
            if not a.size:
                continue
        pn = p[a] + step
        rn, Jn, cn = residual(a, pn)
        finite = np.isfinite(cn)
        accept = finite & (cn <= cost[a])
        flat = finite & (cn - cost[a] <= 1e-14 * cost[a]) & np.all(np.abs(step) <= 1e-9 * np.abs(p[a]), axis=1)
        for j, i in enumerate(a):
            if accept[j]:
                continue
            if flat[j]:  # the cost is flat to rounding around p: converged
                done(i, True)
                continue
            lam[i] *= 4.0
            if lam[i] > 1e20:  # no step lowers the cost: a minimum to rounding, if the gradient agrees
                done(i, bool(np.all(np.abs(g[i]) <= 1e-8 * (np.sqrt(d[i]) * (np.sqrt(cost[i]) + 1e-300)))))
        acc = np.flatnonzero(accept)
        if acc.size:
            i = a[acc]
            small = (np.all(np.abs(step[acc]) <= 1e-11 * np.abs(pn[acc]), axis=1)
                     | (cost[i] - cn[acc] <= 1e-15 * cost[i]))
            p[i], J[i], r[i], cost[i] = pn[acc], Jn[acc], rn[acc], cn[acc]
            lam[i] = np.maximum(lam[i] / 3.0, 1e-12)
            steps[i] += 1
            fresh[i] = True
            for j, ii in enumerate(i):
                if small[j]:
                    done(ii, True)
                elif steps[ii] >= max_iter:
                    done(ii, False)
    return out


def _covariance(J: np.ndarray, cost: float) -> np.ndarray:
    """The parameters' covariance from the Jacobian at the solution, scaled by the residual
    variance (inf where it cannot be estimated: no more samples than parameters)."""
    _, sv, VT = np.linalg.svd(J, full_matrices=False)
    keep = sv > np.finfo(float).eps * max(J.shape) * sv[0]
    pcov = (VT[keep].T / sv[keep] ** 2) @ VT[keep]
    n, m = J.shape
    return pcov * (cost / (n - m)) if n > m else np.full((m, m), np.inf)


def fit_profile(x: np.ndarray, y: np.ndarray, shape: str, guess: tuple[float, float, float]) -> ProfileFit:
    """Fit ``shape`` to samples (x, y) from a guess (A, x0, W); failed fit -> ``ok=False``, NaNs."""
    return fit_profiles([x], [y], shape, [guess])[0]


def fit_profiles(xs: list, ys: list, shape: str, guesses: list) -> list[ProfileFit]:
    """``fit_profile`` of several profiles (x, y) with their guesses (A, x0, W), solved together
    (one Levenberg–Marquardt over the batch: the cost of a few fits, not of their number)."""
    xs = [np.asarray(x, float) for x in xs]
    ys = [np.asarray(y, float) for y in ys]
    setups, todo = [], []
    for i, (x, y, (A0, x00, W0)) in enumerate(zip(xs, ys, guesses)):
        p0 = [A0, x00, W0] + ([0.0] if shape == "kg" else [])
        ok = x.size > 0 and np.all(np.isfinite(x)) and np.all(np.isfinite(y))
        lo = [-np.inf, x.min() if ok else 0.0, 1e-3 * W0] + ([-20.0] if shape == "kg" else [])
        hi = [np.inf, x.max() if ok else 0.0, 1e3 * W0] + ([0.95] if shape == "kg" else [])
        p0[1] = min(max(p0[1], lo[1]), hi[1])
        ok = ok and np.all(np.isfinite(p0))
        setups.append((ok, p0, lo, hi))
        if ok and W0 > 0:
            todo.append(i)
    sols: dict = {}
    if todo:
        n = max(xs[i].size for i in todo)
        X, Y, M = np.zeros((len(todo), n)), np.zeros((len(todo), n)), np.zeros((len(todo), n), bool)
        for j, i in enumerate(todo):
            X[j, : xs[i].size], Y[j, : xs[i].size], M[j, : xs[i].size] = xs[i], ys[i], True
        P0 = np.array([setups[i][1] for i in todo], float)
        sols = dict(zip(todo, _least_squares(shape, X, Y, M, P0)))
    return [_finish(shape, xs[i], ys[i], *setups[i], sols.get(i)) for i in range(len(xs))]


def _finish(shape: str, x, y, ok: bool, p0, lo, hi, sol) -> ProfileFit:
    """A ProfileFit from the batch's solution of one problem: its covariance, or, at a bound or not
    converged, the bounded solver's fit."""
    if not ok:
        return ProfileFit.failed(shape)
    func = SHAPES[shape]
    if sol is not None:
        popt, J, cost = sol
        popt[2] = abs(popt[2])  # every shape is even in z: W and -W are the same fit
        if np.all(popt >= lo) and np.all(popt <= hi):
            pcov = _covariance(J, cost)
        else:
            sol = None
    if sol is None:  # at a bound or not converged: the bounded solver
        import warnings

        from scipy.optimize import OptimizeWarning, curve_fit

        try:
            with warnings.catch_warnings():  # a covariance it cannot estimate is inf: the error is NaN below
                warnings.simplefilter("ignore", OptimizeWarning)
                popt, pcov = curve_fit(func, x, y, p0=p0, bounds=(lo, hi), maxfev=4000)
        except (RuntimeError, ValueError):
            return ProfileFit.failed(shape)
    err = np.sqrt(np.clip(np.diag(pcov), 0, None)) if np.all(np.isfinite(pcov)) else np.full(len(popt), np.nan)
    res = float(np.sqrt(np.mean((func(x, *popt) - y) ** 2)))
    b = float(popt[3]) if shape == "kg" else 0.0
    W = abs(float(popt[2]))
    return ProfileFit(shape, float(popt[0]), float(popt[1]), W, b, float(err[2]),
                      shape_fwhm(shape, W, b), res, True)
