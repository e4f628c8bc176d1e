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

from typing import NamedTuple

import numpy as np

from numba import types
from numba.extending import overload

from flexmm._jit import JIT_OPTIONS, NO_JIT, fma, jit, prange
from flexmm._trig import sincos

# Columns of the per-hinge parameter table.
H_REST, H_HALF_A, H_HALF_B, H_SIGN, H_KL, H_KS, H_KT = range(7)
N_HINGE_PARAMS = 7
# Columns of the per-site parameter table (chain).
S_THETA0, S_KG, S_KR = range(3)
N_SITE_PARAMS = 3
#: sites per block of the chain kernels' passes (their scratch, ~8 arrays of this length, stays
#: in L1/L2; the force does not depend on it)
BLOCK = 4096
#: sites per range of the threaded chain force at least (ranges are shared out among threads)
PARALLEL_BLOCK = 8192
#: rows of the block scratch of ``chain_block_hinges``
W_COS, W_SIN, W_FT, W_FL, W_GA, W_GB, W_C0, W_X, W_Y = range(9)
N_W = 9


@jit
def stretch(dl, rest, hA, cA, hB, cB):
    """Δl = d_l + r − (h_A cos φ_A + h_B cos φ_B), the hinge's stretch (φ = θ0 + θ). The one
    place this formula is written: the engine, the gradients and the energies call it."""
    return dl + rest - fma(hA, cA, hB * cB)


@jit
def skew(hA, sA, hB, sB):
    """x = h_B sin φ_B − h_A sin φ_A, the hinge's shear without d_s and σ: Δs = d_s + σ x."""
    return fma(hB, sB, -(hA * sA))


@jit
def stretch_variation(ddl, hA, sA, dta, hB, sB, dtb):
    """δ(Δl) = δd_l + h_A sin φ_A δφ_A + h_B sin φ_B δφ_B, the stretch's first variation."""
    return fma(hB * sB, dtb, fma(hA * sA, dta, ddl))


@jit
def skew_variation(hA, cA, dta, hB, cB, dtb):
    """δx = h_B cos φ_B δφ_B − h_A cos φ_A δφ_A, the unsigned shear's first variation."""
    return fma(hB * cB, dtb, -(hA * cA) * dta)


@jit
def hinge_law(dl, ds, tA, tB, cA, sA, cB, sB, prm):
    """Energy of one hinge and its derivatives.

    ``cA = cos(θ0_A+θ_A)``, ``sA = sin(θ0_A+θ_A)`` (same for B); ``prm`` is a row of the hinge
    table. Returns ``(E, ∂E/∂d_l, ∂E/∂d_s, ∂E/∂θ_A, ∂E/∂θ_B)``.
    """
    hA = prm[H_HALF_A]
    hB = prm[H_HALF_B]
    sig = prm[H_SIGN]
    el = stretch(dl, prm[H_REST], hA, cA, hB, cB)
    es = ds + sig * skew(hA, sA, hB, sB)
    ep = tA + tB
    fl = prm[H_KL] * el
    fs = prm[H_KS] * es
    fp = prm[H_KT] * ep
    energy = 0.5 * (fl * el + fs * es + fp * ep)
    gA, gB = hinge_torques(fl, fs * sig, fp, hA, hB, cA, sA, cB, sB)
    return energy, fl, fs, gA, gB


@jit
def hinge_torques(fl, w, fp, hA, hB, cA, sA, cB, sB):
    """(∂E/∂θ_A, ∂E/∂θ_B) of a hinge from k_l Δl (fl), σ k_s Δs (w) and k_θ Δφ (fp):
    fl h_A sin_A − w h_A cos_A + fp and fl h_B sin_B + w h_B cos_B + fp, as fused multiply-adds
    (``_jit.fma``), the same in every hinge law below."""
    return fma(fl * hA, sA, fma(-(w * hA), cA, fp)), fma(fl * hB, sB, fma(w * hB, cB, fp))


