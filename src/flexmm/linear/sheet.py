"""Linear plane waves of the 2D rotating-squares sheet (docs/physics.md §1.2), from its Hessian.

The sheet's primitive cell holds two units (the checkerboard σ = ±1). With K the Hessian of the
energy at rest (central differences of the compiled force, flexmm.stability.hessian_operator) of a
small fully periodic sheet, the Bloch matrix of wave vector k is

    D_ab(k) = Σ_j K_{a j} e^{i k·(r_j − r_a)},   D(k) x = ω² M x,

summed over the units j of sublattice b, with r the rest positions (minimum image; the hinges
couple nearest neighbours only). The two lowest branches are acoustic: at long wavelength their
phase speeds ω/|k| along a direction φ are the speeds of the two in-plane polarisations. For
θ0 = 0 they are x- and y-polarised with c_x² = cos²φ + K_s sin²φ and c_y² = K_s cos²φ + sin²φ
(in c0 = a sqrt(k_l/m)): an oblique pulse (0 < φ < 45°, K_s ≠ 1) separates into two pulses.
Everything is nondimensional (length a, time sqrt(m/k_l)). ``squares_cell`` reads the cell of
this sheet, ``cell_couplings`` that of any periodic sheet with a two-unit cell of (u, v, θ) units
(the kagome of rotating triangles too, ``linear.triangles``); ``flexmm.linalg.bloch_frequencies``
gives their bands.
"""

from __future__ import annotations

import math

import numpy as np

from flexmm.config.rigid import RotatingSquaresSheet
from flexmm.integrators.common import empty_terms
from flexmm.linalg import BlochCell, bloch_eigen, read_cell
from flexmm.stability import hessian_operator

#: rows and columns of the periodic sheet the couplings are read from (even, ≥ 4 for minimum image)
_CELL_SHEET = 6


def _periodic_copy(lat: RotatingSquaresSheet) -> RotatingSquaresSheet:
    """The same lattice as a small fully periodic, undriven, unvaried sheet."""
    return lat.model_copy(update={
        "n_rows": _CELL_SHEET, "n_cols": _CELL_SHEET, "left": "periodic", "right": "periodic",
        "bottom": "periodic", "top": "periodic", "skew_cols": 0, "variation": [], "predeform": None,
        "magnets": None,
    })


def squares_cell(lat: RotatingSquaresSheet) -> BlochCell:
    """The ``BlochCell`` of the sheet's two-unit cell (``cell_couplings``; unit 0: σ = +1 at row 0,
    col 0, unit 1 its right neighbour), offsets in units of a."""
    return _cell(lat)[0]


def _cell(lat: RotatingSquaresSheet):
    """(``squares_cell``, the periodic copy's built system)."""
    from flexmm.models.rotating_sheet import build

    system = build(_periodic_copy(lat))
    n, nc = system.n_sites, _CELL_SHEET
    h = system.spacing_m / system.scales.length_m
    row, col = np.divmod(np.arange(n), nc)
    wrap = lambda d: (d + nc // 2) % nc - nc // 2  # noqa: E731 - minimum image on the torus
    offsets = np.stack([wrap(col) * h, wrap(row) * h], axis=1)
    return cell_couplings(system, offsets, (row + col) % 2), system


def site_bands(lat: RotatingSquaresSheet, k_site: np.ndarray) -> np.ndarray:
    """ω (rad/s) of the sheet's six branches (…, 6) at wave vectors ``k_site`` (…, 2) in rad per
    site, (k_x along the columns, k_y along the rows): every mode of that wave vector modulo the
    two-unit cell's reciprocal lattice, as a field sampled per site shows them."""
    from flexmm.linalg import bloch_frequencies

    cell, system = _cell(lat)
    h = system.spacing_m / system.scales.length_m
    return bloch_frequencies(cell, np.asarray(k_site, float) / h) / system.scales.time_s


def cell_couplings(system, offsets: np.ndarray, sublattice: np.ndarray) -> BlochCell:
    """The ``BlochCell`` of a periodic sheet whose primitive cell holds units 0 and 1 (sublattices
    0 and 1), three fields each (cell DOF order (u, v, θ) of unit 0, then unit 1): its Hessian at
    rest, read from the columns of the cell's DOFs.

    ``offsets`` (N, 2): every unit's minimum-image rest position relative to unit 0 (units of the
    model's length); the couplings must reach less than half the periodic box.
    """
    n = system.n_sites
    kx = hessian_operator(system, empty_terms())
    sub = np.asarray(sublattice)
    dof = np.arange(system.ndof)
    cls = np.where(dof < 3 * n, 3 * sub[dof % n] + dof // n, -1)
    cell_dofs = [f * n + s for s in (0, 1) for f in range(3)]
    return read_cell(kx, system.ndof, cell_dofs, cls, np.asarray(offsets, float)[dof % n],
                     system.mass[cell_dofs])


def acoustic_modes(lat: RotatingSquaresSheet, phi: float, k: float = 1e-3) -> list[tuple[float, float]]:
    """(speed in c0, polarisation ψ in degrees) of the two acoustic branches along φ (rad), slow first.

    ψ is the direction of the mode's in-plane displacement measured from the propagation
    direction, folded into [−90, 90) (0: longitudinal, −90: transverse).
    """
    lam, vec = bloch_eigen(squares_cell(lat), np.array([k * math.cos(phi), k * math.sin(phi)]), vectors=True)
    out = []
    for j in range(2):
        uv = vec[[0, 1], j] + vec[[3, 4], j]       # both units move alike at long wavelength
        uv = (uv * np.exp(-1j * np.angle(uv[np.argmax(np.abs(uv))]))).real
        ang = math.degrees(math.atan2(uv[1], uv[0]) - phi)
        out.append((math.sqrt(max(lam[j], 0.0)) / k, (ang + 90.0) % 180.0 - 90.0))
    return out
