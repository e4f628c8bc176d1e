"""One BLAS thread around small dense linear algebra (eigenvalues, solves, fits).

OpenBLAS (numpy's and scipy's) starts one thread per core and hands every LAPACK call to them.
On small matrices the threads cost far more than they save, and more still on a busy machine,
where they spin-wait for cores that other work holds. A 400 × 400 ``numpy.linalg.eigvalsh``
on a 2-core machine with two busy processes beside it (61 calls): median 26 ms, worst 4.3 s
with the default two threads; median 18 ms, worst 34 ms on one thread.
flexmm's dense problems are small (the dynamical matrix up to ``linalg.DENSE_LIMIT`` DOFs,
Bloch matrices of a cell, least-squares lines), so they run on one BLAS thread::

    from flexmm._blas import single_blas_thread

    with single_blas_thread():
        lam = np.linalg.eigvalsh(a)

or as a decorator, ``@single_blas_thread()``. The limit is process-wide (BLAS has no per-thread
setting) and is restored on exit; nesting is fine. It applies to every BLAS library loaded at
entry (numpy's and scipy's OpenBLAS, or MKL), through ``threadpoolctl``. Large, long
computations (sparse eigensolvers on big systems) are better left to the default threads.
"""

from __future__ import annotations

import sys
from collections.abc import Iterator
from contextlib import contextmanager

_controller = None
_controller_key = -1


def _blas_controller():
    """A cached ``threadpoolctl.ThreadpoolController`` (finding the libraries takes ~1 ms).

    It is rebuilt when modules were imported since it was made, as an import may have loaded
    another BLAS (scipy.linalg brings its own OpenBLAS next to numpy's).
    """
    global _controller, _controller_key
    if _controller is None or _controller_key != len(sys.modules):
        from threadpoolctl import ThreadpoolController

        _controller = ThreadpoolController()
        _controller_key = len(sys.modules)
    return _controller


@contextmanager
def single_blas_thread() -> Iterator[None]:
    """Limit every loaded BLAS library to one thread inside the block (or decorated function)."""
    with _blas_controller().limit(limits=1, user_api="blas"):
        yield


__all__ = ["single_blas_thread"]
