"""Scalar energy laws E(z) for bonds and on-site terms of chains of masses (docs/physics.md §2).

One compiled function, ``law(code, z, prm, tab) -> (E, dE/dz)``, evaluates every law with its
exact derivative; ``law_second(code, z, prm, tab, dprm) -> d²E/dz²`` gives its second derivative
and the derivatives of dE/dz by the row's parameters (what the gradients' adjoint and tangent
steps need), branch by branch beside it. Tests check both against finite differences of ``law``. A bond between sites i and j feeds it the elongation z = x_j − x_i + s, an
on-site term the displacement z = x_i + s, where s = ``prm[0]`` is a per-element shift (rest
offset, prestretch, or the relaxed initial state). The law is lifted over index arrays by the
model (``flexmm.models.mass_chain``); parameters live in per-element rows of width
``N_LAW_PRM`` (columns below), so gradients and defects are only data.

| law      | code | energy E(z)                                         | columns after the shift |
|----------|------|-----------------------------------------------------|-------------------------|
| poly     | 0    | Σ_{n=1..8} c_n z^n                                   | c_1 … c_8               |
| hertz    | 1    | A δ₊^{p+1}/(p+1), δ = δ0 − z (no tension)             | A, p, δ0                |
| toda     | 2    | (A/B)(e^{−Bz} − 1) + A z                             | A, B                    |
| dipole   | 3    | C (d + z)^{−p} (repulsion of magnets at gap d + z)   | C, d, p                 |
| table    | 4    | ∫ spline(force) (C² cubic spline, linear extension)  | start, n_knots in `tab` |
| sine     | 5    | A (1 − cos k z)                                     | A, k                    |

Tabulated laws store, from ``start`` in the flat ``tab`` array: knots x (n), energies at the
knots e (n), then the spline's force coefficients per segment c3, c2, c1, c0 (n − 1 each), so
F(z) = c0 + c1 s + c2 s² + c3 s³ with s = z − x_k and E = e_k + c0 s + c1 s²/2 + c2 s³/3 + c3 s⁴/4.
Outside the knots the force continues linearly (energy quadratically), with the end slope.

Every law has a numpy reference (``LAWS[name].reference``) written independently of the
compiled path (numpy.polynomial, scipy's spline antiderivative, ...) for the tests.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from flexmm._jit import jit

POLY, HERTZ, TODA, DIPOLE, TABLE, SINE = range(6)
N_LAW_PRM = 9
POLY_DEGREE = 8
#: smallest dipole gap as a fraction of d (the law is singular at contact)
DIPOLE_MIN_GAP = 1e-3


@jit
def table_columns(start, n):
    """Offsets in ``tab`` of a tabulated law's spline coefficients (c0, c1, c2, c3: n − 1 each, after
    the n knots and n energies that start at ``start``)."""
    m = n - 1
    c3 = start + 2 * n
    return c3 + 3 * m, c3 + 2 * m, c3 + m, c3


@jit
def table_piece(z, start, n, tab):
    """Index of the spline piece that holds z, strictly between the first and last knots (bisection)."""
    lo, hi = 0, n - 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if tab[start + mid] <= z:
            lo = mid
        else:
            hi = mid
    return lo


@jit
def _table(z, start, n, tab):
    """Energy and force of a tabulated (spline) law at z."""
    x0 = tab[start]
    x1 = tab[start + n - 1]
    m = n - 1
    c0, c1, c2, c3 = table_columns(start, n)
    if z <= x0:
        s = z - x0
        f0, k0 = tab[c0], tab[c1]
        return tab[start + n] + f0 * s + 0.5 * k0 * s * s, f0 + k0 * s
    if z >= x1:
        k = m - 1
        h = x1 - tab[start + k]
        f1 = tab[c0 + k] + h * (tab[c1 + k] + h * (tab[c2 + k] + h * tab[c3 + k]))
        k1 = tab[c1 + k] + h * (2.0 * tab[c2 + k] + 3.0 * h * tab[c3 + k])
        s = z - x1
        return tab[start + n + m] + f1 * s + 0.5 * k1 * s * s, f1 + k1 * s
    lo = table_piece(z, start, n, tab)
    s = z - tab[start + lo]
    a0, a1, a2, a3 = tab[c0 + lo], tab[c1 + lo], tab[c2 + lo], tab[c3 + lo]
    e = tab[start + n + lo] + s * (a0 + s * (0.5 * a1 + s * (a2 / 3.0 + 0.25 * a3 * s)))
    return e, a0 + s * (a1 + s * (a2 + s * a3))


@jit
def law(code, z, prm, tab):
    """Energy E(z + s) and its derivative dE/dz for one element; ``prm`` is its row."""
    z = z + prm[0]
    if code == POLY:
        e = 0.0
        d = 0.0
        for n in range(POLY_DEGREE, 0, -1):
            e = (e + prm[n]) * z
            d = d * z + n * prm[n]
        return e, d
    if code == HERTZ:
        delta = prm[3] - z
        if delta <= 0.0:
            return 0.0, 0.0
        p = prm[2]
        f = prm[1] * delta**p
        return f * delta / (p + 1.0), -f
    if code == TODA:
        ex = math.exp(-prm[2] * z)
        return prm[1] / prm[2] * (ex - 1.0) + prm[1] * z, prm[1] * (1.0 - ex)
    if code == DIPOLE:
        gap = max(prm[2] + z, DIPOLE_MIN_GAP * prm[2])
        e = prm[1] * gap ** (-prm[3])
        return e, -prm[3] * e / gap
    if code == TABLE:
        return _table(z, int(prm[1]), int(prm[2]), tab)
    # SINE
    kz = prm[2] * z
    return prm[1] * (1.0 - math.cos(kz)), prm[1] * prm[2] * math.sin(kz)


@jit
def law_second(code, z, prm, tab, dprm):
    """E''(z) of one law element and ∂E'/∂prm_c into ``dprm`` (N_LAW_PRM,), c = 0 the shift.

    Matches ``laws.law`` branch by branch (same clipping: a clipped dipole gap and a Hertz
    contact out of touch have zero derivatives).
    """
    for c in range(dprm.shape[0]):
        dprm[c] = 0.0
    z = z + prm[0]
    d2 = 0.0
    if code == POLY:
        zp = 1.0  # z^(n−1)
        zq = 0.0  # z^(n−2)
        for n in range(1, POLY_DEGREE + 1):
            dprm[n] = n * zp
            d2 += n * (n - 1) * prm[n] * zq
            zq = zp
            zp *= z
    elif code == HERTZ:
        delta = prm[3] - z
        if delta > 0.0:
            a, p = prm[1], prm[2]
            dp = delta**p
            d2 = a * p * delta ** (p - 1.0)
            dprm[1] = -dp
            dprm[2] = -a * dp * math.log(delta)
            dprm[3] = -d2
    elif code == TODA:
        a, b = prm[1], prm[2]
        ex = math.exp(-b * z)
        d2 = a * b * ex
        dprm[1] = 1.0 - ex
        dprm[2] = a * z * ex
    elif code == DIPOLE:
        d0 = prm[2]
        gap = prm[2] + z
        if gap > DIPOLE_MIN_GAP * d0:
            c0, p = prm[1], prm[3]
            gp = gap ** (-p - 1.0)
            d2 = p * (p + 1.0) * c0 * gp / gap
            dprm[1] = -p * gp
            dprm[2] = d2
            dprm[3] = -c0 * gp * (1.0 - p * math.log(gap))
        else:  # clipped: E' = −p C (ε d)^(−p−1), constant in z
            c0, p = prm[1], prm[3]
            g0 = DIPOLE_MIN_GAP * d0
            gp = g0 ** (-p - 1.0)
            dprm[1] = -p * gp
            dprm[2] = p * (p + 1.0) * c0 * gp / d0
            dprm[3] = -c0 * gp * (1.0 - p * math.log(g0))
    elif code == TABLE:
        d2 = _table_second(z, int(prm[1]), int(prm[2]), tab)
    else:  # SINE
        a, k = prm[1], prm[2]
        kz = k * z
        d2 = a * k * k * math.cos(kz)
        dprm[1] = k * math.sin(kz)
        dprm[2] = a * math.sin(kz) + a * kz * math.cos(kz)
    if code != DIPOLE or prm[2] + z > DIPOLE_MIN_GAP * prm[2]:
        dprm[0] = d2
    return d2


@jit
def _table_second(z, start, n, tab):
    """d²E/dz² of a tabulated law (the slope of its spline force, linear beyond the knots)."""
    x0 = tab[start]
    x1 = tab[start + n - 1]
    m = n - 1
    _, c1, c2, c3 = table_columns(start, n)
    if z <= x0:
        return tab[c1]
    if z >= x1:
        k = m - 1
        h = x1 - tab[start + k]
        return tab[c1 + k] + h * (2.0 * tab[c2 + k] + 3.0 * h * tab[c3 + k])
    lo = table_piece(z, start, n, tab)
    s = z - tab[start + lo]
    return tab[c1 + lo] + s * (2.0 * tab[c2 + lo] + 3.0 * s * tab[c3 + lo])


@jit
def energies(code, z, rows, tab, out):
    """E of law ``code`` at z[m, e] with element e's row (``rows`` (k, N_LAW_PRM)) into out (M, k)."""
    for m in range(z.shape[0]):
        for e in range(z.shape[1]):
            out[m, e] = law(code, z[m, e], rows[e], tab)[0]


