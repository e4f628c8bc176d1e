"""Energies of single elements of the rigid-unit models from their strains (docs/physics.md §1–2).

The renderer colours units by energy from stored fields; it evaluates the models' own laws
(``hinge.hinge_law``: the one place the stretch and shear are written; ``joints.joint_law``)
element by element instead of copies of them. Kept apart from the laws' modules so that the
cache of the engine's kernels does not depend on these loops.
"""

from __future__ import annotations

from flexmm._jit import jit
from flexmm.models.hinge import hinge_law
from flexmm.models.joints import joint_law


@jit
def hinge_energies(dl, ds, ta, tb, ca, sa, cb, sb, prm, out):
    """E of every hinge k into ``out[k]``: ``hinge_law`` at (d_l, d_s, θ_A, θ_B) with
    cos/sin of the units' angles θ0 + θ (all (K,)) and ``prm`` (K, N_HINGE_PARAMS) its rows (any
    consistent units: SI rows give joules)."""
    for k in range(out.shape[0]):
        out[k] = hinge_law(dl[k], ds[k], ta[k], tb[k], ca[k], sa[k], cb[k], sb[k], prm[k])[0]


@jit
def joint_energies(psi, prm, out):
    """V(ψ_k) of the bistable joint law (``joints.joint_law``, row ``prm`` = k, β, ψ*) into ``out[k]``."""
    for k in range(out.shape[0]):
        out[k] = joint_law(psi[k], prm)[0]
