"""Pulse shapes and least-squares fits of a sampled profile (scipy.optimize.curve_fit).

Shapes (z = (x − x0)/W):

- ``sech``:  A sech z — the rotating-chain soliton at θ0 = 0 (docs/physics.md §1.3);
- ``sech2``: A sech² z — softening-chain and KdV-like solitary waves (docs/physics.md §2);
- ``kg``:    A/(b + (1 − b) cosh z), b < 1 — the §1.3 profile 1/(D1 + D2 cosh z) written with its
  peak A = 1/(D1 + D2) and b = D1 A, so that b = 0 is sech.

``W`` is the parameter of the shape, not a full width; the FWHM of each fitted shape is returned
as well (``fwhm``), in the units of x.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import curve_fit


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


def fit_profile(x: np.ndarray, y: np.ndarray, shape: str, guess: tuple[float, float, float]) -> ProfileFit:
    """Fit ``shape`` to samples (x, y) from a guess (A, x0, W); failed fit -> ``ok=False``, NaNs."""
    func = SHAPES[shape]
    A0, x00, W0 = guess
    p0 = [A0, x00, W0] + ([0.0] if shape == "kg" else [])
    big = np.inf
    lo = [-big, x.min(), 1e-3 * W0] + ([-20.0] if shape == "kg" else [])
    hi = [big, x.max(), 1e3 * W0] + ([0.95] if shape == "kg" else [])
    p0[1] = min(max(p0[1], lo[1]), hi[1])
    try:
        popt, pcov = curve_fit(func, x, y, p0=p0, bounds=(lo, hi), maxfev=4000)
    except (RuntimeError, ValueError):
        return ProfileFit.failed(shape)
    err = np.sqrt(np.clip(np.diag(pcov), 0, None)) if np.all(np.isfinite(pcov)) else np.full(len(popt), np.nan)
    res = float(np.sqrt(np.mean((func(x, *popt) - y) ** 2)))
    b = float(popt[3]) if shape == "kg" else 0.0
    W = abs(float(popt[2]))
    return ProfileFit(shape, float(popt[0]), float(popt[1]), W, b, float(err[2]),
                      shape_fwhm(shape, W, b), res, True)