@jit
def hinge_products(fl, fs, pl, ps, hA, hB, ca, sa, cb, sb, lta, ltb):
    """The hinge's second-derivative products along λ, from f_l = k_l Δl, f_s = σ k_s Δs and their
    variations p_l = k_l δl, p_s = σ k_s δs: with X_A = p_l + f_s λ_A, Y_A = f_l λ_A − p_s,
    X_B = p_l − f_s λ_B, Y_B = f_l λ_B + p_s, returns (h_A (sin φ_A X_A + cos φ_A Y_A),
    h_B (sin φ_B X_B + cos φ_B Y_B), sin φ_A Y_A − cos φ_A X_A, sin φ_B Y_B − cos φ_B X_B): the
    derivatives of D = λ·∇E by θ0_A, θ0_B, h_A, h_B (``hinge_second``). Every adjoint loop of
    the gradients (general, column, uniform and grid forms) calls this one algebra."""
    xa = fma(fs, lta, pl)
    ya = fma(fl, lta, -ps)
    xb = fma(-fs, ltb, pl)
    yb = fma(fl, ltb, ps)
    return hA * fma(sa, xa, ca * ya), hB * fma(sb, xb, cb * yb), fma(sa, ya, -ca * xa), fma(sb, yb, -cb * xb)


@jit
def hinge_second(dlq, dsq, ep, dll, dsl, lta, ltb, rest, hA, hB, sig, kl, ks, kt, ca, sa, cb, sb):
    """One hinge's second derivatives along λ, from scalars (no arrays: it inlines into loops).

    dlq, dsq: the relative displacements of B and A along and across the hinge axis; ep = θ_A + θ_B;
    dll, dsl: the same differences of λ; lta, ltb: λ at θ_A, θ_B; then the hinge's parameters
    and cos/sin of φ = θ0 + θ at A and B. With the levers a_s = h_A sin φ_A, a_c = h_A cos φ_A
    (b_s, b_c at B), the stretch, shear and bend of ``models.hinge``

        el = d_l + r − (a_c + b_c),   es = d_s + σ (b_s − a_s),   ep = θ_A + θ_B,

    their variations along λ δl = λ_l + a_s λ_A + b_s λ_B, δs = λ_s + σ (b_c λ_B − a_c λ_A),
    δp = λ_A + λ_B, and D = λ·∇E = k_l el δl + k_s es δs + k_θ ep δp: with f_l = k_l el,
    f_s = σ k_s es, p_l = k_l δl, p_s = σ k_s δs and X_A = p_l + f_s λ_A, Y_A = f_l λ_A − p_s,
    X_B = p_l − f_s λ_B, Y_B = f_l λ_B + p_s,

        ∂D/∂θ0_A = a_s X_A + a_c Y_A,   ∂D/∂θ_A = ∂D/∂θ0_A + k_θ δp,   ∂D/∂h_A = sin φ_A Y_A − cos φ_A X_A

    (B likewise), ∂D/∂d_l = ∂D/∂r = p_l, ∂D/∂d_s = k_s δs, ∂D/∂k_l = el δl, ∂D/∂k_s = es δs,
    ∂D/∂k_θ = ep δp. Returns (p_l, k_s δs, ∂D/∂θ_A, ∂D/∂θ_B, ∂D/∂θ0_A, ∂D/∂θ0_B, ∂D/∂h_A,
    ∂D/∂h_B, ∂D/∂k_l, ∂D/∂k_s, ∂D/∂k_θ): the Hessian-vector and parameter products of the
    force are these negated.
    """
    el = stretch(dlq, rest, hA, ca, hB, cb)
    es = dsq + sig * skew(hA, sa, hB, sb)
    dl = stretch_variation(dll, hA, sa, lta, hB, sb, ltb)
    ds = dsl + sig * skew_variation(hA, ca, lta, hB, cb, ltb)
    dp = lta + ltb
    kdp = kt * dp
    pl = kl * dl
    pss = ks * ds
    t0a, t0b, gha, ghb = hinge_products(kl * el, sig * (ks * es), pl, sig * pss, hA, hB, ca, sa, cb, sb, lta, ltb)
    return pl, pss, t0a + kdp, t0b + kdp, t0a, t0b, gha, ghb, el * dl, es * ds, ep * dp


