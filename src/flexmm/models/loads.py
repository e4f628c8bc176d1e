"""Constant loads: a linear potential E_load = −Σ_k f_k q_k on chosen DOFs (their kernels).

``loads`` = (dof (L,) int64, value (L,)): generalised forces held constant during the dynamics,
so the energy with them is conserved. The sheet carries them in ``SheetArgs.loads``; the chain
becomes a ``LoadedChainArgs`` (``predeform.attach_loads``).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from flexmm._jit import jit
from flexmm.models.hinge import ChainArgs, chain_energy, chain_force, chain_reference


def empty_loads() -> tuple:
    """Load arguments with no loads: (dof (0,), value (0,))."""
    return (np.zeros(0, np.int64), np.zeros(0))


@jit
def load_terms(q, loads, out, want_force):
    """Add the constant forces to ``out`` (if ``want_force``); return E_load = −Σ f q."""
    dof, val = loads
    e = 0.0
    for k in range(dof.shape[0]):
        e -= val[k] * q[dof[k]]
        if want_force:
            out[dof[k]] += val[k]
    return e


def load_reference(q: np.ndarray, loads: tuple) -> tuple[float, np.ndarray]:
    dof, val = loads
    f = np.zeros_like(q)
    np.add.at(f, dof, val)
    return -float(np.dot(val, q[dof])), f


class LoadedChainArgs(NamedTuple):
    """The chain's arguments plus constant loads (``chain_loaded_force``)."""

    chain: ChainArgs
    loads: tuple


@jit
def chain_loaded_force(q, args, out):
    """Chain forces (hinge.chain_force on ``args[0]``) plus constant loads ``args[1]``."""
    chain_force(q, args[0], out)
    load_terms(q, args[1], out, True)


@jit
def chain_loaded_energy(q, args):
    return chain_energy(q, args[0]) + load_terms(q, args[1], np.empty(0), False)


def chain_loaded_reference(q: np.ndarray, args: tuple) -> tuple[float, np.ndarray]:
    e, f = chain_reference(q, args[0])
    el, fl = load_reference(q, args[1])
    return e + el, f + fl