# ---------------------------------------------------------------- rows and tables
def poly_row(coeffs, shift: float = 0.0) -> np.ndarray:
    """Row of a polynomial energy Σ_{n≥1} c_n z^n from ``coeffs`` = [c_1, c_2, ...] (≤ 8 terms)."""
    c = np.asarray(coeffs, float)
    if c.size > POLY_DEGREE:
        raise ValueError(f"polynomial degree {c.size} > {POLY_DEGREE}")
    row = np.zeros(N_LAW_PRM)
    row[0] = shift
    row[1 : 1 + c.size] = c
    return row


def row(*values: float, shift: float = 0.0) -> np.ndarray:
    """Row ``[shift, *values, 0, ...]`` of width N_LAW_PRM."""
    r = np.zeros(N_LAW_PRM)
    r[0] = shift
    r[1 : 1 + len(values)] = values
    return r


def spline_table(x, force) -> np.ndarray:
    """Flat table (see module doc) of the C² cubic spline through (x, force), energy 0 at x = 0.

    ``x`` must be strictly increasing with at least 4 knots. The zero of energy is E(0) when
    0 lies inside or beyond the knots (the linear extension is used outside).
    """
    from scipy.interpolate import CubicSpline

    x = np.asarray(x, float)
    f = np.asarray(force, float)
    if x.ndim != 1 or x.size < 4 or x.shape != f.shape:
        raise ValueError("a tabulated law needs matching 1D arrays with at least 4 points")
    if np.any(np.diff(x) <= 0):
        raise ValueError("tabulated displacements must be strictly increasing")
    sp = CubicSpline(x, f, bc_type="not-a-knot")
    c3, c2, c1, c0 = sp.c
    h = np.diff(x)
    seg = h * (c0 + h * (c1 / 2 + h * (c2 / 3 + h * c3 / 4)))
    e = np.concatenate([[0.0], np.cumsum(seg)])
    tab = np.concatenate([x, e, c3, c2, c1, c0])
    e0, _ = law(TABLE, 0.0, row(0.0, x.size), tab)
    tab[x.size : 2 * x.size] -= e0
    return tab