@jit
def hinge_tangent_terms(dlq, dsq, ep, ddl, dds, dta, dtb, dt0a, dt0b, rest, hA, hB, sig, kl, ks, kt, drest, dhA, dhB,
                        dkl, dks, dkt, ca, sa, cb, sb):
    """One hinge's tangent from scalars: the variations (d f_l, d f_s, d g_A, d g_B) of its
    (∂E/∂d_l, ∂E/∂d_s, ∂E/∂θ_A, ∂E/∂θ_B) along δq and δp (the force's tangent is their negation).

    dlq, dsq, ep as ``hinge_second``; ddl, dds: the differences of δq along and across the axis;
    dta, dtb: δθ_A, δθ_B; dt0a, dt0b: δθ0 of the units; drest … dkt: δ of the hinge's parameters.
    With δφ = δθ0 + δθ, ∂E/∂θ_A = f_l h_A sin φ_A − σ f_s h_A cos φ_A + f_p (f = k × strain;
    likewise B with + σ), differentiated factor by factor.
    """
    el = stretch(dlq, rest, hA, ca, hB, cb)
    es = dsq + sig * skew(hA, sa, hB, sb)
    dpa = dt0a + dta
    dpb = dt0b + dtb
    # the strains are linear in (d, r, h): their parameter variations are the strains of (δd, δr, δh)
    d_el = stretch_variation(stretch(ddl, drest, dhA, ca, dhB, cb), hA, sa, dpa, hB, sb, dpb)
    d_es = dds + sig * (skew(dhA, sa, dhB, sb) + skew_variation(hA, ca, dpa, hB, cb, dpb))
    d_fa = dhA * sa + hA * ca * dpa  # d(h_A sin φ_A)
    d_fb = dhB * sb + hB * cb * dpb
    d_ga = dhA * ca - hA * sa * dpa  # d(h_A cos φ_A)
    d_gb = dhB * cb - hB * sb * dpb
    d_fl = dkl * el + kl * d_el
    d_fs = dks * es + ks * d_es
    d_fp = dkt * ep + kt * (dta + dtb)
    fl, fs = kl * el, ks * es
    return (d_fl, d_fs, d_fl * hA * sa + fl * d_fa - sig * (d_fs * hA * ca + fs * d_ga) + d_fp,
            d_fl * hB * sb + fl * d_fb + sig * (d_fs * hB * cb + fs * d_gb) + d_fp)


@jit
def hinge_forces(dl, ds, tA, tB, cA, sA, cB, sB, rest, hA, hB, sig, kl, ks, kt):
    """``hinge_law``'s (∂E/∂d_l, ∂E/∂d_s, ∂E/∂θ_A, ∂E/∂θ_B) from scalar parameters (same
    operations: the same results), for loops that vectorise."""
    el = stretch(dl, rest, hA, cA, hB, cB)
    es = ds + sig * skew(hA, sA, hB, sB)
    fl = kl * el
    fs = ks * es
    gA, gB = hinge_torques(fl, fs * sig, kt * (tA + tB), hA, hB, cA, sA, cB, sB)
    return fl, fs, gA, gB


@jit
def chain_hinge_terms(du, ta, tb, ca, sa, cb, sb, rest, hA, hB, kl, ks, kt):
    """A chain hinge (no shear d_s): its stretch Δl, unsigned shear x = Δs/σ, k_l Δl, k_s x and
    (∂E/∂θ_A, ∂E/∂θ_B). ``du`` = u_B − u_A, ``ca, sa, cb, sb`` the cos/sin of θ0+θ at its two
    sites, then its law's parameters. The shear sign σ = ±1 drops out (σ k_s σ x = k_s x
    exactly), so these are ``hinge_law``'s results for d_s = 0, bit for bit. The design
    sweeps (design/kernels.py) call this too, so their forces have the same bits."""
    el = stretch(du, rest, hA, ca, hB, cb)
    x = skew(hA, sa, hB, sb)
    fl = kl * el
    xs = ks * x
    ga, gb = hinge_torques(fl, xs, kt * (ta + tb), hA, hB, ca, sa, cb, sb)
    return el, x, fl, xs, ga, gb


@jit
def chain_hinge(du, ta, tb, ca, sa, cb, sb, rest, hA, hB, kl, ks, kt):
    """(∂E/∂d_l, ∂E/∂θ_A, ∂E/∂θ_B) of a chain hinge (``chain_hinge_terms``)."""
    _, _, fl, _, ga, gb = chain_hinge_terms(du, ta, tb, ca, sa, cb, sb, rest, hA, hB, kl, ks, kt)
    return fl, ga, gb


