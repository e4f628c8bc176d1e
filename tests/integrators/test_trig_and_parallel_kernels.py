"""The vectorised sincos and the threaded chain kernels give the serial results."""

from __future__ import annotations

import numba
import numpy as np
import pytest
from integrator_helpers import chain_problem

from flexmm._jit import jit
from flexmm._trig import sincos
from flexmm.integrators import INTEGRATORS
from flexmm.integrators.parallel import kernels
from flexmm.models.hinge import chain_force, chain_force_parallel


@jit
def _many(x, s, c):
    for i in range(x.shape[0]):
        s[i], c[i] = sincos(x[i])


def test_sincos_accuracy() -> None:
    rng = np.random.default_rng(0)
    x = np.concatenate([rng.uniform(-1, 1, 20000), rng.uniform(-1e4, 1e4, 20000),
                        np.pi / 4 * np.arange(-40, 41), [0.0, -0.0, 1e-300]])
    s, c = np.empty_like(x), np.empty_like(x)
    _many(x, s, c)
    ulp = np.spacing(1.0)
    assert np.max(np.abs(s - np.sin(x))) < 4 * ulp * max(1.0, 1e-4 * np.abs(x).max())
    assert np.max(np.abs(c - np.cos(x))) < 4 * ulp * max(1.0, 1e-4 * np.abs(x).max())
    small = np.abs(x) < 1
    np.testing.assert_allclose(s[small], np.sin(x[small]), rtol=3e-16, atol=1e-300)
    bad = np.array([np.nan, np.inf, -np.inf])
    s, c = np.empty(3), np.empty(3)
    _many(bad, s, c)
    assert not np.any(np.isfinite(s)) and not np.any(np.isfinite(c))  # blow-ups stay visible


def test_parallel_chain_force_equals_serial() -> None:
    problem = chain_problem(20_000, theta0_rad=0.2, n_lateral=2, lateral_stretch=True)
    s = problem.system
    q = 0.1 * np.random.default_rng(2).standard_normal(s.ndof)
    a, b = np.zeros(s.ndof), np.zeros(s.ndof)
    chain_force(q, s.args, a)
    numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
    chain_force_parallel(q, s.args, b)
    np.testing.assert_allclose(b, a, rtol=0, atol=1e-15)


@pytest.mark.parametrize("variant", ["undamped", "drive+damping"])
def test_parallel_verlet_equals_serial(variant) -> None:
    problem = chain_problem(20_000, variant=variant)
    s, terms = problem.system, problem.terms_tuple()
    spec = INTEGRATORS["velocity_verlet"]
    rng = np.random.default_rng(3)
    q0 = 0.05 * rng.standard_normal(s.ndof)
    v0 = 0.05 * rng.standard_normal(s.ndof)
    out = []
    for threads in (1, 2):
        advance, force, used = kernels(spec, s.force, threads)
        assert used == min(threads, numba.config.NUMBA_NUM_THREADS)
        q, v, f, acc = q0.copy(), v0.copy(), np.zeros(s.ndof), np.zeros(8)
        spec.init(force, s.args, q, v, 0.0, f, terms)
        advance(force, s.args, q, v, f, s.inv_mass, problem.damp, terms, 0.0, 0.1, 20, acc)
        out.append((q, v, acc))
    np.testing.assert_allclose(out[1][0], out[0][0], rtol=0, atol=1e-13)
    np.testing.assert_allclose(out[1][1], out[0][1], rtol=0, atol=1e-13)
    np.testing.assert_allclose(out[1][2][:2], out[0][2][:2], rtol=1e-12)