# ---------------------------------------------------------------- numpy references
def _ref_poly(z, p, tab):
    poly = np.polynomial.Polynomial(np.concatenate([[0.0], p[1 : 1 + POLY_DEGREE]]))
    return poly(z), poly.deriv()(z)


def _ref_hertz(z, p, tab):
    delta = np.clip(p[3] - z, 0.0, None)
    return p[1] * delta ** (p[2] + 1) / (p[2] + 1), -p[1] * delta ** p[2]


def _ref_toda(z, p, tab):
    a, b = p[1], p[2]
    return a / b * np.expm1(-b * z) + a * z, -a * np.expm1(-b * z)


def _ref_dipole(z, p, tab):
    gap = np.maximum(p[2] + z, DIPOLE_MIN_GAP * p[2])
    return p[1] / gap ** p[3], -p[3] * p[1] / gap ** (p[3] + 1)


def _ref_table(z, p, tab):
    from scipy.interpolate import CubicSpline

    start, n = int(p[1]), int(p[2])
    x = tab[start : start + n]
    # rebuild the spline from its knot values, independently of the stored coefficients
    c0 = tab[start + 2 * n + 3 * (n - 1) : start + 2 * n + 4 * (n - 1)]
    c3, c2, c1 = (tab[start + 2 * n + k * (n - 1) : start + 2 * n + (k + 1) * (n - 1)] for k in range(3))
    h = x[-1] - x[-2]
    f_knots = np.concatenate([c0, [c0[-1] + h * (c1[-1] + h * (c2[-1] + h * c3[-1]))]])
    sp = CubicSpline(x, f_knots, bc_type="not-a-knot")
    en = sp.antiderivative()
    e_shift = tab[start + n] - en(x[0])
    zc = np.clip(z, x[0], x[-1])
    fz = sp(zc) + sp(zc, 1) * (z - zc)
    ez = en(zc) + e_shift + sp(zc) * (z - zc) + 0.5 * sp(zc, 1) * (z - zc) ** 2
    return ez, fz


def _ref_sine(z, p, tab):
    return p[1] * (1 - np.cos(p[2] * z)), p[1] * p[2] * np.sin(p[2] * z)


@dataclass(frozen=True)
class LawSpec:
    """One compiled law: its code, its numpy reference ``(z, row, tab) -> (E, dE/dz)``."""

    code: int
    reference: Callable
    description: str


LAWS: dict[str, LawSpec] = {
    "poly": LawSpec(POLY, _ref_poly, "polynomial energy Σ c_n z^n (linear, FPU, softening, wells)"),
    "hertz": LawSpec(HERTZ, _ref_hertz, "one-sided power-law contact A δ₊^p, optional precompression"),
    "toda": LawSpec(TODA, _ref_toda, "Toda exponential interaction"),
    "dipole": LawSpec(DIPOLE, _ref_dipole, "repulsion C/gap^p of facing magnets"),
    "table": LawSpec(TABLE, _ref_table, "tabulated force, C² spline, integrated exactly"),
    "sine": LawSpec(SINE, _ref_sine, "periodic on-site potential A(1 − cos kz)"),
}


def reference(code: int, z, prm: np.ndarray, tab: np.ndarray):
    """Numpy reference of law ``code`` for one parameter row (vectorised over z)."""
    for spec in LAWS.values():
        if spec.code == code:
            z = np.asarray(z, float) + prm[0]
            return spec.reference(z, prm, tab)
    raise KeyError(f"unknown law code {code}")