def param(x, i):
    """Entry i of a parameter: ``x[i]`` of a column, ``x`` itself if uniform (a float), ``x[i & 1]``
    of a (even, odd) pair (the alternating shear sign of a uniform chain). In compiled code the
    type of ``x`` picks the access, so one loop serves uniform and graded chains."""
    if isinstance(x, tuple):
        return x[i & 1]
    if isinstance(x, float):
        return x
    return x[i]


if not NO_JIT:

    @overload(param, jit_options=JIT_OPTIONS)
    def _param(x, i):
        if isinstance(x, types.Float):
            return lambda x, i: x
        if isinstance(x, types.UniTuple):
            return lambda x, i: x[0] if (i & 1) == 0 else x[1]
        return lambda x, i: x[i]


# Block passes. Every argument is a view from the block's first site, so loops start at 0;
# each loop is simple and free of carried scalars, so it vectorises (``_trig.sincos`` is
# branch-free). Parameters (``param``) are column views of the row-wise tables (strided) in
# ``chain_force``; contiguous per-call columns, or scalars on a uniform block, in the fused
# Verlet (integrators/verlet_chain.py).


@jit
def chain_sites(qt, th0, kg, kr, c0, cs, sn, ft, m, with_kg):
    """cos/sin of θ0+θ into cs, sn and the lateral-hinge force on θ into ft (m sites).

    Without lateral stretch (``with_kg`` False: k_g = 0 on all m sites) only −k_r θ.
    """
    if with_kg:
        for i in range(m):
            s, c = sincos(param(th0, i) + qt[i])
            cs[i] = c
            sn[i] = s
            ft[i] = -(param(kg, i) * (param(c0, i) - c) * s + param(kr, i) * qt[i])
    else:
        for i in range(m):
            s, c = sincos(param(th0, i) + qt[i])
            cs[i] = c
            sn[i] = s
            ft[i] = -param(kr, i) * qt[i]


@jit
def chain_hinges(qu, qt, cs, sn, rest, ha, hb, kl, ks, kt, fl, ga, gb, m):
    """Hinges i ↔ i+1 for i < m − 1 into fl[i], ga[i], gb[i]."""
    for i in range(m - 1):
        fl[i], ga[i], gb[i] = chain_hinge(qu[i + 1] - qu[i], qt[i], qt[i + 1], cs[i], sn[i], cs[i + 1], sn[i + 1],
                                          param(rest, i), param(ha, i), param(hb, i), param(kl, i), param(ks, i),
                                          param(kt, i))


@jit
def chain_site_forces(fl, ga, gb, fu, ft, m):
    """Forces on m sites from their two hinges (fl[j], ga[j], gb[j]: hinge j−1 ↔ j; ft holds the
    on-site θ force and gets the hinges')."""
    for i in range(m):
        fu[i] = fl[i + 1] - fl[i]
        ft[i] = ft[i] - (gb[i] + ga[i + 1])


@jit
def chain_block_hinges(qu, qt, prm, w, m, right, ub, tb, th0_next, fl_left, gb_left, with_kg):
    """Site terms and hinges of m consecutive sites (views from the first site, as qu, qt).

    ``prm`` = (rest, hA, hB, σ, k_l, k_s, k_θ, θ0, k_g, k_r, cos θ0), each a column view from the
    first site (hinge columns from the hinge to its right) or uniform (``param``); ``w``
    (N_W, ≥ m + 1) scratch: gets cos/sin, the on-site θ force (row W_FT) and the hinges
    (rows W_FL, W_GA, W_GB; entry j: hinge j−1 ↔ j, entry 0 = (fl_left, ·, gb_left) the hinge
    to the left of the first site, entry m the right one: ``right``, a hinge joins the last
    site to a next site with old state (ub, tb) and rest angle th0_next, else zeros). Reads
    the state only on the m sites (and the given next site), so a caller may already have
    moved the sites before. Returns the right hinge's (fl, gb) for the next block.
    """
    rest, ha, hb, sig, kl, ks, kt, th0, kg, kr, c0 = prm
    cs, sn, ft, fl, ga, gb = w[W_COS], w[W_SIN], w[W_FT], w[W_FL], w[W_GA], w[W_GB]
    chain_sites(qt, th0, kg, kr, c0, cs, sn, ft, m, with_kg)
    chain_hinges(qu, qt, cs, sn, rest, ha, hb, kl, ks, kt, fl[1:], ga[1:], gb[1:], m)
    fl[0] = fl_left
    gb[0] = gb_left
    fr, gar, gbr = 0.0, 0.0, 0.0
    if right:
        j = m - 1
        sb, cb = sincos(th0_next + tb)
        fr, gar, gbr = chain_hinge(ub - qu[j], qt[j], tb, cs[j], sn[j], cb, sb, param(rest, j), param(ha, j),
                                   param(hb, j), param(kl, j), param(ks, j), param(kt, j))
    fl[m] = fr
    ga[m] = gar
    gb[m] = gbr
    return fr, gbr


