"""Linear dispersion of any 1D model from its Hessian and mass matrix (Bloch eigenproblem).

For a built System (flexmm.models) whose sites repeat with a period of ``cell_sites`` sites,
the Hessian K of the energy at the reference state (central differences of the compiled force,
flexmm.stability.hessian_operator) is read around a cell in the middle of the chain; with
K_m the block coupling that cell to the cell m periods away,

    D(q) = Σ_m K_m e^{i q m},    D(q) x = ω² M x,

where q is the phase per cell and M the cell's diagonal mass matrix (docs/physics.md §1.4 is the
closed form of this for the rotating-squares chain): ``chain_cell`` reads the couplings, and
``flexmm.linalg.bloch_frequencies(chain_cell(system), q)`` gives ω(q). Everything is in the
model's nondimensional units (frequency unit 1/scales.time_s).
"""

from __future__ import annotations

import math

import numpy as np

from flexmm.integrators.common import empty_terms
from flexmm.linalg import BlochCell, bloch_frequencies, read_cell
from flexmm.stability import hessian_operator


def _cell_dofs(system, first_site: int, cell_sites: int) -> np.ndarray:
    n, nf = system.n_sites, len(system.fields)
    return np.array([f * n + first_site + s for f in range(nf) for s in range(cell_sites)], dtype=np.int64)


def _blocks(cell: BlochCell, reach: int) -> np.ndarray:
    """The coupling blocks K_m (2 reach + 1, d, d), m = −reach..reach, of a 1D cell."""
    out = np.zeros((2 * reach + 1, cell.size, cell.size))
    m = np.rint(cell.offsets[:, 0]).astype(np.int64) + reach
    np.add.at(out, (m, cell.rows, cell.cols), cell.values)
    return out


def chain_cell(system, cell_sites: int = 1, reach: int = 2, q_ref=None) -> BlochCell:
    """The ``BlochCell`` (offsets in cells, couplings up to ``reach`` cells) of a 1D model whose
    sites repeat every ``cell_sites`` sites, read around a cell in the middle of the chain.

    ValueError if the chain is too short or the couplings of two neighbouring cells differ (then
    the lattice period is not ``cell_sites``).
    """
    n, nf = system.n_sites, len(system.fields)
    if n < (2 * reach + 4) * cell_sites:
        raise ValueError(f"need at least {(2 * reach + 4) * cell_sites} sites, the system has {n}")
    kx = hessian_operator(system, empty_terms(), q_ref)
    site = np.arange(system.ndof) % n
    cls = np.where(np.arange(system.ndof) < nf * n,
                   np.arange(system.ndof) // n * cell_sites + site % cell_sites, -1)
    cell_of = (site // cell_sites)[:, None]
    mid = (n // 2 // cell_sites) * cell_sites

    def read(c0: int) -> BlochCell:
        dofs = _cell_dofs(system, c0, cell_sites)
        return read_cell(kx, system.ndof, dofs, cls, cell_of, system.mass[dofs],
                         keep=lambda off: np.abs(off[:, 0]) <= reach)

    cell = read(mid)
    K, K2 = _blocks(cell, reach), _blocks(read(mid - cell_sites), reach)
    if not np.allclose(K, K2, rtol=1e-5, atol=1e-7 * np.max(np.abs(K))):
        raise ValueError(f"the Hessian is not periodic with {cell_sites} site(s) per cell; "
                         f"try cell_sites={2 * cell_sites}")
    return cell


def band_edges_numeric(system, cell_sites: int = 1, n_q: int = 257) -> list[tuple[float, float]]:
    """(min, max) of each branch over q ∈ [0, π], nondimensional angular frequency."""
    w = bloch_frequencies(chain_cell(system, cell_sites), np.linspace(0.0, math.pi, n_q))
    return [(float(np.nanmin(w[:, b])), float(np.nanmax(w[:, b]))) for b in range(w.shape[1])]
