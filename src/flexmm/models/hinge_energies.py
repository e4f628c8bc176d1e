"""Energies of single hinges from their strains, element by element (docs/physics.md §1).

The renderer colours units by energy from stored fields; it evaluates the models' own hinge law
(``hinge.hinge_law``: the one place the stretch and shear are written) on each hinge instead of
a copy of it. Kept apart from ``hinge`` so that the cache of the engine's kernels does not
depend on it.
"""

from __future__ import annotations

from flexmm._jit import jit
from flexmm.models.hinge import hinge_law


@jit
def hinge_energies(dl, ds, ta, tb, ca, sa, cb, sb, prm, out):
    """E of every hinge k into ``out[k]``: ``hinge_law`` at (d_l, d_s, θ_A, θ_B) with
    cos/sin of the units' angles θ0 + θ (all (K,)) and ``prm`` (K, N_HINGE_PARAMS) its rows (any
    consistent units: SI rows give joules)."""
    for k in range(out.shape[0]):
        out[k] = hinge_law(dl[k], ds[k], ta[k], tb[k], ca[k], sa[k], cb[k], sb[k], prm[k])[0]