@jit
def _chain_ordered(ha, hb, n):
    """Whether hinge h joins h and h + 1 for every h (the chain's own order)."""
    if ha.shape[0] != n - 1:
        return False
    bad = False
    for h in range(n - 1):
        bad |= (ha[h] != h) | (hb[h] != h + 1)
    return not bad


@jit
def _any_nonzero(x, m):
    nz = False
    for i in range(m):
        nz |= x[i] != 0.0
    return nz


@jit
def _left_hinge(q, hprm, sprm, n, i):
    """(fl, gb) of hinge i−1 ↔ i from q; zeros if i is 0 or n."""
    if i <= 0 or i >= n:
        return 0.0, 0.0
    h = i - 1
    sa, ca = sincos(sprm[h, S_THETA0] + q[n + h])
    sb, cb = sincos(sprm[i, S_THETA0] + q[n + i])
    fl, _, gb = chain_hinge(q[i] - q[h], q[n + h], q[n + i], ca, sa, cb, sb, hprm[h, H_REST], hprm[h, H_HALF_A],
                            hprm[h, H_HALF_B], hprm[h, H_KL], hprm[h, H_KS], hprm[h, H_KT])
    return fl, gb


@jit
def _block_columns(hprm, sprm, a, m, nh, cols, with_kg):
    """The parameters of sites a..a+m−1 as contiguous columns: cols rows 0–6 the hinge table's
    (nh hinges from a), 7–9 the site table's, 10 cos θ0 (if ``with_kg``): ``chain_block_hinges``'
    ``prm``. The loops read whole rows (interleaved loads, not gathers)."""
    hf, sf = hprm[a:].ravel(), sprm[a:].ravel()
    c0, c1, c2, c3, c4, c5, c6 = cols[0], cols[1], cols[2], cols[3], cols[4], cols[5], cols[6]
    for i in range(nh):
        c0[i] = hf[7 * i]
        c1[i] = hf[7 * i + 1]
        c2[i] = hf[7 * i + 2]
        c3[i] = hf[7 * i + 3]
        c4[i] = hf[7 * i + 4]
        c5[i] = hf[7 * i + 5]
        c6[i] = hf[7 * i + 6]
    d0, d1, d2, cz = cols[7], cols[8], cols[9], cols[10]
    for i in range(m):
        d0[i] = sf[3 * i]
        d1[i] = sf[3 * i + 1]
        d2[i] = sf[3 * i + 2]
    if with_kg:
        for i in range(m):
            _, cz[i] = sincos(d0[i])
    return (c0, c1, c2, c3, c4, c5, c6, d0, d1, d2, cz)


@jit
def _repeats(flat, period, n):
    """Whether flat[j] = flat[j − period] for period ≤ j < n (stops at the first chunk that differs)."""
    for a in range(period, n, 512):
        x, y = flat[a:], flat[a - period :]
        bad = False
        for j in range(min(512, n - a)):
            bad |= x[j] != y[j]
        if bad:
            return False
    return True


