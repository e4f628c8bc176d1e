"""The single numba wrapper every compiled kernel goes through.

All numba flags live here: ``cache=True``, a fastmath subset that keeps NaN/inf checks
working (no ``nnan``/``ninf``), and ``FLEXMM_NO_JIT=1`` in the environment to run every
kernel as plain Python for debugging.
"""

from __future__ import annotations

import os

import numba

NO_JIT = os.environ.get("FLEXMM_NO_JIT", "0") == "1"

# Reassociation and contraction are allowed; NaN/inf semantics are kept so blow-ups are seen.
FASTMATH = frozenset({"nsz", "arcp", "contract", "afn", "reassoc"})

prange = range if NO_JIT else numba.prange


def jit(fn=None, *, parallel: bool = False, cache: bool = True, reassoc: bool = True):
    """Compile ``fn`` with flexmm's numba settings (or return it untouched if NO_JIT).

    ``cache=False`` for kernels that take other compiled functions as arguments (integrator
    steppers receive the model's ``force``): numba cannot reuse such entries across processes,
    so caching them only adds an index entry per process, and re-pickling that index fails
    ("underlying object has vanished") once it holds a dispatcher that no longer exists.
    ``reassoc=False`` keeps the written order of floating-point operations (compensated
    arithmetic such as the argument reduction of ``_trig.sincos``; the flags stay on the
    instructions when the function is inlined into a caller compiled with reassociation).
    """

    def wrap(f):
        if NO_JIT:
            return f
        return numba.njit(
            f,
            cache=cache,
            fastmath=set(FASTMATH) if reassoc else set(FASTMATH) - {"reassoc"},
            parallel=parallel,
            nogil=True,
            error_model="numpy",
            boundscheck=False,
        )

    return wrap if fn is None else wrap(fn)
