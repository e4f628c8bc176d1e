"""Velocity Verlet fused with the rotating-squares chain force: one sweep over memory per step.

``verlet_advance`` streams the state three times per step (force; closing kick; opening kick
and drift). Here each step is one sweep over cache blocks of sites: the block's forces go to
block scratch, then at once

    v += 2 · (h/2) m⁻¹ F,   q += h v      (closing kick of step s, opening kick and drift of s+1)

(the last step: v += (h/2) m⁻¹ F and F is stored in ``f``). A block's force needs the hinges to
its neighbours at the *old* state, so each block's right hinge is evaluated before the block
moves and carried to the next block, and the hinges between the ranges of different threads
are evaluated for all ranges before the threads start. The arithmetic is that of
``verlet_advance`` with ``hinge.chain_force`` (same operations in the same order; results agree
to rounding, tests/integrators/test_trig_and_parallel_kernels.py); the scheme only saves
memory traffic: ≈ 20 instead of ≈ 32 doubles per unit and step, and ≈ 10 on a uniform
chain, whose parameter tables are replaced by block-sized copies that stay in cache
(``_cached_tables``; benchmarks/).

Used for scenes without damping or external terms (contacts, dashpots, drives) and with the
chain's own hinge order (``fusable``); anything else runs ``verlet_advance``.
"""

from __future__ import annotations

import numpy as np

from flexmm._jit import jit, prange
from flexmm.integrators.verlet import BLOCK, _count, _start
from flexmm.models.hinge import CACHE_BLOCK, PARALLEL_BLOCK, ChainArgs, chain_block, hinge_at


def fusable(args, q: np.ndarray, minv: np.ndarray, damp: np.ndarray, terms) -> bool:
    """Whether the fused sweep applies: chain-ordered hinges, 2N DOFs, no damping, no terms.

    Checked once in Python when a stepper is made (``parallel.advance_kernel``), so the fused
    kernels carry no fallback and a first run compiles one Verlet kernel, not two.
    """
    if not isinstance(args, ChainArgs):
        return False
    n = args.site_prm.shape[0]
    if q.shape[0] != 2 * n or args.hinge_a.shape[0] != n - 1:
        return False
    if terms.con_ij.shape[0] + terms.dash_ij.shape[0] + terms.drv_dof.shape[0] > 0:
        return False
    idx = np.arange(n - 1)
    return (not np.any(damp * minv != 0.0) and np.array_equal(args.hinge_a, idx)
            and np.array_equal(args.hinge_b, idx + 1))


@jit
def _uniform(hprm, sprm):
    """Every hinge row equals row (h mod 2) (the shear sign alternates), every site row row 0."""
    if hprm.shape[0] < 2:
        return False
    for h in range(hprm.shape[0]):
        for k in range(hprm.shape[1]):
            if hprm[h, k] != hprm[h & 1, k]:
                return False
    for i in range(sprm.shape[0]):
        for k in range(sprm.shape[1]):
            if sprm[i, k] != sprm[0, k]:
                return False
    return True


@jit
def _cached_tables(hprm, sprm):
    """Block-sized parameter tables of a uniform chain (``_uniform``), else empty ones.

    Row j of the hinge copy is row (j mod 2), so the copy viewed from (a mod 2) serves any
    block starting at site a (``_params``).
    """
    if not _uniform(hprm, sprm):
        return np.empty((0, hprm.shape[1])), np.empty((0, sprm.shape[1]))
    hp = np.empty((CACHE_BLOCK + 2, hprm.shape[1]))
    sp = np.empty((CACHE_BLOCK + 2, sprm.shape[1]))
    for j in range(CACHE_BLOCK + 2):
        hp[j] = hprm[j & 1]
        sp[j] = sprm[0]
    return hp, sp


@jit
def _params(args, tables, i):
    """Hinge and site parameter tables viewed from site i (≥ −1): the chain's or the cached ones."""
    hp, sp = tables
    if hp.shape[0] == 0:
        return args[2][i:], args[3][i:]
    return hp[i & 1 :], sp


@jit
def _kicks(minv, h):
    """Per-DOF h/2 · m⁻¹."""
    kick = np.empty(minv.shape[0])
    for k in range(minv.shape[0]):
        kick[k] = 0.5 * h * minv[k]
    return kick


