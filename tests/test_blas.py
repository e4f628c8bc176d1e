"""``flexmm._blas.single_blas_thread``: one BLAS thread inside, the previous count restored after."""

from __future__ import annotations

import numpy as np
import scipy.linalg  # noqa: F401 - loads scipy's own BLAS next to numpy's
from threadpoolctl import threadpool_info

from flexmm._blas import single_blas_thread


def blas_threads() -> list[int]:
    return [lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"]


def test_one_thread_inside_and_restored_after():
    before = blas_threads()
    assert before  # numpy's BLAS at least
    with single_blas_thread():
        assert set(blas_threads()) == {1}
        with single_blas_thread():  # nested
            assert set(blas_threads()) == {1}
        assert set(blas_threads()) == {1}
    assert blas_threads() == before


def test_as_decorator_and_results_unchanged():
    a = np.random.default_rng(1).standard_normal((60, 60))
    a = a + a.T

    @single_blas_thread()
    def top(m):
        assert set(blas_threads()) == {1}
        return np.linalg.eigvalsh(m)[-1]

    before = blas_threads()
    assert np.isclose(top(a), np.linalg.eigvalsh(a)[-1], rtol=1e-12)
    assert blas_threads() == before
