"""Hinge energy between rigid rotating units, with its exact gradient (PHYSICS.md §1).

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

The lateral hinges of a chain (n_v per unit, PHYSICS.md §1.1) are an on-site term
E_v = ½ k_g (cos θ0 − cos(θ0+θ))² + ½ k_r θ² with k_g = n_v s_v k_l a²/2, k_r = 2 n_v k_θ.
"""

from __future__ import annotations

import math

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
def _hinges_span(qu, qt, hprm, cs, sn, ou, ot, ha, hb, first, m, fl_l, gb_l, right, cr, sr):
    """Hinge forces on m sites starting at site ``first`` (chain order: hinge h joins h, h + 1).

    Arrays are views starting at ``first`` (loops from 0 vectorise where they can). Site-centred:
    each site takes its left hinge (carried: (fl_l, gb_l) of hinge first−1 on entry) and its
    right hinge, so there are no scattered writes. The last site's right hinge uses the halo
    (cr, sr) = cos/sin at site first+m when ``right``, else it is the chain's end. Returns the
    number of hinges found out of order (the caller then falls back to the general loop).
    """
    bad = 0
    for i in range(m - 1):
        bad += (ha[i] != first + i) | (hb[i] != first + i + 1)
        fl_r, ga_r, gb_r = _chain_hinge(qu, qt, i, hprm, cs[i], sn[i], cs[i + 1], sn[i + 1])
        ou[i] = fl_r - fl_l
        ot[i] -= gb_l + ga_r
        fl_l = fl_r
        gb_l = gb_r
    i = m - 1
    if right:
        bad += (ha[i] != first + i) | (hb[i] != first + i + 1)
        fl_r, ga_r, gb_r = _chain_hinge(qu, qt, i, hprm, cs[i], sn[i], cr, sr)
        ou[i] = fl_r - fl_l
        ot[i] -= gb_l + ga_r
    else:
        ou[i] = -fl_l
        ot[i] -= gb_l
    return bad


@jit
def _site_trig(q, sprm, n, i):
    """(cos, sin) of θ0+θ at site i (a halo value)."""
    s, c = sincos(sprm[i, S_THETA0] + q[n + i])
    return c, s


@jit
def _chain_range(q, ha, hb, hprm, sprm, cs, sn, out, n, lo, hi):
    """All forces on sites lo..hi−1 (chain order), one cache block at a time: the block's site
    terms and cos/sin, then its hinges. Writes only inside lo..hi−1 (halo cos/sin are private),
    so ranges can run on different threads. Returns the count of out-of-order hinges."""
    bad = 0
    for a in range(lo, hi, CACHE_BLOCK):
        b = min(a + CACHE_BLOCK, hi)
        _sites_block(q, sprm, cs, sn, out, n, a, min(b + 1, hi))
        fl_l, gb_l = 0.0, 0.0
        if a > 0:
            cl, sl = (cs[a - 1], sn[a - 1]) if a > lo else _site_trig(q, sprm, n, a - 1)
            fl_l, _, gb_l = _chain_hinge(q[:n], q[n:], a - 1, hprm, cl, sl, cs[a], sn[a])
        cr, sr = 1.0, 0.0
        if b < n:
            cr, sr = (cs[b], sn[b]) if b < hi else _site_trig(q, sprm, n, b)
        bad += _hinges_span(q[a:n], q[n + a : 2 * n], hprm[a:], cs[a:], sn[a:], out[a:n], out[n + a : 2 * n],
                            ha[a:], hb[a:], a, b - a, fl_l, gb_l, b < n, cr, sr)
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
