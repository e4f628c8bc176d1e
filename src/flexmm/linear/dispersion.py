"""Linear dispersion of any 1D model from its Hessian and mass matrix (Bloch eigenproblem).

For a built System (flexmm.models) whose sites repeat with a period of ``cell_sites`` sites,
the Hessian K of the energy at the reference state (central differences of the compiled force,
flexmm.stability.hessian_operator) is read around a cell in the middle of the chain; with
K_m the block coupling that cell to the cell m periods away,

    D(q) = Σ_m K_m e^{i q m},    D(q) x = ω² M x,

where q is the phase per cell and M the cell's diagonal mass matrix (docs/physics.md §1.4 is the
closed form of this for the rotating-squares chain). Everything is in the model's
nondimensional units (frequency unit 1/scales.time_s).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import eigh

from flexmm._blas import single_blas_thread
from flexmm.integrators.common import empty_terms
from flexmm.stability import hessian_operator


def _cell_dofs(system, first_site: int, cell_sites: int) -> np.ndarray:
    n, nf = system.n_sites, len(system.fields)
    return np.array([f * n + first_site + s for f in range(nf) for s in range(cell_sites)], dtype=np.int64)


def hessian_blocks(system, cell_sites: int = 1, reach: int = 2, q_ref=None) -> tuple[np.ndarray, np.ndarray]:
    """Coupling blocks K_m, m = −reach..reach, shape (2 reach + 1, d, d), and the cell masses (d,).

    ValueError if the chain is too short or the blocks of two neighbouring cells differ (then
    the lattice period is not ``cell_sites``).
    """
    n = system.n_sites
    if n < (2 * reach + 4) * cell_sites:
        raise ValueError(f"need at least {(2 * reach + 4) * cell_sites} sites, the system has {n}")
    kx = hessian_operator(system, empty_terms(), q_ref)
    mid = (n // 2 // cell_sites) * cell_sites

    def blocks(c0: int) -> np.ndarray:
        rows = _cell_dofs(system, c0, cell_sites)
        out = []
        for m in range(-reach, reach + 1):
            cols = _cell_dofs(system, c0 + m * cell_sites, cell_sites)
            out.append(np.column_stack([kx(np.eye(1, system.ndof, j).ravel())[rows] for j in cols]))
        return np.array(out)

    K = blocks(mid)
    K2 = blocks(mid - cell_sites)
    if not np.allclose(K, K2, rtol=1e-5, atol=1e-7 * np.max(np.abs(K))):
        raise ValueError(f"the Hessian is not periodic with {cell_sites} site(s) per cell; "
                         f"try cell_sites={2 * cell_sites}")
    return K, system.mass[_cell_dofs(system, mid, cell_sites)]


def bloch_frequencies(system, q, cell_sites: int = 1, reach: int = 2, q_ref=None) -> np.ndarray:
    """Angular frequencies ω(q), shape q.shape + (n_branches,), ascending (nondimensional).

    q is the phase per cell (in [−π, π]); n_branches = number of fields × cell_sites. Unstable
    (negative ω²) modes come out as NaN.
    """
    K, mass = hessian_blocks(system, cell_sites, reach, q_ref)
    M = np.diag(mass)
    m = np.arange(-reach, reach + 1)
    qa = np.atleast_1d(np.asarray(q, dtype=float))
    out = np.empty(qa.shape + (K.shape[1],))
    with single_blas_thread():  # small dense eigenproblems: BLAS threads only add overhead
        for idx, qq in np.ndenumerate(qa):
            D = np.tensordot(np.exp(1j * qq * m), K, axes=(0, 0))
            lam = eigh(0.5 * (D + D.conj().T), M, eigvals_only=True)
            out[idx] = np.where(lam >= -1e-10 * max(1.0, np.max(np.abs(lam))), np.sqrt(np.abs(lam)), np.nan)
    return out.reshape(np.shape(q) + (K.shape[1],))


def band_edges_numeric(system, cell_sites: int = 1, n_q: int = 257) -> list[tuple[float, float]]:
    """(min, max) of each branch over q ∈ [0, π], nondimensional angular frequency."""
    w = bloch_frequencies(system, np.linspace(0.0, math.pi, n_q), cell_sites)
    return [(float(np.nanmin(w[:, b])), float(np.nanmax(w[:, b]))) for b in range(w.shape[1])]
