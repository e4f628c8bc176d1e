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
Everything is nondimensional (length a, time sqrt(m/k_l)). ``cell_couplings`` and
``cell_frequencies`` serve any periodic sheet with a two-unit cell of (u, v, θ) units (the kagome
of rotating triangles too, ``linear.triangles``).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import eigh

from flexmm._blas import single_blas_thread
from flexmm.config.rigid import RotatingSquaresSheet
from flexmm.integrators.common import empty_terms
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


def bloch_matrices(lat: RotatingSquaresSheet) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Coupling data of the two-unit cell: (K (2, 3, N, 3), offsets (N, 2), sublattice (N,), mass (6,)).

    K[a, f, j, g] is the Hessian entry of unit a's field f (0: σ = +1 at row 0, col 0; 1: its right
    neighbour) against unit j's field g (u, v, θ); offsets are the minimum-image rest positions of the units relative to
    unit a = 0 in units of a.
    """
    from flexmm.models.rotating_sheet import build

    system = build(_periodic_copy(lat))
    n, nc = system.n_sites, _CELL_SHEET
    h = system.spacing_m / system.scales.length_m
    row, col = np.divmod(np.arange(n), nc)
    wrap = lambda d: (d + nc // 2) % nc - nc // 2  # noqa: E731 - minimum image on the torus
    offsets = np.stack([wrap(col) * h, wrap(row) * h], axis=1)
    return cell_couplings(system, offsets, (row + col) % 2)


def cell_couplings(system, offsets: np.ndarray, sublattice: np.ndarray):
    """(K, offsets, sublattice, mass) of a periodic sheet whose primitive cell holds units 0 and 1
    (sublattices 0 and 1), three fields each: its Hessian at rest, read column by column.

    ``offsets`` (N, 2): every unit's minimum-image rest position relative to unit 0 (units of the
    model's length); the couplings must reach less than half the periodic box.
    """
    n = system.n_sites
    kx = hessian_operator(system, empty_terms())
    hess = np.column_stack([kx(np.eye(1, 3 * n, j).ravel()) for j in range(3 * n)])
    units = (0, 1)
    K = np.array([hess[[f * n + s for f in range(3)]].reshape(3, 3, n).transpose(0, 2, 1) for s in units])
    mass = np.concatenate([system.mass[[f * n + s for f in range(3)]] for s in units])
    return K, offsets, np.asarray(sublattice), mass


def _bloch_matrix(data, k: np.ndarray) -> np.ndarray:
    """D(k) (6 × 6, Hermitian) of the two-unit cell; DOF order (u, v, θ) of unit 0, then unit 1."""
    K, offsets, sub, _ = data
    D = np.zeros((6, 6), complex)
    for a in range(2):
        phase = np.exp(1j * ((offsets - offsets[a]) @ k))  # unit 1 is one column right of unit 0
        for b in range(2):
            sel = sub == b
            D[3 * a:3 * a + 3, 3 * b:3 * b + 3] = np.einsum("fjg,j->fg", K[a][:, sel, :], phase[sel])
    return 0.5 * (D + D.conj().T)


def bloch_frequencies(lat: RotatingSquaresSheet, kvec: np.ndarray) -> np.ndarray:
    """The six ω(k) (ascending, nondimensional) for each wave vector in ``kvec`` (…, 2)."""
    return cell_frequencies(bloch_matrices(lat), kvec)


def cell_frequencies(data, kvec: np.ndarray) -> np.ndarray:
    """The six ω(k) (ascending) of the two-unit cell ``data`` (``cell_couplings``) at each wave
    vector in ``kvec`` (…, 2)."""
    kv = np.asarray(kvec, float)
    out = np.empty(kv.shape[:-1] + (6,))
    with single_blas_thread():  # 6 × 6 eigenproblems: BLAS threads only add overhead
        for idx in np.ndindex(kv.shape[:-1]):
            lam = eigh(_bloch_matrix(data, kv[idx]), np.diag(data[3]), eigvals_only=True)
            out[idx] = np.sqrt(np.clip(lam, 0.0, None))
    return out


def acoustic_modes(lat: RotatingSquaresSheet, phi: float, k: float = 1e-3) -> list[tuple[float, float]]:
    """(speed in c0, polarisation ψ in degrees) of the two acoustic branches along φ (rad), slow first.

    ψ is the direction of the mode's in-plane displacement measured from the propagation
    direction, folded into [−90, 90) (0: longitudinal, −90: transverse).
    """
    data = bloch_matrices(lat)
    with single_blas_thread():
        lam, vec = eigh(_bloch_matrix(data, np.array([k * math.cos(phi), k * math.sin(phi)])), np.diag(data[3]))
    out = []
    for j in range(2):
        uv = vec[[0, 1], j] + vec[[3, 4], j]       # both units move alike at long wavelength
        uv = (uv * np.exp(-1j * np.angle(uv[np.argmax(np.abs(uv))]))).real
        ang = math.degrees(math.atan2(uv[1], uv[0]) - phi)
        out.append((math.sqrt(max(lam[j], 0.0)) / k, (ang + 90.0) % 180.0 - 90.0))
    return out