@jit
def _uniform_block(hprm, sprm, a, m, nh):
    """Whether the hinges and sites of a block all have the same parameters (but the shear sign,
    which may alternate): then ``chain_block_hinges`` gets them as scalars."""
    if nh < 2 or m < 2:
        return False
    for k in range(N_HINGE_PARAMS):
        if k != H_SIGN and hprm[a, k] != hprm[a + 1, k]:
            return False
    for k in range(N_SITE_PARAMS):
        if sprm[a, k] != sprm[a + 1, k]:
            return False
    return (_repeats(hprm[a:].ravel(), 2 * N_HINGE_PARAMS, nh * N_HINGE_PARAMS)
            and _repeats(sprm[a:].ravel(), N_SITE_PARAMS, m * N_SITE_PARAMS))


@jit
def _chain_range(q, hprm, sprm, out, n, lo, hi, w, cols):
    """All forces on sites lo..hi−1 of a chain-ordered chain, block by block (writes only there,
    so ranges can run on different threads). A uniform block reads its parameters as scalars,
    any other as contiguous copies (``_block_columns``)."""
    fl, gb = _left_hinge(q, hprm, sprm, n, lo)
    for a in range(lo, hi, BLOCK):
        b = min(a + BLOCK, hi)
        m = b - a
        nh = min(b, n - 1) - a
        k = min(b, n - 1)
        if _uniform_block(hprm, sprm, a, m, nh):
            _, c0 = sincos(sprm[a, S_THETA0])
            prm = (hprm[a, H_REST], hprm[a, H_HALF_A], hprm[a, H_HALF_B], (hprm[a, H_SIGN], hprm[a + 1, H_SIGN]),
                   hprm[a, H_KL], hprm[a, H_KS], hprm[a, H_KT], sprm[a, S_THETA0], sprm[a, S_KG], sprm[a, S_KR], c0)
            fl, gb = chain_block_hinges(q[a:n], q[n + a : 2 * n], prm, w, m, b < n, q[k], q[n + k],
                                        sprm[k, S_THETA0], fl, gb, sprm[a, S_KG] != 0.0)
        else:
            with_kg = _any_nonzero(sprm[a:, S_KG], m)
            fl, gb = chain_block_hinges(q[a:n], q[n + a : 2 * n], _block_columns(hprm, sprm, a, m, nh, cols, with_kg),
                                        w, m, b < n, q[k], q[n + k], sprm[k, S_THETA0], fl, gb, with_kg)
        ft = out[n + a : 2 * n]
        for i in range(m):
            ft[i] = w[W_FT, i]
        chain_site_forces(w[W_FL], w[W_GA], w[W_GB], out[a:n], ft, m)


