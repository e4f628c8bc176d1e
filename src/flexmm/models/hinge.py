"""Hinge energy between rigid rotating units, with its exact gradient (docs/physics.md §1).

A hinge joins the hinge point of unit A to that of unit B with three linear springs,

    E = ½ k_l Δl² + ½ k_s Δs² + ½ k_θ Δφ²,
    Δl = d_l + r − (h_A cos(θ0_A+θ_A) + h_B cos(θ0_B+θ_B)),
    Δs = d_s + σ (h_B sin(θ0_B+θ_B) − h_A sin(θ0_A+θ_A)),
    Δφ = θ_A + θ_B,

where d_l, d_s are the relative displacements of B and A along and across the hinge axis,
h = a/2 the centre-to-hinge distance, r = h_A cos θ0_A + h_B cos θ0_B the rest length and
σ = ±1 the checkerboard sign (σ_A for horizontal hinges, −σ_A for vertical ones). θ are the
staggered rotations, so every hinge has the same law. The same function serves chains, sheets,
gradients and defects: only the connectivity and parameter arrays change.

The lateral hinges of a chain (n_v per unit, docs/physics.md §1.1) are an on-site term
E_v = ½ k_g (cos θ0 − cos(θ0+θ))² + ½ k_r θ² with k_g = n_v s_v k_l a²/2, k_r = 2 n_v k_θ.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from flexmm._jit import jit, prange
from flexmm._trig import sincos

# Columns of the per-hinge parameter table.
H_REST, H_HALF_A, H_HALF_B, H_SIGN, H_KL, H_KS, H_KT = range(7)
N_HINGE_PARAMS = 7
# Columns of the per-site parameter table (chain).
S_THETA0, S_KG, S_KR = range(3)
N_SITE_PARAMS = 3
#: sites per block of the parallel chain kernel (blocks are shared out among the threads)
PARALLEL_BLOCK = 4096
#: sites per cache block of the chain kernel's passes (~ a few arrays of 16 kB each: L1/L2)
CACHE_BLOCK = 2048


@jit
def hinge_law(dl, ds, tA, tB, cA, sA, cB, sB, prm):
    """Energy of one hinge and its derivatives.

    ``cA = cos(θ0_A+θ_A)``, ``sA = sin(θ0_A+θ_A)`` (same for B); ``prm`` is a row of the hinge
    table. Returns ``(E, ∂E/∂d_l, ∂E/∂d_s, ∂E/∂θ_A, ∂E/∂θ_B)``.
    """
    hA = prm[H_HALF_A]
    hB = prm[H_HALF_B]
    sig = prm[H_SIGN]
    el = dl + prm[H_REST] - (hA * cA + hB * cB)
    es = ds + sig * (hB * sB - hA * sA)
    ep = tA + tB
    fl = prm[H_KL] * el
    fs = prm[H_KS] * es
    fp = prm[H_KT] * ep
    energy = 0.5 * (fl * el + fs * es + fp * ep)
    gA = fl * hA * sA - fs * sig * hA * cA + fp
    gB = fl * hB * sB + fs * sig * hB * cB + fp
    return energy, fl, fs, gA, gB


@jit
def _chain_sites(theta, sprm, cs, sn, out_u, out_t):
    """Sites of one block: cos/sin of θ0+θ into the scratch, lateral-hinge forces on θ, zero u.

    All arguments are slices over the same sites, so loops start at 0 and vectorise (a loop
    from a variable start keeps numba's negative-index wraparound and does not); they are
    split so that each is simple (``_trig.sincos`` is branch-free).
    """
    m = theta.shape[0]
    kg_max = 0.0
    for i in range(m):
        cs[i] = sprm[i, S_THETA0] + theta[i]
        kg_max = max(kg_max, abs(sprm[i, S_KG]))
    for i in range(m):
        s, c = sincos(cs[i])
        cs[i] = c
        sn[i] = s
    for i in range(m):
        out_u[i] = 0.0
    if kg_max == 0.0:
        for i in range(m):
            out_t[i] = -sprm[i, S_KR] * theta[i]
    else:
        for i in range(m):
            _, c0 = sincos(sprm[i, S_THETA0])
            out_t[i] = -(sprm[i, S_KG] * (c0 - cs[i]) * sn[i] + sprm[i, S_KR] * theta[i])


@jit
def _sites_block(q, sprm, cs, sn, out, n, lo, hi):
    """``_chain_sites`` on sites lo..hi−1, in cache-sized pieces (its loops then stay in L1/L2)."""
    for a in range(lo, hi, CACHE_BLOCK):
        b = min(a + CACHE_BLOCK, hi)
        _chain_sites(q[n + a : n + b], sprm[a:b], cs[a:b], sn[a:b], out[a:b], out[n + a : n + b])


@jit
def _chain_hinge(qu, qt, h, hprm, ca, sa, cb, sb):
    """(∂E/∂d_l, ∂E/∂θ_A, ∂E/∂θ_B) of hinge h between sites h and h + 1 (no shear d_s).

    ``qu``, ``qt``: u and θ (or views of them, with ``hprm`` viewed alike); ``ca, sa, cb, sb``:
    cos/sin of θ0+θ at the two sites.
    """
    hA = hprm[h, H_HALF_A]
    hB = hprm[h, H_HALF_B]
    sig = hprm[h, H_SIGN]
    fl = hprm[h, H_KL] * (qu[h + 1] - qu[h] + hprm[h, H_REST] - (hA * ca + hB * cb))
    fs = hprm[h, H_KS] * sig * (hB * sb - hA * sa)
    fp = hprm[h, H_KT] * (qt[h] + qt[h + 1])
    return fl, fl * hA * sa - fs * sig * hA * ca + fp, fl * hB * sb + fs * sig * hB * cb + fp


@jit
def _hinges_span(qu, qt, hprm, cs, sn, ou, ot, ha, hb, first, m, fl_l, gb_l, fl_r, ga_r, right, check):
    """Hinge forces on m sites starting at site ``first`` (chain order: hinge h joins h, h + 1).

    Arrays are views starting at ``first`` (``cs``, ``sn``, ``ou``, ``ot`` may be block scratch).
    Site-centred: each site takes its left hinge (carried: (fl_l, gb_l) of hinge first−1 on entry)
    and its right hinge, so there are no scattered writes; the last site's right hinge
    (fl_r, ga_r) is given by the caller (zeros at the chain's end; ``right``: it exists).
    With ``check``, returns the number of hinges found out of order (the caller then falls back
    to the general loop), else 0 without reading ``ha``, ``hb``.
    """
    bad = 0
    for i in range(m - 1):
        if check:
            bad += (ha[i] != first + i) | (hb[i] != first + i + 1)
        fl, ga, gb = _chain_hinge(qu, qt, i, hprm, cs[i], sn[i], cs[i + 1], sn[i + 1])
        ou[i] = fl - fl_l
        ot[i] -= gb_l + ga
        fl_l = fl
        gb_l = gb
    i = m - 1
    if check and right:
        bad += (ha[i] != first + i) | (hb[i] != first + i + 1)
    ou[i] = fl_r - fl_l
    ot[i] -= gb_l + ga_r
    return bad


@jit
def hinge_at(q, hp, sp, n, i):
    """(∂E/∂d_l, ∂E/∂θ_A, ∂E/∂θ_B) of hinge i−1 ↔ i from q; zeros if i is 0 or n (no hinge).

    ``hp``, ``sp``: the hinge and site parameter tables viewed from hinge / site i−1.
    """
    if i <= 0 or i >= n:
        return 0.0, 0.0, 0.0
    sa, ca = sincos(sp[0, S_THETA0] + q[n + i - 1])
    sb, cb = sincos(sp[1, S_THETA0] + q[n + i])
    return _chain_hinge(q[i - 1 : n], q[n + i - 1 : 2 * n], 0, hp, ca, sa, cb, sb)


@jit
def chain_block(q, ha, hb, hp, sp, cs, sn, ou, ot, n, a, b, left, right, check):
    """All forces on sites a..b−1 into ``ou``, ``ot`` (u and θ parts, views from site a).

    ``hp``, ``sp``: parameter tables viewed from site a; ``cs``, ``sn``: scratch from site a;
    ``left`` = (fl, gb) of hinge a−1 ↔ a, ``right`` = (fl, ga) of hinge b−1 ↔ b (``hinge_at``).
    Reads q only on sites a..b−1, so a caller may already have moved the neighbouring sites.
    Returns the out-of-order count (``check``).
    """
    _chain_sites(q[n + a : n + b], sp, cs, sn, ou, ot)
    return _hinges_span(q[a:n], q[n + a : 2 * n], hp, cs, sn, ou, ot, ha[a:], hb[a:], a, b - a,
                        left[0], left[1], right[0], right[1], b < n, check)


@jit
def _chain_range(q, ha, hb, hprm, sprm, cs, sn, out, n, lo, hi):
    """All forces on sites lo..hi−1 (chain order), one cache block at a time (site terms and
    cos/sin, then hinges, with the blocks' boundary hinges from ``hinge_at``). Writes only inside
    lo..hi−1, so ranges can run on different threads. Returns the count of out-of-order hinges."""
    bad = 0
    fl_l, _, gb_l = hinge_at(q, hprm[lo - 1 :], sprm[lo - 1 :], n, lo)
    for a in range(lo, hi, CACHE_BLOCK):
        b = min(a + CACHE_BLOCK, hi)
        fl_r, ga_r, gb_r = hinge_at(q, hprm[b - 1 :], sprm[b - 1 :], n, b)
        bad += chain_block(q, ha, hb, hprm[a:], sprm[a:], cs[a:], sn[a:], out[a:n], out[n + a : 2 * n], n, a, b,
                           (fl_l, gb_l), (fl_r, ga_r), True)
        fl_l, gb_l = fl_r, gb_r
    return bad


@jit
def _chain_hinges_general(q, ha, hb, hprm, cs, sn, out, n):
    """Hinge forces for any hinge list (scattered accumulation)."""
    for h in range(ha.shape[0]):
        a = ha[h]
        b = hb[h]
        _, fl, _, gA, gB = hinge_law(
            q[b] - q[a], 0.0, q[n + a], q[n + b], cs[a], sn[a], cs[b], sn[b], hprm[h]
        )
        out[a] += fl
        out[b] -= fl
        out[n + a] -= gA
        out[n + b] -= gB


@jit
def _chain_fallback(q, ha, hb, hprm, sprm, cs, sn, out, n):
    _sites_block(q, sprm, cs, sn, out, n, 0, n)
    _chain_hinges_general(q, ha, hb, hprm, cs, sn, out, n)


class ChainArgs(NamedTuple):
    """What the chain kernels read (``chain_force``, ``chain_energy``; numba takes NamedTuples).

    ``hinge_a``/``hinge_b`` (H,) the units each hinge joins, ``hinge_prm`` (H, 7) its law's
    parameters (``H_*`` columns), ``site_prm`` (N, 3) each unit's on-site parameters (``S_*``),
    ``cos``/``sin`` (N,) scratch for the units' angles.
    """

    hinge_a: np.ndarray
    hinge_b: np.ndarray
    hinge_prm: np.ndarray
    site_prm: np.ndarray
    cos: np.ndarray
    sin: np.ndarray


@jit
def chain_force(q, args, out):
    """Generalised forces −∂E/∂q of the rotating-squares chain, written into ``out``.

    State: ``q[:N]`` = u (units of a), ``q[N:2N]`` = θ. ``args`` = (hinge_a (H,), hinge_b (H,),
    hinge_prm (H, 7), site_prm (N, 3), cos_scratch (N,), sin_scratch (N,)).
    DOFs beyond 2N (if any) are left at zero. Chain-ordered hinges (h joins h and h + 1, as
    ``rotating_chain.chain_tables`` builds them) take a vectorised site-centred path; any
    other hinge list the general scattered loop (same result).
    """
    ha, hb, hprm, sprm, cs, sn = args
    n = sprm.shape[0]
    for k in range(2 * n, out.shape[0]):
        out[k] = 0.0
    if ha.shape[0] != n - 1 or _chain_range(q, ha, hb, hprm, sprm, cs, sn, out, n, 0, n) > 0:
        _chain_fallback(q, ha, hb, hprm, sprm, cs, sn, out, n)


@jit(parallel=True)
def chain_force_parallel(q, args, out):
    """``chain_force`` with the site loops split over numba's threads (worth it for N ≳ 1e5)."""
    ha, hb, hprm, sprm, cs, sn = args
    n = sprm.shape[0]
    for k in range(2 * n, out.shape[0]):
        out[k] = 0.0
    n_chunks = max(1, min(n // PARALLEL_BLOCK, 16))  # fixed ranges (not thread count): cacheable
    bad = 0
    if ha.shape[0] == n - 1:
        for c in prange(n_chunks):
            bad += _chain_range(q, ha, hb, hprm, sprm, cs, sn, out, n, c * n // n_chunks, (c + 1) * n // n_chunks)
    if ha.shape[0] != n - 1 or bad > 0:
        _chain_fallback(q, ha, hb, hprm, sprm, cs, sn, out, n)


@jit
def chain_energy(q, args):
    """Potential energy of the rotating-squares chain (same arguments as ``chain_force``)."""
    ha, hb, hprm, sprm, cs, sn = args
    n = sprm.shape[0]
    total = 0.0
    for i in range(n):
        t = q[n + i]
        ang = sprm[i, S_THETA0] + t
        cs[i] = math.cos(ang)
        sn[i] = math.sin(ang)
        g = math.cos(sprm[i, S_THETA0]) - cs[i]
        total += 0.5 * (sprm[i, S_KG] * g * g + sprm[i, S_KR] * t * t)
    for h in range(ha.shape[0]):
        a = ha[h]
        b = hb[h]
        e, _, _, _, _ = hinge_law(
            q[b] - q[a], 0.0, q[n + a], q[n + b], cs[a], sn[a], cs[b], sn[b], hprm[h]
        )
        total += e
    return total


def chain_reference(q: np.ndarray, args: tuple) -> tuple[float, np.ndarray]:
    """Readable numpy version of the chain energy and forces (the test oracle).

    Vectorised over hinges with ``np.add.at``; independent of the compiled code path.
    """
    ha, hb, hprm, sprm, _, _ = args
    n = sprm.shape[0]
    u, th = q[:n], q[n : 2 * n]
    ang = sprm[:, S_THETA0] + th
    c, s = np.cos(ang), np.sin(ang)
    g = np.cos(sprm[:, S_THETA0]) - c
    energy = 0.5 * np.sum(sprm[:, S_KG] * g**2 + sprm[:, S_KR] * th**2)
    f = np.zeros_like(q)
    f[n : 2 * n] = -(sprm[:, S_KG] * g * s + sprm[:, S_KR] * th)
    p = hprm.T
    el = u[hb] - u[ha] + p[H_REST] - (p[H_HALF_A] * c[ha] + p[H_HALF_B] * c[hb])
    es = p[H_SIGN] * (p[H_HALF_B] * s[hb] - p[H_HALF_A] * s[ha])
    ep = th[ha] + th[hb]
    energy += 0.5 * np.sum(p[H_KL] * el**2 + p[H_KS] * es**2 + p[H_KT] * ep**2)
    fl, fs, fp = p[H_KL] * el, p[H_KS] * es, p[H_KT] * ep
    np.add.at(f, ha, fl)
    np.add.at(f, hb, -fl)
    np.add.at(f, n + ha, -(fl * p[H_HALF_A] * s[ha] - fs * p[H_SIGN] * p[H_HALF_A] * c[ha] + fp))
    np.add.at(f, n + hb, -(fl * p[H_HALF_B] * s[hb] + fs * p[H_SIGN] * p[H_HALF_B] * c[hb] + fp))
    return float(energy), f