@jit
def _kick_drift(q, v, kick, fb, h, last, f):
    """Block pass (views over the same DOFs, from 0): end + start kicks and drift, or the last
    half kick with F stored in ``f``."""
    if last:
        for k in range(v.shape[0]):
            v[k] += kick[k] * fb[k]
            f[k] = fb[k]
    else:
        for k in range(v.shape[0]):
            v[k] += 2.0 * kick[k] * fb[k]
            q[k] += h * v[k]


@jit
def _sweep(q, v, f, kick, args, tables, buf, n, lo, hi, left, right, h, last):
    """One step on sites lo..hi−1; ``left``/``right``: the range's outer hinges at the old state."""
    ha, hb = args[0], args[1]
    fu, ft, cs, sn = buf[0], buf[1], buf[2], buf[3]
    for a in range(lo, hi, CACHE_BLOCK):
        b = min(a + CACHE_BLOCK, hi)
        fl_r, ga_r, gb_r = right
        if b < hi:
            hp, sp = _params(args, tables, b - 1)
            fl_r, ga_r, gb_r = hinge_at(q, hp, sp, n, b)
        hp, sp = _params(args, tables, a)
        chain_block(q, ha, hb, hp, sp, cs, sn, fu, ft, n, a, b, left, (fl_r, ga_r), False)
        m = b - a
        _kick_drift(q[a:b], v[a:b], kick[a:b], fu[:m], h, last, f[a:b])
        _kick_drift(q[n + a : n + b], v[n + a : n + b], kick[n + a : n + b], ft[:m], h, last, f[n + a : n + b])
        left = (fl_r, gb_r)


@jit
def _outer_hinges(q, args, tables, n_ranges, edges):
    """``hinge_at`` at the first site of each range (and at n): edges (n_ranges + 1, 3)."""
    n = args[3].shape[0]
    for r in range(n_ranges + 1):
        i = r * n // n_ranges
        hp, sp = _params(args, tables, i - 1)
        edges[r, 0], edges[r, 1], edges[r, 2] = hinge_at(q, hp, sp, n, i)


@jit
def _prepare(args, minv, h, n_ranges):
    """Per-call arrays: kicks, cached tables, block scratch per range, range-edge hinges (zeros)."""
    return (_kicks(minv, h), _cached_tables(args[2], args[3]), np.empty((n_ranges, 4, CACHE_BLOCK)),
            np.zeros((n_ranges + 1, 3)))


@jit
def _range_step(q, v, f, kick, args, tables, buf, edges, n_ranges, r, h, last):
    """One step on range r of n_ranges (its outer hinges from ``edges``)."""
    n = args[3].shape[0]
    _sweep(q, v, f, kick, args, tables, buf[r], n, r * n // n_ranges, (r + 1) * n // n_ranges,
           (edges[r, 0], edges[r, 2]), (edges[r + 1, 0], edges[r + 1, 1], edges[r + 1, 2]), h, last)


@jit
def chain_verlet_advance(args, q, v, f, minv, damp, terms, t, h, nsteps, acc):
    """``verlet_advance`` for ``hinge.chain_force`` (same arguments and results), fused.

    Only for states where ``fusable`` holds (the caller checks).
    """
    if nsteps <= 0:
        return t
    kick, tables, buf, edges = _prepare(args, minv, h, 1)
    _start(q, v, f, kick, kick, h, False)
    for s in range(nsteps):
        t += h
        _range_step(q, v, f, kick, args, tables, buf, edges, 1, 0, h, s == nsteps - 1)
    _count(acc, nsteps)
    return t


@jit(parallel=True)
def chain_verlet_advance_parallel(args, q, v, f, minv, damp, terms, t, h, nsteps, acc):
    """``chain_verlet_advance`` with the site ranges shared out among numba's threads."""
    if nsteps <= 0:
        return t
    nr = max(1, min(args[3].shape[0] // PARALLEL_BLOCK, 16))  # fixed ranges (not thread count)
    kick, tables, buf, edges = _prepare(args, minv, h, nr)
    nd = q.shape[0]
    nb = max(1, min(nd // BLOCK, 16))
    for c in prange(nb):
        lo, hi = c * nd // nb, (c + 1) * nd // nb
        _start(q[lo:hi], v[lo:hi], f[lo:hi], kick[lo:hi], kick[lo:hi], h, False)
    for s in range(nsteps):
        t += h
        _outer_hinges(q, args, tables, nr, edges)
        for r in prange(nr):
            _range_step(q, v, f, kick, args, tables, buf, edges, nr, r, h, s == nsteps - 1)
    _count(acc, nsteps)
    return t
