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
    _chain_sites(q[n + lo : n + hi], sprm[lo:hi], cs[lo:hi], sn[lo:hi], out[lo:hi], out[n + lo : n + hi])


@jit
def _chain_hinge(q, n, h, hprm, cs, sn):
    """(∂E/∂d_l, ∂E/∂θ_A, ∂E/∂θ_B) of hinge h between sites h and h + 1 (no shear d_s)."""
    a = h
    b = h + 1
    hA = hprm[h, H_HALF_A]
    hB = hprm[h, H_HALF_B]
    sig = hprm[h, H_SIGN]
    fl = hprm[h, H_KL] * (q[b] - q[a] + hprm[h, H_REST] - (hA * cs[a] + hB * cs[b]))
    fs = hprm[h, H_KS] * sig * (hB * sn[b] - hA * sn[a])
    fp = hprm[h, H_KT] * (q[n + a] + q[n + b])
    return fl, fl * hA * sn[a] - fs * sig * hA * cs[a] + fp, fl * hB * sn[b] + fs * sig * hB * cs[b] + fp


@jit
def _chain_hinges_ordered(q, ha, hb, hprm, cs, sn, out, n, lo, hi):
    """Hinge forces on sites lo..hi−1 when hinge h joins sites h and h + 1 (the chain order).

    Site-centred: each site takes its left hinge (carried from the previous site) and its
    right hinge, so the loop has no scattered writes and vectorises. Returns the number of
    hinges found out of order (then the result is invalid and the caller falls back).
    """
    lo = max(lo, 0)  # as in _chain_sites: provably non-negative indices
    fl_l, gb_l = 0.0, 0.0
    if lo > 0:
        fl_l, _, gb_l = _chain_hinge(q, n, lo - 1, hprm, cs, sn)
    bad = 0
    for i in range(lo, min(hi, n - 1)):
        bad += (ha[i] != i) | (hb[i] != i + 1)
        fl_r, ga_r, gb_r = _chain_hinge(q, n, i, hprm, cs, sn)
        out[i] = fl_r - fl_l
        out[n + i] -= gb_l + ga_r
        fl_l = fl_r
        gb_l = gb_r
    if hi == n:
        out[n - 1] = -fl_l
        out[2 * n - 1] -= gb_l
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
    _sites_block(q, sprm, cs, sn, out, n, 0, n)
    if ha.shape[0] != n - 1 or _chain_hinges_ordered(q, ha, hb, hprm, cs, sn, out, n, 0, n) > 0:
        _chain_fallback(q, ha, hb, hprm, sprm, cs, sn, out, n)


@jit(parallel=True)
def chain_force_parallel(q, args, out):
    """``chain_force`` with the site loops split over numba's threads (worth it for N ≳ 1e5)."""
    ha, hb, hprm, sprm, cs, sn = args
    n = sprm.shape[0]
    for k in range(2 * n, out.shape[0]):
        out[k] = 0.0
    n_chunks = max(1, min(n // PARALLEL_BLOCK, 16))  # fixed blocks (not thread count): cacheable
    for c in prange(n_chunks):
        _sites_block(q, sprm, cs, sn, out, n, c * n // n_chunks, (c + 1) * n // n_chunks)
    bad = 0
    if ha.shape[0] == n - 1:
        for c in prange(n_chunks):
            bad += _chain_hinges_ordered(q, ha, hb, hprm, cs, sn, out, n, c * n // n_chunks,
                                         (c + 1) * n // n_chunks)
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