@jit
def _chain_sites_all(q, sprm, cs, sn, out, n):
    """cos/sin of θ0+θ of every site into cs, sn; lateral-hinge forces on θ; zero u forces."""
    for i in range(n):
        s, c = sincos(sprm[i, S_THETA0] + q[n + i])
        _, c0 = sincos(sprm[i, S_THETA0])
        cs[i] = c
        sn[i] = s
        out[i] = 0.0
        out[n + i] = -(sprm[i, S_KG] * (c0 - c) * s + sprm[i, S_KR] * q[n + i])


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
    _chain_sites_all(q, sprm, cs, sn, out, n)
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
    ``rotating_chain.chain_tables`` builds them) take the vectorised block path
    (``chain_block_hinges``); any other hinge list the general scattered loop (same result).
    """
    ha, hb, hprm, sprm, cs, sn = args
    n = sprm.shape[0]
    for k in range(2 * n, out.shape[0]):
        out[k] = 0.0
    if _chain_ordered(ha, hb, n):
        nb = min(BLOCK, n) + 1  # short chains (called often) allocate no more than they need
        _chain_range(q, hprm, sprm, out, n, 0, n, np.empty((N_W, nb)), np.empty((11, nb)))
    else:
        _chain_fallback(q, ha, hb, hprm, sprm, cs, sn, out, n)


@jit(parallel=True)
def chain_force_parallel(q, args, out):
    """``chain_force`` with the blocks split over numba's threads (worth it for N ≳ 1e5)."""
    ha, hb, hprm, sprm, cs, sn = args
    n = sprm.shape[0]
    for k in range(2 * n, out.shape[0]):
        out[k] = 0.0
    if _chain_ordered(ha, hb, n):
        n_chunks = max(1, min(n // PARALLEL_BLOCK, 16))  # fixed ranges (not thread count): cacheable
        for c in prange(n_chunks):
            _chain_range(q, hprm, sprm, out, n, c * n // n_chunks, (c + 1) * n // n_chunks,
                         np.empty((N_W, BLOCK + 1)), np.empty((11, BLOCK + 1)))
    else:
        _chain_fallback(q, ha, hb, hprm, sprm, cs, sn, out, n)


@jit
def lane_sum(x, m):
    """Σ x[:m] in a fixed order that vectorises without reassociation (four interleaved partial
    sums, then (s0 + s1) + (s2 + s3)): bit-identical wherever it was compiled."""
    s0 = s1 = s2 = s3 = 0.0
    m4 = m - m % 4
    for i in range(0, m4, 4):
        s0 += x[i]
        s1 += x[i + 1]
        s2 += x[i + 2]
        s3 += x[i + 3]
    for i in range(m4, m):
        s0 += x[i]
    return (s0 + s1) + (s2 + s3)


@jit
def weighted_square_sum(w, x):
    """Σ w x² in a fixed order that vectorises (``lane_sum``'s four interleaved partial sums)."""
    s0 = s1 = s2 = s3 = 0.0
    n = x.shape[0]
    n4 = n - n % 4
    for i in range(0, n4, 4):
        s0 += w[i] * x[i] * x[i]
        s1 += w[i + 1] * x[i + 1] * x[i + 1]
        s2 += w[i + 2] * x[i + 2] * x[i + 2]
        s3 += w[i + 3] * x[i + 3] * x[i + 3]
    for i in range(n4, n):
        s0 += w[i] * x[i] * x[i]
    return (s0 + s1) + (s2 + s3)


@jit
def chain_energy(q, args):
    """Potential energy of the rotating-squares chain (same arguments as ``chain_force``).

    Chain-ordered hinges: per block, site and hinge energies into scratch, summed with
    ``lane_sum`` (vectorised; a fixed order, so the same result in every process).
    """
    ha, hb, hprm, sprm, cs, sn = args
    n = sprm.shape[0]
    total = 0.0
    if not _chain_ordered(ha, hb, n):
        for i in range(n):
            t = q[n + i]
            s, c = sincos(sprm[i, S_THETA0] + t)
            _, c0 = sincos(sprm[i, S_THETA0])
            cs[i] = c
            sn[i] = s
            g = c0 - c
            total += 0.5 * (sprm[i, S_KG] * g * g + sprm[i, S_KR] * t * t)
        for h in range(ha.shape[0]):
            a = ha[h]
            b = hb[h]
            e, _, _, _, _ = hinge_law(q[b] - q[a], 0.0, q[n + a], q[n + b], cs[a], sn[a], cs[b], sn[b], hprm[h])
            total += e
        return total
    w = np.empty((N_W, min(BLOCK, n) + 1))
    bc, bs, x, y = w[W_COS], w[W_SIN], w[W_X], w[W_Y]
    for a in range(0, n, BLOCK):
        b = min(a + BLOCK + 1, n)  # one site more: the hinge to the next block
        m = b - a
        qu, qt, th0, kg, kr = q[a:n], q[n + a : 2 * n], sprm[a:, S_THETA0], sprm[a:, S_KG], sprm[a:, S_KR]
        for i in range(m):
            s, c = sincos(th0[i] + qt[i])
            _, c0 = sincos(th0[i])
            bc[i] = c
            bs[i] = s
            g = c0 - c
            x[i] = 0.5 * (kg[i] * g * g + kr[i] * qt[i] * qt[i])
        ms = min(m, BLOCK)
        rest, hA, hB, sig = hprm[a:, H_REST], hprm[a:, H_HALF_A], hprm[a:, H_HALF_B], hprm[a:, H_SIGN]
        kl, ks, kt = hprm[a:, H_KL], hprm[a:, H_KS], hprm[a:, H_KT]
        for i in range(m - 1):
            el = stretch(qu[i + 1] - qu[i], rest[i], hA[i], bc[i], hB[i], bc[i + 1])
            es = sig[i] * skew(hA[i], bs[i], hB[i], bs[i + 1])
            ep = qt[i] + qt[i + 1]
            y[i] = 0.5 * (kl[i] * el * el + ks[i] * es * es + kt[i] * ep * ep)
        total += lane_sum(x, ms) + lane_sum(y, m - 1)
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
