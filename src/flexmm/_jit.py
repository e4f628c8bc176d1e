"""The single numba wrapper every compiled kernel goes through.

All numba flags live here: ``cache=True``, a fastmath subset that keeps NaN/inf checks
working (no ``nnan``/``ninf``), and ``FLEXMM_NO_JIT=1`` in the environment to run every
kernel as plain Python for debugging.

No reassociation and no contraction into fused multiply-adds: with them, a kernel inlined into
a stepper compiled in the same process (a cold numba cache) and the same kernel loaded from the
cache were optimised differently, and the same config gave results differing in the last bits
(≈ 1e-15) depending on the cache state. Without them the operations keep their written order
and rounding everywhere; the price is ≈ 14 % of the chain's single-thread throughput.
"""

from __future__ import annotations

import os

import numba

NO_JIT = os.environ.get("FLEXMM_NO_JIT", "0") == "1"

# NaN/inf semantics are kept so blow-ups are seen; see the module docstring for reassoc/contract.
FASTMATH = frozenset({"nsz", "arcp", "afn"})

prange = range if NO_JIT else numba.prange


def jit(fn=None, *, parallel: bool = False, cache: bool = True):
    """Compile ``fn`` with flexmm's numba settings (or return it untouched if NO_JIT).

    ``cache=False`` for kernels that take other compiled functions as arguments (integrator
    steppers receive the model's ``force``): numba cannot reuse such entries across processes,
    so caching them only adds an index entry per process, and re-pickling that index fails
    ("underlying object has vanished") once it holds a dispatcher that no longer exists.
    """

    def wrap(f):
        if NO_JIT:
            return f
        return numba.njit(
            f,
            cache=cache,
            fastmath=set(FASTMATH),
            parallel=parallel,
            nogil=True,
            error_model="numpy",
            boundscheck=False,
        )

    return wrap if fn is None else wrap(fn)
