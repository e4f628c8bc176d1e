"""Compiled kernels of chains and networks of masses: ``MassArgs``, force, energy, reference.

Bonds between two sites and on-site terms, each through a law of ``laws`` (code + parameter row,
tabulated laws read a shared spline table); ``mass_chain`` builds the arrays.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from flexmm._jit import jit
from flexmm.models import laws as lw


class MassArgs(NamedTuple):
    """What the mass-chain kernels read: bonds (``bond_i``, ``bond_j`` (B,), law ``bond_code`` (B,)
    and ``bond_prm`` (B, P)), on-site terms (``site_i``, ``site_code`` (S,), ``site_prm`` (S, P))
    and the spline ``table`` (T,) tabulated laws index into (``laws``)."""

    bond_i: np.ndarray
    bond_j: np.ndarray
    bond_code: np.ndarray
    bond_prm: np.ndarray
    site_i: np.ndarray
    site_code: np.ndarray
    site_prm: np.ndarray
    table: np.ndarray


@jit
def mass_force(q, args, out):
    """−∂E/∂q into ``out`` (ndof,). ``args`` = (bi (B,), bj (B,), bcode (B,), bprm (B, P),
    si (S,), scode (S,), sprm (S, P), tab (T,)); DOFs beyond the sites get only what acts on them."""
    bi, bj, bcode, bprm, si, scode, sprm, tab = args
    for k in range(out.shape[0]):
        out[k] = 0.0
    for b in range(bi.shape[0]):
        i = bi[b]
        j = bj[b]
        _, t = lw.law(bcode[b], q[j] - q[i], bprm[b], tab)
        out[i] += t
        out[j] -= t
    for s in range(si.shape[0]):
        i = si[s]
        _, d = lw.law(scode[s], q[i], sprm[s], tab)
        out[i] -= d


@jit
def mass_energy(q, args):
    """Potential energy Σ_bonds E_b + Σ_terms V_t (same ``args`` as ``mass_force``)."""
    bi, bj, bcode, bprm, si, scode, sprm, tab = args
    total = 0.0
    for b in range(bi.shape[0]):
        e, _ = lw.law(bcode[b], q[bj[b]] - q[bi[b]], bprm[b], tab)
        total += e
    for s in range(si.shape[0]):
        e, _ = lw.law(scode[s], q[si[s]], sprm[s], tab)
        total += e
    return total


def mass_reference(q: np.ndarray, args: tuple) -> tuple[float, np.ndarray]:
    """Numpy oracle: each element through its law's numpy reference, forces by ``np.add.at``."""
    bi, bj, bcode, bprm, si, scode, sprm, tab = args
    f = np.zeros_like(q)
    energy = 0.0
    for code in np.unique(bcode):
        for b in np.flatnonzero(bcode == code):
            e, t = lw.reference(int(code), q[bj[b]] - q[bi[b]], bprm[b], tab)
            energy += float(e)
            np.add.at(f, [bi[b], bj[b]], [float(t), -float(t)])
    for code in np.unique(scode):
        for s in np.flatnonzero(scode == code):
            e, d = lw.reference(int(code), q[si[s]], sprm[s], tab)
            energy += float(e)
            f[si[s]] -= float(d)
    return energy, f


# ---------------------------------------------------------------- building
