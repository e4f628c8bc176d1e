"""The vectorised sincos, the threaded chain kernels and velocity Verlet fused with the chain
force give the serial, unfused results."""

from __future__ import annotations

import numba
import numpy as np
import pytest
from integrator_helpers import chain_problem

from flexmm._jit import jit
from flexmm._trig import sincos
from flexmm.integrators import INTEGRATORS
from flexmm.integrators.parallel import advance_kernel
from flexmm.integrators.stepper import make_stepper
from flexmm.models.hinge import ChainArgs
from flexmm.models.sheet_kernels import SheetArgs
from flexmm.integrators.verlet import verlet_advance
from flexmm.integrators.verlet_chain import (_cached_tables, fusable, chain_verlet_advance,
                                             chain_verlet_advance_parallel)
from flexmm.models.hinge import H_KS, S_KR, chain_force, chain_force_parallel, chain_reference


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
    s = problem.system
    rng = np.random.default_rng(3)
    q0 = 0.05 * rng.standard_normal(s.ndof)
    v0 = 0.05 * rng.standard_normal(s.ndof)
    out = []
    for threads in (1, 2):
        st = make_stepper(problem, "velocity_verlet", h=0.1, threads=threads, q0=q0, v0=v0)
        assert st.threads == min(threads, numba.config.NUMBA_NUM_THREADS)
        st.advance(20)
        out.append((st.q, st.v, st.acc))
    np.testing.assert_allclose(out[1][0], out[0][0], rtol=0, atol=1e-13)
    np.testing.assert_allclose(out[1][1], out[0][1], rtol=0, atol=1e-13)
    np.testing.assert_allclose(out[1][2][:2], out[0][2][:2], rtol=1e-12)


def test_chain_force_over_several_cache_blocks_matches_reference() -> None:
    """5000 units: three cache blocks, so the carried and recomputed block-edge hinges are used."""
    s = chain_problem(5_000, theta0_rad=0.2, n_lateral=2, lateral_stretch=True).system
    q = 0.1 * np.random.default_rng(4).standard_normal(s.ndof)
    f = np.zeros(s.ndof)
    chain_force(q, s.args, f)
    _, f_ref = chain_reference(q, s.args)
    np.testing.assert_allclose(f, f_ref, rtol=0, atol=1e-13 * np.max(np.abs(f_ref)))


def _advance(advance, problem, q0, v0, steps):
    s, terms = problem.system, problem.terms
    q, v, f, acc = q0.copy(), v0.copy(), np.zeros(s.ndof), INTEGRATORS["velocity_verlet"].new_acc(s.ndof)
    INTEGRATORS["velocity_verlet"].init(s.args, q, v, 0.0, f, terms)
    t = advance(s.args, q, v, f, s.inv_mass, problem.damp, terms, 0.0, 0.1, steps, acc)
    return q, v, f, t, acc


@pytest.mark.parametrize("threads", [1, 2])
@pytest.mark.parametrize("chain", ["uniform", "graded"])
def test_fused_chain_verlet_equals_unfused(threads, chain) -> None:
    """Fused sweep (several cache blocks and thread ranges) = verlet_advance + chain_force, with
    the cached parameter tables of a uniform chain and with the chain's own (graded) tables."""
    problem = chain_problem(20_000, theta0_rad=0.2, n_lateral=2, lateral_stretch=True, right="fixed")
    s = problem.system
    assert fusable(s.args, s.q0, s.inv_mass, problem.damp, problem.terms)
    assert _cached_tables(s.args[2], s.args[3])[0].shape[0] > 0
    if chain == "graded":
        s.args[2][:, H_KS] *= np.linspace(0.5, 1.5, s.n_sites - 1)
        s.args[3][:, S_KR] *= np.linspace(1.5, 0.5, s.n_sites)
        assert _cached_tables(s.args[2], s.args[3])[0].shape[0] == 0
    rng = np.random.default_rng(5)
    q0, v0 = 0.05 * rng.standard_normal(s.ndof), 0.05 * rng.standard_normal(s.ndof)
    ref = _advance(verlet_advance, problem, q0, v0, 20)
    numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    fused = chain_verlet_advance if threads == 1 else chain_verlet_advance_parallel
    out = _advance(fused, problem, q0, v0, 20)
    for a, b in zip(out[:3], ref[:3]):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-13)
    assert out[3] == ref[3]
    np.testing.assert_array_equal(out[4], ref[4])  # ledger and counters


def test_kernels_pick_the_fused_verlet_only_where_it_applies() -> None:
    spec = INTEGRATORS["velocity_verlet"]
    undamped = chain_problem(50)
    s = undamped.system

    def pick(spec, p):
        return advance_kernel(spec, p.system.args, p.system.inv_mass, p.damp, p.terms, 1)[0]

    assert fusable(s.args, s.q0, s.inv_mass, undamped.damp, undamped.terms)
    assert pick(spec, undamped) is chain_verlet_advance
    assert pick(INTEGRATORS["pefrl"], undamped) is INTEGRATORS["pefrl"].advance
    for variant in ("viscous", "drive+damping", "prescribed"):
        p = chain_problem(50, variant=variant)
        assert not fusable(p.system.args, p.system.q0, p.system.inv_mass, p.damp, p.terms), variant
        assert pick(spec, p) is spec.advance, variant
    ha, hb, *rest = s.args
    shuffled = ChainArgs(ha[::-1].copy(), hb[::-1].copy(), *rest)
    assert not fusable(shuffled, s.q0, s.inv_mass, undamped.damp, undamped.terms)
    sheet = SheetArgs(*([np.zeros(0)] * 10))
    assert not fusable(sheet, s.q0, s.inv_mass, undamped.damp, undamped.terms)