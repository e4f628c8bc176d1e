"""Linear waves of the rotating-triangles chain and kagome sheet (docs/physics.md §1.6), from the
Hessian of the built model: the chain's cell with ``linear.dispersion`` (two units per cell), the
sheet's with the two-unit cell of ``linear.sheet`` (an up and a down triangle); their bands from
``flexmm.linalg.bloch_frequencies``. Nondimensional: length a (the side of a triangle), time
sqrt(m/k_l).
"""

from __future__ import annotations

import math

import numpy as np

from flexmm.config.triangles import RotatingTrianglesChain, RotatingTrianglesSheet
from flexmm.linalg import BlochCell, bloch_frequencies
from flexmm.linear.dispersion import chain_cell
from flexmm.linear.sheet import cell_couplings
from flexmm.models.rotating_triangles import (
    HALF,
    build_chain,
    build_sheet,
    centroids,
    sublattice_sign,
)

#: units of the open chain the Bloch blocks are read from (cells of two, away from the ends)
_CHAIN_UNITS = 24
#: rows and columns of the periodic sheet the couplings are read from (even, ≥ 4 for minimum image)
_CELL_SHEET = 6
#: phase per cell of the long-wave limit
_LONG_WAVE_Q = 1e-3


def chain_bands(lat: RotatingTrianglesChain, q: np.ndarray) -> np.ndarray:
    """ω(q) (…, 6) of the chain, ascending, q the phase per two-unit cell (length 2 a cos θ0)."""
    small = build_chain(lat.model_copy(update={"n_units": _CHAIN_UNITS, "left": "free", "right": "free"}))
    return bloch_frequencies(chain_cell(small, cell_sites=2), q)


def _acoustic(w: np.ndarray, q: float) -> np.ndarray:
    """The two acoustic frequencies of the six at a small q; ValueError if a third branch is not
    gapped (k_θ = 0: the twist mechanism costs nothing and mixes with the long waves)."""
    if not w[2] > 100.0 * q:
        raise ValueError("no long-wave limit: the twist branch has no gap (k_rot = 0?), so the "
                         "mechanism mixes with the acoustic waves")
    return w[:2]


def chain_long_wave_speed(lat: RotatingTrianglesChain) -> float:
    """Longitudinal long-wave speed of the chain in c0 = a sqrt(k_l/m) (the faster of its two
    acoustic branches; the other is flexural, ω ∝ q²). θ0 = 0: sqrt(4K_s/(1 + 3K_s))."""
    w = _acoustic(chain_bands(lat, np.array([_LONG_WAVE_Q]))[0], _LONG_WAVE_Q)
    return float(w[1] / _LONG_WAVE_Q * 2.0 * math.cos(lat.theta0_rad))


def sheet_cell(lat: RotatingTrianglesSheet) -> BlochCell:
    """The ``BlochCell`` of the kagome's two-triangle cell (``linear.sheet.cell_couplings``), read
    from a small fully periodic copy of the sheet."""
    periodic = lat.model_copy(update={"n_rows": _CELL_SHEET, "n_cols": _CELL_SHEET, "left": "periodic",
                                      "right": "periodic", "bottom": "periodic", "top": "periodic"})
    system = build_sheet(periodic)
    n, nc = system.n_sites, _CELL_SHEET
    row, col = np.divmod(np.arange(n), nc)
    wrap = lambda d: (d + nc // 2) % nc - nc // 2
    x, y = centroids(nc, nc, lat.theta0_rad)
    d = 2.0 * HALF * math.cos(lat.theta0_rad)
    sigma = sublattice_sign(nc, nc)
    offsets = np.stack([wrap(col) * x[1], wrap(row) * 1.5 * d + (sigma - sigma[0]) * d / 4], axis=1)
    return cell_couplings(system, offsets, (row + col) % 2)


def sheet_bands(lat: RotatingTrianglesSheet, kvec: np.ndarray) -> np.ndarray:
    """The six ω(k) (ascending) of the kagome sheet at each wave vector in ``kvec`` (…, 2), units 1/a."""
    return bloch_frequencies(sheet_cell(lat), kvec)


def sheet_long_wave_speeds(lat: RotatingTrianglesSheet, phi: float) -> tuple[float, float]:
    """Phase speeds (c0) of the two acoustic branches along direction φ (rad) at long wavelength,
    slow first. θ0 = 0: sqrt(K_s/(1 + K_s)) and sqrt(K_s/(1 + K_s) + ½)."""
    k = _LONG_WAVE_Q
    w = _acoustic(sheet_bands(lat, np.array([k * math.cos(phi), k * math.sin(phi)])), k)
    return float(w[0] / k), float(w[1] / k)
