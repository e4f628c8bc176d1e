"""Pulse shapes and least-squares fits of a sampled profile.

Shapes (z = (x − x0)/W):

- ``sech``:  A sech z — the rotating-chain soliton at θ0 = 0 (docs/physics.md §1.3);
- ``sech2``: A sech² z — softening-chain and KdV-like solitary waves (docs/physics.md §2);
- ``kg``:    A/(b + (1 − b) cosh z), b < 1 — the §1.3 profile 1/(D1 + D2 cosh z) written with its
  peak A = 1/(D1 + D2) and b = D1 A, so that b = 0 is sech.

``W`` is the parameter of the shape, not a full width; the FWHM of each fitted shape is returned
as well (``fwhm``), in the units of x.

``fit_profile`` solves the least-squares problem by Levenberg–Marquardt with the shapes' analytic
Jacobians (``shape_jacobian``), converged far tighter than the fit's use needs; the parameters
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
    (n, len(p)); written with sech and tanh, so nothing overflows far from the centre."""
    A, x0, W = p[0], p[1], p[2]
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
        b = p[3]
        E = b * s + 1 - b
        dA = s / E
        f = A * dA
        dz = -A * (1 - b) * t * s / (E * E)
    cols = [dA, -dz / W, -dz * z / W]
    if shape == "kg":
        cols.append(A * s * (1 - s) / (E * E))
    return f, np.stack(cols, axis=1)


def _least_squares(shape: str, x: np.ndarray, y: np.ndarray, p0: np.ndarray, max_iter: int = 100):
    """Levenberg–Marquardt (Marquardt's diagonal scaling) from ``p0``: (p, J at p, sum of squares),
    or None if it did not converge (or met a singular or non-finite step)."""
    p = np.array(p0, float)
    f, J = shape_jacobian(shape, x, p)
    r = f - y
    cost = float(r @ r)
    lam = 1e-3
    for _ in range(max_iter):
        g = J.T @ r
        H = J.T @ J
        d = np.diag(H).copy()
        if not np.all(np.isfinite(H)) or d.max() <= 0:
            return None
        d = np.maximum(d, 1e-12 * d.max())
        while True:
            try:
                step = np.linalg.solve(H + lam * np.diag(d), -g)
            except np.linalg.LinAlgError:
                return None
            pn = p + step
            fn, Jn = shape_jacobian(shape, x, pn)
            rn = fn - y
            cn = float(rn @ rn)
            if np.isfinite(cn) and cn <= cost:
                break
            if np.isfinite(cn) and cn - cost <= 1e-14 * cost and np.all(np.abs(step) <= 1e-9 * np.abs(p)):
                return p, J, cost  # the cost is flat to rounding around p: converged
            lam *= 4.0
            if lam > 1e20:  # no step lowers the cost: a minimum to rounding, if the gradient agrees
                return (p, J, cost) if np.all(np.abs(g) <= 1e-8 * (np.sqrt(d) * (np.sqrt(cost) + 1e-300))) else None
        small = np.all(np.abs(step) <= 1e-11 * np.abs(pn)) or cost - cn <= 1e-15 * cost
        p, J, r, cost = pn, Jn, rn, cn
        lam = max(lam / 3.0, 1e-12)
        if small:
            return p, J, cost
    return None


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
    func = SHAPES[shape]
    A0, x00, W0 = guess
    p0 = [A0, x00, W0] + ([0.0] if shape == "kg" else [])
    big = np.inf
    lo = [-big, x.min(), 1e-3 * W0] + ([-20.0] if shape == "kg" else [])
    hi = [big, x.max(), 1e3 * W0] + ([0.95] if shape == "kg" else [])
    p0[1] = min(max(p0[1], lo[1]), hi[1])
    x, y = np.asarray(x, float), np.asarray(y, float)
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y)) and np.all(np.isfinite(p0))) or x.size == 0:
        return ProfileFit.failed(shape)
    sol = _least_squares(shape, x, y, np.asarray(p0, float)) if W0 > 0 else None
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
