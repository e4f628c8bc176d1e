"""Second derivatives of the model forces: the kernels the adjoint and tangent sweeps need.

For a model with energy E(q; p) and force F = −∂E/∂q, a reverse (adjoint) step needs, for an
adjoint vector λ, the Hessian-vector product and the parameter vector-Jacobian product

    (∂F/∂q)ᵀ λ = −∇²E λ,        (∂F/∂p)ᵀ λ = −∂(λ·∇E)/∂p,

and a forward (tangent) step needs (∂F/∂q) dq + (∂F/∂p) dp. Both are written per element
(hinge, bond, on-site term) from the element's closed-form law, so they cost about two force
evaluations. Parameters are the model's two tables (``param_tables``): for ``ChainArgs`` the
hinge table (H, 7) and the site table (N, 3) of ``models.hinge``; for ``SheetArgs`` the hinge
table and θ0 (N,) (with dipoles, joints or loads a longer vector: ``kernels_extra``, which also
describes the tables of loaded chains and harmonic oscillators); for ``MassArgs`` the bond and
on-site law rows (B, 9), (S, 9) of ``models.laws``; for ``NetworkArgs`` and ``TriangleArgs`` the
ligament and contact tables (``models.ligaments``, ``models.triangle_kernels``). Columns that are not continuous (the hinge
sign, a tabulated law's start and length) get zero derivatives.

``model_adjoint(q, args, lam, out, g1, g2)`` adds (∂F/∂q)ᵀλ to ``out`` and (∂F/∂p)ᵀλ to
(g1, g2); ``model_tangent(q, args, dq, d1, d2, out)`` writes (∂F/∂q)dq + (∂F/∂p)(d1, d2). Like
``models.kernels.model_force`` they are plain functions for Python and numba overloads that
dispatch on the type of ``args`` inside compiled loops (``ADJOINT_KERNELS``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
from numba.extending import overload

from flexmm._jit import JIT_OPTIONS, NO_JIT, fma, jit, runtime
from flexmm._trig import sincos
from flexmm.design.kernels_extra import (
    add_to_ends,
    dipoles_second,
    harmonic_adjoint,
    harmonic_pack,
    harmonic_tangent,
    harmonic_unpack,
    joints_adjoint,
    joints_tangent,
    loaded_chain_pack,
    loaded_chain_unpack,
    loads_adjoint,
    loads_tangent,
    sheet_offsets,
    sheet_pack,
    sheet_unpack,
    unit_angles,
)
from flexmm.models.laws import law_second
from flexmm.models.harmonic import HarmonicArgs
from flexmm.models.hinge import (
    H_HALF_A,
    H_HALF_B,
    H_KL,
    H_KS,
    H_KT,
    H_REST,
    H_SIGN,
    N_HINGE_PARAMS,
    S_KG,
    S_KR,
    S_THETA0,
    ChainArgs,
    chain_hinge_terms,
    hinge_products,
    hinge_second,
    hinge_tangent_terms,
    param,
    skew,
    skew_variation,
    stretch,
    stretch_variation,
)
from flexmm.models.ligaments import NetworkArgs, network_adjoint, network_pack, network_tangent, network_unpack
from flexmm.models.loads import LoadedChainArgs
from flexmm.models.mass_kernels import MassArgs
from flexmm.models.sheet_kernels import SheetArgs
from flexmm.models.triangle_kernels import TriangleArgs, triangle_adjoint, triangle_pack, triangle_tangent, triangle_unpack

# ---------------------------------------------------------------- rotating-squares chain


@jit
def _chain_trig(q, sprm, n, cs, sn):
    """cos and sin of every unit's angle θ0 + θ (vectorised ``_trig.sincos``)."""
    for i in range(n):
        s, c = sincos(sprm[i, S_THETA0] + q[n + i])
        cs[i] = c
        sn[i] = s


@jit
def _chain_site_terms(q, sprm, lam, out, g2, n, cs, sn):
    """Lateral-hinge on-site terms E = ½ k_g (cos θ0 − cos φ)² + ½ k_r θ², φ = θ0 + θ."""
    for i in range(n):
        th = q[n + i]
        t0 = sprm[i, S_THETA0]
        c, s = cs[i], sn[i]
        kg, kr = sprm[i, S_KG], sprm[i, S_KR]
        li = lam[n + i]
        g = math.cos(t0) - c
        out[n + i] -= (kg * (s * s + g * c) + kr) * li
        g2[i, S_KR] -= th * li
        g2[i, S_KG] -= g * s * li
        g2[i, S_THETA0] -= kg * ((s - math.sin(t0)) * s + g * c) * li


@jit
def hinge_row(hf, h):
    """(r, h_A, h_B, σ, k_l, k_s, k_θ) of hinge h from the hinge table flattened (``hprm.ravel()``)."""
    p = N_HINGE_PARAMS * h
    return hf[p + H_REST], hf[p + H_HALF_A], hf[p + H_HALF_B], hf[p + H_SIGN], hf[p + H_KL], hf[p + H_KS], hf[p + H_KT]


@jit
def add_hinge_grads(g1, h, fl_, g_ha, g_hb, g_kl, g_ks, g_kt):
    """Subtract ``hinge_second``'s parameter products from row h of the hinge table's gradient."""
    g1[h, H_REST] -= fl_
    g1[h, H_HALF_A] -= g_ha
    g1[h, H_HALF_B] -= g_hb
    g1[h, H_KL] -= g_kl
    g1[h, H_KS] -= g_ks
    g1[h, H_KT] -= g_kt


@jit
def hinge_adjoint(q, lam, out, g1, h, hprm, la, lb, sa_, sb_, ta, tb, ca, sa, cb, sb):
    """One hinge's share of ``chain_adjoint`` (``hinge_second`` on its DOFs); returns ∂D/∂θ0 of
    its two units. la, lb: the DOFs along the hinge axis; sa_, sb_: across it (−1: none, a
    chain); ta, tb: the rotations."""
    shear = sa_ >= 0
    dsq = q[sb_] - q[sa_] if shear else 0.0
    dsl = lam[sb_] - lam[sa_] if shear else 0.0
    fl_, fs_, d_ta, d_tb, d_t0a, d_t0b, g_ha, g_hb, g_kl, g_ks, g_kt = hinge_second(
        q[lb] - q[la], dsq, q[ta] + q[tb], lam[lb] - lam[la], dsl, lam[ta], lam[tb], hprm[h, H_REST],
        hprm[h, H_HALF_A], hprm[h, H_HALF_B], hprm[h, H_SIGN], hprm[h, H_KL], hprm[h, H_KS], hprm[h, H_KT], ca, sa, cb,
        sb)
    out[la] += fl_
    out[lb] -= fl_
    if shear:
        out[sa_] += fs_
        out[sb_] -= fs_
    out[ta] -= d_ta
    out[tb] -= d_tb
    add_hinge_grads(g1, h, fl_, g_ha, g_hb, g_kl, g_ks, g_kt)
    return d_t0a, d_t0b


@jit
def hinge_tangent(q, dq, d1, h, hprm, la, lb, sa_, sb_, ta, tb, ca, sa, cb, sb, dt0a, dt0b, out):
    """One hinge's share of the tangent (∂F/∂q) dq + (∂F/∂p) dp, added to ``out`` (DOFs as in
    ``hinge_adjoint``; dt0a, dt0b: the directions of the units' θ0)."""
    shear = sa_ >= 0
    dsq = q[sb_] - q[sa_] if shear else 0.0
    dds = dq[sb_] - dq[sa_] if shear else 0.0
    d_fl, d_fs, d_ga, d_gb = hinge_tangent_terms(
        q[lb] - q[la], dsq, q[ta] + q[tb], dq[lb] - dq[la], dds, dq[ta], dq[tb], dt0a, dt0b, hprm[h, H_REST],
        hprm[h, H_HALF_A], hprm[h, H_HALF_B], hprm[h, H_SIGN], hprm[h, H_KL], hprm[h, H_KS], hprm[h, H_KT],
        d1[h, H_REST], d1[h, H_HALF_A], d1[h, H_HALF_B], d1[h, H_KL], d1[h, H_KS], d1[h, H_KT], ca, sa, cb, sb)
    out[la] += d_fl
    out[lb] -= d_fl
    if shear:
        out[sa_] += d_fs
        out[sb_] -= d_fs
    out[ta] -= d_ga
    out[tb] -= d_gb


@jit
def chain_adjoint(q, args, lam, out, g1, g2):
    """(∂F/∂q)ᵀλ added to ``out``, (∂F/∂p)ᵀλ to g1 (hinge table), g2 (site table)."""
    ha, hb, hprm, sprm, _, _ = args
    n = sprm.shape[0]
    cs = np.empty(n)
    sn = np.empty(n)
    _chain_trig(q, sprm, n, cs, sn)
    _chain_site_terms(q, sprm, lam, out, g2, n, cs, sn)
    for h in range(ha.shape[0]):
        a = ha[h]
        b = hb[h]
        ga, gb = hinge_adjoint(q, lam, out, g1, h, hprm, a, b, -1, -1, n + a, n + b, cs[a], sn[a], cs[b], sn[b])
        g2[a, S_THETA0] -= ga
        g2[b, S_THETA0] -= gb


@jit
def chain_tangent(q, args, dq, d1, d2, out):
    """(∂F/∂q) dq + (∂F/∂p)(d1, d2) into ``out`` (d1: hinge-table, d2: site-table directions)."""
    ha, hb, hprm, sprm, _, _ = args
    n = sprm.shape[0]
    for k in range(out.shape[0]):
        out[k] = 0.0
    cs = np.empty(n)
    sn = np.empty(n)
    _chain_trig(q, sprm, n, cs, sn)
    for i in range(n):
        th = q[n + i]
        t0 = sprm[i, S_THETA0]
        c, s = cs[i], sn[i]
        g = math.cos(t0) - c
        kg = sprm[i, S_KG]
        dt0 = d2[i, S_THETA0]
        dphi = dt0 + dq[n + i]
        # g_θ = k_g g sin φ + k_r θ
        dgrad = (d2[i, S_KG] * g * s + kg * ((s - math.sin(t0)) * dt0 * s + s * s * dq[n + i] + g * c * dphi)
                 + d2[i, S_KR] * th + sprm[i, S_KR] * dq[n + i])
        out[n + i] = -dgrad
    for h in range(ha.shape[0]):
        a = ha[h]
        b = hb[h]
        hinge_tangent(q, dq, d1, h, hprm, a, b, -1, -1, n + a, n + b, cs[a], sn[a], cs[b], sn[b],
                      d2[a, S_THETA0], d2[b, S_THETA0], out)


# ---------------------------------------------------------------- chain-ordered chains, column form
#
# The sweeps of a chain whose hinge h joins units h and h + 1 (``chain_ordered``) run on
# contiguous parameter columns (``chain_columns``) with short loops over sites and hinges that
# vectorise (``_trig.sincos``; per-hinge results go to padded rows, entry h + 1 for hinge h, so
# each site gathers its two hinges without scattered writes; a loop touching many arrays does
# not vectorise, hence several passes). The force has the arithmetic of ``hinge.chain_force``
# (the same bits). The reverse step at a state takes the force there again, then the
# Hessian-vector product and the parameter products, and accumulates parameter adjoints per
# element in columns (``CA_*``), added to the tables once per gradient.

#: rows of ``chain_columns``: hinge h (joins h, h + 1) at entry h, sites at entry i
(CC_REST, CC_HA, CC_HB, CC_SIG, CC_KL, CC_KS, CC_KT, CC_TH0, CC_KG, CC_KR, CC_C0, CC_S0) = range(12)
N_CC = 12
#: rows of the parameter-adjoint accumulator of the column sweeps (hinge columns, then site columns)
(CA_REST, CA_HA, CA_HB, CA_KL, CA_KS, CA_KT, CA_TH0, CA_KG, CA_KR) = range(9)
N_CA = 9
#: rows of the reverse step's scratch (padded rows: entry h + 1 for hinge h, 0 and n zero)
(R_COS, R_SIN, R_FT, R_FL, R_GA, R_GB, R_EL, R_ES, R_XU, R_TA, R_TB, R_KD, R_DL, R_DS, R_DP) = range(15)
N_R = 15


def chain_ordered(args, ndof: int) -> bool:
    """Whether a model's args are a chain with hinge h joining units h, h + 1 and 2N DOFs."""
    if not isinstance(args, ChainArgs):
        return False
    n = args.site_prm.shape[0]
    idx = np.arange(n - 1)
    return (n >= 2 and ndof == 2 * n and np.array_equal(args.hinge_a, idx)
            and np.array_equal(args.hinge_b, idx + 1))


@jit
def chain_columns(hprm, sprm):
    """The (N_CC, n) parameter columns of a chain-ordered chain (hinge columns: last entry 0)."""
    n = sprm.shape[0]
    cols = np.zeros((N_CC, n))
    hcols = (H_REST, H_HALF_A, H_HALF_B, H_SIGN, H_KL, H_KS, H_KT)
    for h in range(n - 1):
        for c in range(7):
            cols[c, h] = hprm[h, hcols[c]]
    for i in range(n):
        cols[CC_TH0, i] = sprm[i, S_THETA0]
        cols[CC_KG, i] = sprm[i, S_KG]
        cols[CC_KR, i] = sprm[i, S_KR]
        s0, c0 = sincos(sprm[i, S_THETA0])  # as hinge.chain_force
        cols[CC_C0, i] = c0
        cols[CC_S0, i] = s0
    return cols


@jit
def chain_add_columns(acc, g1, g2):
    """Add the column accumulator ``acc`` (N_CA, n) to the table gradients g1 (H, 7), g2 (n, 3)."""
    hcols = (H_REST, H_HALF_A, H_HALF_B, H_KL, H_KS, H_KT)
    for h in range(g1.shape[0]):
        for c in range(6):
            g1[h, hcols[c]] += acc[c, h]
    for i in range(g2.shape[0]):
        g2[i, S_THETA0] += acc[CA_TH0, i]
        g2[i, S_KG] += acc[CA_KG, i]
        g2[i, S_KR] += acc[CA_KR, i]


@jit
def chain_force_columns(q, cols, with_kg, r, f):
    """The model force F(q) of a chain-ordered chain from its columns into f (2n): the
    operations of ``hinge.chain_force`` (``chain_sites``, ``chain_hinge``), so the same bits.
    Leaves in the scratch r (N_R, n + 1) cos/sin of θ0+θ (rows R_COS, R_SIN), the hinges' forces
    (R_FL, R_GA, R_GB) and their stretch and shear (R_EL, R_ES) for ``chain_reverse_hessian``."""
    n = cols.shape[1]
    qu, qt = q[:n], q[n:]
    th0, kg, kr, c0 = cols[CC_TH0], cols[CC_KG], cols[CC_KR], cols[CC_C0]
    cs, sn, ft = r[R_COS], r[R_SIN], r[R_FT]
    if with_kg:
        for i in range(n):
            s, c = sincos(th0[i] + qt[i])
            cs[i] = c
            sn[i] = s
            ft[i] = -(kg[i] * (c0[i] - c) * s + kr[i] * qt[i])
    else:
        for i in range(n):
            s, c = sincos(th0[i] + qt[i])
            cs[i] = c
            sn[i] = s
            ft[i] = -kr[i] * qt[i]
    rest, ha, hb, sig = cols[CC_REST], cols[CC_HA], cols[CC_HB], cols[CC_SIG]
    kl, ks, kt = cols[CC_KL], cols[CC_KS], cols[CC_KT]
    fl, ga, gb, el_, es_ = r[R_FL, 1:], r[R_GA, 1:], r[R_GB, 1:], r[R_EL, 1:], r[R_ES, 1:]
    for h in range(n - 1):
        el, x, fl[h], _, ga[h], gb[h] = chain_hinge_terms(qu[h + 1] - qu[h], qt[h], qt[h + 1], cs[h], sn[h], cs[h + 1],
                                                          sn[h + 1], rest[h], ha[h], hb[h], kl[h], ks[h], kt[h])
        el_[h] = el
        es_[h] = sig[h] * x
    for row in (R_FL, R_GA, R_GB):
        r[row, 0] = 0.0
        r[row, n] = 0.0
    fl, ga, gb = r[R_FL], r[R_GA], r[R_GB]
    for i in range(n):
        f[i] = fl[i + 1] - fl[i]
        f[n + i] = ft[i] - (gb[i] + ga[i + 1])


@jit
def chain_strains(q, cols, r):
    """cos/sin of θ0+θ (rows R_COS, R_SIN) and the hinges' stretch and shear (R_EL, R_ES) at q:
    what ``chain_reverse_hessian`` reads, without the force (``chain_force_columns``)."""
    n = cols.shape[1]
    qu, qt = q[:n], q[n:]
    th0, rest, ha, hb, sig = cols[CC_TH0], cols[CC_REST], cols[CC_HA], cols[CC_HB], cols[CC_SIG]
    cs, sn, el_, es_ = r[R_COS], r[R_SIN], r[R_EL, 1:], r[R_ES, 1:]
    for i in range(n):
        s, c = sincos(th0[i] + qt[i])
        cs[i] = c
        sn[i] = s
    for h in range(n - 1):  # as chain_force_columns (its force unused)
        el_[h], x, _, _, _, _ = chain_hinge_terms(qu[h + 1] - qu[h], qt[h], qt[h + 1], cs[h], sn[h], cs[h + 1],
                                                  sn[h + 1], rest[h], ha[h], hb[h], 0.0, 0.0, 0.0)
        es_[h] = sig[h] * x


@jit
def chain_reverse_hessian(q, cols, lam, r, acc):
    """Hinge part of (∂F/∂q)ᵀλ and (∂F/∂p)ᵀλ at the state of ``chain_strains`` (its rows in r): per hinge into the padded rows R_XU, R_TA, R_TB, R_KD (gathered by
    ``chain_reverse_gather``), hinge-parameter adjoints into acc (``hinge_adjoint``'s algebra).
    Three short loops (the variations of the strains along λ; the products; the parameter
    adjoints): a loop touching many arrays does not vectorise."""
    n = cols.shape[1]
    qt = q[n:]
    lu, lt = lam[:n], lam[n:]
    cs, sn, el_, es_ = r[R_COS], r[R_SIN], r[R_EL, 1:], r[R_ES, 1:]
    ha, hb, sig, kl, ks, kt = cols[CC_HA], cols[CC_HB], cols[CC_SIG], cols[CC_KL], cols[CC_KS], cols[CC_KT]
    dl_, ds_, dp_ = r[R_DL], r[R_DS], r[R_DP]
    for h in range(n - 1):
        hA, hB, lta, ltb = ha[h], hb[h], lt[h], lt[h + 1]
        dl_[h] = stretch_variation(lu[h + 1] - lu[h], hA, sn[h], lta, hB, sn[h + 1], ltb)
        ds_[h] = sig[h] * skew_variation(hA, cs[h], lta, hB, cs[h + 1], ltb)
        dp_[h] = lta + ltb
    xu, ta_, tb_, kd = r[R_XU, 1:], r[R_TA, 1:], r[R_TB, 1:], r[R_KD, 1:]
    for h in range(n - 1):
        hA, hB, sg, k_l, k_s = ha[h], hb[h], sig[h], kl[h], ks[h]
        ca, sa, cb, sb = cs[h], sn[h], cs[h + 1], sn[h + 1]
        el, es, dl, ds = el_[h], es_[h], dl_[h], ds_[h]
        lta, ltb = lt[h], lt[h + 1]
        xu[h] = k_l * dl
        ta_[h], tb_[h], _, _ = hinge_products(k_l * el, sg * (k_s * es), k_l * dl, sg * (k_s * ds), hA, hB, ca, sa, cb,
                                              sb, lta, ltb)
        kd[h] = kt[h] * dp_[h]
    a_rest, a_ha, a_hb, a_kl, a_ks, a_kt = acc[CA_REST], acc[CA_HA], acc[CA_HB], acc[CA_KL], acc[CA_KS], acc[CA_KT]
    for h in range(n - 1):
        sg, k_l, k_s = sig[h], kl[h], ks[h]
        ca, sa, cb, sb = cs[h], sn[h], cs[h + 1], sn[h + 1]
        el, es, dl, ds = el_[h], es_[h], dl_[h], ds_[h]
        lta, ltb = lt[h], lt[h + 1]
        _, _, gha, ghb = hinge_products(k_l * el, sg * (k_s * es), k_l * dl, sg * (k_s * ds), ha[h], hb[h], ca, sa, cb,
                                        sb, lta, ltb)
        a_rest[h] -= k_l * dl
        a_ha[h] -= gha
        a_hb[h] -= ghb
        a_kl[h] -= el * dl
        a_ks[h] -= es * ds
        a_kt[h] -= (qt[h] + qt[h + 1]) * dp_[h]
    for row in (R_XU, R_TA, R_TB, R_KD):
        r[row, 0] = 0.0
        r[row, n] = 0.0


@jit
def chain_reverse_gather(q, cols, lam, r, acc, out):
    """Add each site's two hinges' and its on-site term's share of (∂F/∂q)ᵀλ to ``out`` and the
    site-parameter adjoints (θ0, k_g, k_r) to acc (two loops, so that both vectorise)."""
    n = cols.shape[1]
    qt = q[n:]
    lt = lam[n:]
    kg, kr, c0, s0 = cols[CC_KG], cols[CC_KR], cols[CC_C0], cols[CC_S0]
    cs, sn, xu, ta_, tb_, kd = r[R_COS], r[R_SIN], r[R_XU], r[R_TA], r[R_TB], r[R_KD]
    ou, ot = out[:n], out[n:]
    for i in range(n):
        c, s = cs[i], sn[i]
        ou[i] += xu[i + 1] - xu[i]
        ot[i] -= (tb_[i] + ta_[i + 1]) + (kd[i] + kd[i + 1]) + (kg[i] * (s * s + (c0[i] - c) * c) + kr[i]) * lt[i]
    a_th0, a_kg, a_kr = acc[CA_TH0], acc[CA_KG], acc[CA_KR]
    for i in range(n):
        c, s, lti = cs[i], sn[i], lt[i]
        g = c0[i] - c
        a_th0[i] -= (tb_[i] + ta_[i + 1]) + kg[i] * ((s - s0[i]) * s + g * c) * lti
        a_kg[i] -= g * s * lti
        a_kr[i] -= qt[i] * lti


# ---------------------------------------------------------------- uniform chains, fused reverse
#
# A chain-ordered chain whose hinges all have the same law (the shear sign ±1 aside: on a chain
# it drops out, σ·σ = 1 exactly, so the force has the same bits) and whose sites all have the
# same θ0, k_g, k_r: the reverse step with these as scalars (``chain_uniform``), in the style of
# the engine's fused kernel (integrators/verlet_chain.py), in four passes per step (sites'
# cos/sin; integrator factors; every hinge's force, Hessian and parameter products at once;
# every site's) instead of a dozen, with the products regrouped to fewer operations. The hinge
# and site parameter adjoints stay per element (a design varies them). The integrator factors
# K, P, S are scalars per field (u, θ) or per-DOF columns (``param``: one source, two
# variants). The fused passes touch ~15 arrays each: they vectorise only with the vectoriser's
# limit on run-time overlap checks raised (``_jit.VECTORIZE_MEMORY_CHECKS``); at LLVM's
# default they run scalar, slower than the column sweeps.

#: entries of ``chain_uniform``'s parameter vector
(U_REST, U_HA, U_HB, U_KL, U_KS, U_KT, U_TH0, U_KG, U_KR, U_C0, U_S0) = range(11)
N_U = 11
#: rows of the uniform chain's scratch (n + 1 entries; padded rows: hinge h at entry h + 1,
#: entries 0 and n zero): cos/sin, the force's hinge rows (replay), the reverse's hinge rows
(V_COS, V_SIN, V_FL, V_GA, V_GB, V_PL, V_TA, V_TB, V_KD) = range(9)
N_V = 9


def chain_uniform(cols: np.ndarray) -> np.ndarray | None:
    """The parameters (N_U,) of a chain whose columns (``chain_columns``) are uniform — every
    hinge the same rest length, half sizes and stiffnesses with a sign of ±1, every site the
    same θ0, k_g, k_r — or None."""
    n = cols.shape[1]
    hinge = cols[[CC_REST, CC_HA, CC_HB, CC_KL, CC_KS, CC_KT], : n - 1]
    site = cols[[CC_TH0, CC_KG, CC_KR, CC_C0, CC_S0]]
    if not (np.all(hinge == hinge[:, :1]) and np.all(site == site[:, :1])
            and np.all(np.abs(cols[CC_SIG, : n - 1]) == 1.0)):
        return None
    return np.concatenate([hinge[:, 0], site[:, 0]])


@jit
def _uniform_hinge_force(ua, ub, qa, qb, ca, sa, cb, sb, rest, hA, hB, kl, ks, kt):
    """A uniform hinge's stretch el, unsigned shear x, k_l el, k_s x and its (f_l, g_A, g_B) as
    ``chain_force_columns`` (the same bits: k_s σ x σ = k_s x exactly)."""
    return chain_hinge_terms(ub - ua, qa, qb, ca, sa, cb, sb, rest, hA, hB, kl, ks, kt)


@jit
def chain_uniform_force(q, u, with_kg, cs, sn, r, f):
    """``chain_force_columns`` of a uniform chain (``chain_uniform``'s parameters u): the same bits;
    cos/sin of θ0+θ into cs, sn (kept by the replay for the reverse step), the hinges' forces
    left in the scratch r (N_V, n + 1)."""
    n = r.shape[1] - 1
    rest, hA, hB, kl, ks, kt = u[U_REST], u[U_HA], u[U_HB], u[U_KL], u[U_KS], u[U_KT]
    kg, kr, c0 = u[U_KG], u[U_KR], u[U_C0]
    qu, qt = q[:n], q[n:]
    chain_uniform_sites(qt, u[U_TH0], cs, sn)
    fl, ga, gb = r[V_FL, 1:], r[V_GA, 1:], r[V_GB, 1:]
    for h in range(n - 1):
        _, _, fl[h], _, ga[h], gb[h] = _uniform_hinge_force(qu[h], qu[h + 1], qt[h], qt[h + 1], cs[h], sn[h],
                                                            cs[h + 1], sn[h + 1], rest, hA, hB, kl, ks, kt)
    for row in (V_FL, V_GA, V_GB):
        r[row, 0] = 0.0
        r[row, n] = 0.0
    fl, ga, gb = r[V_FL], r[V_GA], r[V_GB]
    if with_kg:
        for i in range(n):
            f[i] = fl[i + 1] - fl[i]
            f[n + i] = -(kg * (c0 - cs[i]) * sn[i] + kr * qt[i]) - (gb[i] + ga[i + 1])
    else:
        for i in range(n):
            f[i] = fl[i + 1] - fl[i]
            f[n + i] = -kr * qt[i] - (gb[i] + ga[i + 1])


@jit
def chain_uniform_sites(qt, th0, cs, sn):
    """cos/sin of θ0 + θ at every site into cs, sn."""
    for i in range(qt.shape[0]):
        s, c = sincos(th0 + qt[i])
        cs[i] = c
        sn[i] = s


@jit
def chain_uniform_hinges(q, lf, cs, sn, r, acc, u):
    """Every hinge of a uniform chain at the state q, in one pass: along λf its share of
    −∇²E λ (rows V_PL: k_l δl, V_TA, V_TB: at its two rotations without k_θ, V_KD: k_θ δφ) and
    its parameters' adjoints into acc (``chain_reverse_hessian``'s algebra, σ dropped and the
    products regrouped), from its stretch and shear as ``chain_force_columns`` takes them."""
    n = r.shape[1] - 1
    rest, hA, hB, kl, ks, kt = u[U_REST], u[U_HA], u[U_HB], u[U_KL], u[U_KS], u[U_KT]
    qu, qt, lu, lt = q[:n], q[n:], lf[:n], lf[n:]
    pl, ta, tb, kd = r[V_PL, 1:], r[V_TA, 1:], r[V_TB, 1:], r[V_KD, 1:]
    a_rest, a_ha, a_hb, a_kl, a_ks, a_kt = acc[CA_REST], acc[CA_HA], acc[CA_HB], acc[CA_KL], acc[CA_KS], acc[CA_KT]
    for h in range(n - 1):
        ca, sa, cb, sb = cs[h], sn[h], cs[h + 1], sn[h + 1]
        qa, qb, lta, ltb = qt[h], qt[h + 1], lt[h], lt[h + 1]
        el, x, e, xs, _, _ = _uniform_hinge_force(qu[h], qu[h + 1], qa, qb, ca, sa, cb, sb, rest, hA, hB, kl, ks,
                                                  kt)
        dl = stretch_variation(lu[h + 1] - lu[h], hA, sa, lta, hB, sb, ltb)
        d = skew_variation(hA, ca, lta, hB, cb, ltb)  # of the unsigned shear: σ drops out
        p = kl * dl
        dp = lta + ltb
        pl[h] = p
        ta[h], tb[h], gha, ghb = hinge_products(e, xs, p, ks * d, hA, hB, ca, sa, cb, sb, lta, ltb)
        kd[h] = kt * dp
        a_rest[h] -= p
        a_ha[h] -= gha
        a_hb[h] -= ghb
        a_kl[h] = fma(-el, dl, a_kl[h])
        a_ks[h] = fma(-x, d, a_ks[h])
        a_kt[h] = fma(-(qa + qb), dp, a_kt[h])
    for row in (V_PL, V_TA, V_TB, V_KD):
        r[row, 0] = 0.0
        r[row, n] = 0.0


@jit
def chain_uniform_gather(q, lf, lq, cs, sn, r, acc, u):
    """Every site of a uniform chain, in one pass: its two hinges' and its on-site term's share
    of (∂F/∂q)ᵀλf added to λq, its parameters' adjoints (θ0, k_g, k_r) into acc."""
    n = r.shape[1] - 1
    kg, kr, c0, s0 = u[U_KG], u[U_KR], u[U_C0], u[U_S0]
    qt, lt = q[n:], lf[n:]
    pl, ta, tb, kd = r[V_PL], r[V_TA], r[V_TB], r[V_KD]
    ou, ot = lq[:n], lq[n:]
    a_th0, a_kg, a_kr = acc[CA_TH0], acc[CA_KG], acc[CA_KR]
    for i in range(n):
        c, s, qi, li = cs[i], sn[i], qt[i], lt[i]
        g = c0 - c
        ou[i] += pl[i + 1] - pl[i]
        t = tb[i] + ta[i + 1]
        ot[i] -= fma(fma(kg, fma(s, s, g * c), kr), li, t + (kd[i] + kd[i + 1]))
        a_th0[i] -= fma(kg * fma(s - s0, s, g * c), li, t)
        a_kg[i] = fma(-g * s, li, a_kg[i])
        a_kr[i] = fma(-qi, li, a_kr[i])


# ---------------------------------------------------------------- 2D sheet


@jit
def _sheet_dofs(ha, hb, hax, n, h):
    """Sheet hinge h's units a, b and DOFs: along its axis la, lb, across sa, sb, rotations ta,
    tb — unsigned, so indexing with them skips numba's negative-index wraparound."""
    a, b = ha[h], hb[h]
    if hax[h] == 0:
        la, lb, sa, sb = a, b, n + a, n + b
    else:
        la, lb, sa, sb = n + a, n + b, a, b
    u = np.uint64
    return u(a), u(b), u(la), u(lb), u(sa), u(sb), u(2 * n + a), u(2 * n + b)


@jit
def sheet_adjoint(q, args, lam, out, g1, g2):
    """(∂F/∂q)ᵀλ added to ``out``, (∂F/∂p)ᵀλ to g1 (hinge table) and g2 (θ0 per unit).

    Hinges only (θ0 at g2[:N]); with dipoles, joints and loads: ``sheet_full_adjoint``.
    One loop over the hinges, each ``hinge_second`` on scalars (DOF indices unsigned: no
    negative-index wraparound on the dozen gathers and scatters of a hinge).
    """
    ha, hb, hax, hprm, theta0 = args[0], args[1], args[2], args[3], args[4]
    n = theta0.shape[0]
    cs = np.empty(n)
    sn = np.empty(n)
    unit_angles(q, theta0, cs, sn)
    hf = hprm.ravel()
    for h in range(ha.shape[0]):
        a, b, la, lb, sa, sb, ta, tb = _sheet_dofs(ha, hb, hax, n, h)
        rest, hA, hB, sig, kl, ks, kt = hinge_row(hf, h)
        pl, pss, d_ta, d_tb, d_t0a, d_t0b, g_ha, g_hb, g_kl, g_ks, g_kt = hinge_second(
            q[lb] - q[la], q[sb] - q[sa], q[ta] + q[tb], lam[lb] - lam[la], lam[sb] - lam[sa], lam[ta], lam[tb],
            rest, hA, hB, sig, kl, ks, kt, cs[a], sn[a], cs[b], sn[b])
        add_to_ends(out, out, out, la, lb, sa, sb, ta, tb, pl, pss, d_ta, d_tb)
        add_hinge_grads(g1, h, pl, g_ha, g_hb, g_kl, g_ks, g_kt)
        g2[a] -= d_t0a
        g2[b] -= d_t0b


# The hinges of a rectangular grid (``sheet_kernels.grid_layout``: no wraps) in column form:
# the x hinges as one family over sites s = 0..n−2 joining s, s + 1 (the n_cols − 1 … pairs that
# cross a row end get zero parameters: exact zeros), the y hinges as one over s = 0..n−n_cols−1
# joining s, s + n_cols. Each family runs the passes of the chain's (strains; their variations
# along λ; products; parameter adjoints; adding to the two ends), contiguous, so they vectorise.

#: rows of a family's scratch
(F_EL, F_ES, F_DL, F_DS, F_DP, F_XL, F_XS, F_TA, F_TB, F_KD) = range(10)
N_F = 10
#: hinge-parameter columns of a family (table columns except the sign, which is discrete), in order
FAMILY_COLS = (H_REST, H_HALF_A, H_HALF_B, H_KL, H_KS, H_KT)


def sheet_grid(args, ndof: int) -> tuple[int, int] | None:
    """(n_cols, first y hinge) if the sheet's hinges are a grid without wraps and 3N DOFs and it
    has no other terms, else None."""
    from flexmm.models.sheet_kernels import grid_layout

    if not isinstance(args, SheetArgs) or args.dipoles[0].shape[0] or args.joints[0].shape[0] or args.loads[0].shape[0]:
        return None  # dipoles, joints and loads: ``sheet_full_adjoint``
    n = args.theta0.shape[0]
    nc, x1, y0, y1 = grid_layout(args.hinge_a, args.hinge_b, args.hinge_axis, n)
    if nc == 0 or ndof != 3 * n or x1 != y0 or y1 != args.hinge_a.shape[0] or n // nc < 2:
        return None
    return int(nc), int(y0)


@jit
def sheet_grid_columns(hprm, n, nc, y0):
    """Parameter columns (7, n − 1) of the x family and (7, n − nc) of the y family."""
    xc = np.zeros((7, n - 1))
    yc = np.zeros((7, n - nc))
    for s in range(n - 1):
        c = s % nc
        if c < nc - 1:
            h = (s // nc) * (nc - 1) + c
            for k in range(7):
                xc[k, s] = hprm[h, k]
    for s in range(n - nc):
        for k in range(7):
            yc[k, s] = hprm[y0 + s, k]
    return xc, yc


@jit
def sheet_grid_add(acc_x, acc_y, acc_t0, g1, g2, nc, y0):
    """Add the family accumulators (6 rows, ``FAMILY_COLS``) and θ0's to the table gradients."""
    n = g2.shape[0]
    for s in range(n - 1):
        c = s % nc
        if c < nc - 1:
            h = (s // nc) * (nc - 1) + c
            for k in range(6):
                g1[h, FAMILY_COLS[k]] += acc_x[k, s]
    for s in range(n - nc):
        for k in range(6):
            g1[y0 + s, FAMILY_COLS[k]] += acc_y[k, s]
    for i in range(n):
        g2[i] += acc_t0[i]


@jit
def _family(q, lam, cs, sn, pc, off, la0, sa0, n, m, r, acc, out, acc_t0):
    """One family of hinges k < m joining sites k and k + off: along-axis DOFs from la0, across
    from sa0 (0 or n), rotations from 2n; (∂F/∂q)ᵀλ added to ``out``, parameter adjoints to
    ``acc`` (6, m) and ``acc_t0`` (n). Many short loops: one that touches more arrays does not
    vectorise (benchmarks/run.py gradient)."""
    qla, qlb, qsa, qsb = q[la0:], q[la0 + off :], q[sa0:], q[sa0 + off :]
    qta, qtb = q[2 * n :], q[2 * n + off :]
    lla, llb, lsa, lsb = lam[la0:], lam[la0 + off :], lam[sa0:], lam[sa0 + off :]
    lta, ltb = lam[2 * n :], lam[2 * n + off :]
    ca, sa, cb, sb = cs, sn, cs[off:], sn[off:]
    rest, ha, hb, sig, kl, ks, kt = pc[H_REST], pc[H_HALF_A], pc[H_HALF_B], pc[H_SIGN], pc[H_KL], pc[H_KS], pc[H_KT]
    el_, es_, dl_, ds_, dp_ = r[F_EL], r[F_ES], r[F_DL], r[F_DS], r[F_DP]
    for k in range(m):
        el_[k] = stretch(qlb[k] - qla[k], rest[k], ha[k], ca[k], hb[k], cb[k])
        es_[k] = (qsb[k] - qsa[k]) + sig[k] * skew(ha[k], sa[k], hb[k], sb[k])
    for k in range(m):
        dl_[k] = stretch_variation(llb[k] - lla[k], ha[k], sa[k], lta[k], hb[k], sb[k], ltb[k])
    for k in range(m):
        ds_[k] = (lsb[k] - lsa[k]) + sig[k] * skew_variation(ha[k], ca[k], lta[k], hb[k], cb[k], ltb[k])
    for k in range(m):
        dp_[k] = lta[k] + ltb[k]
    xl, xs, ta_, tb_, kd = r[F_XL], r[F_XS], r[F_TA], r[F_TB], r[F_KD]
    for k in range(m):
        xl[k] = kl[k] * dl_[k]
        xs[k] = ks[k] * ds_[k]
        kd[k] = kt[k] * dp_[k]
    for k in range(m):
        sg, k_l, k_s = sig[k], kl[k], ks[k]
        ta_[k], tb_[k], _, _ = hinge_products(k_l * el_[k], sg * (k_s * es_[k]), k_l * dl_[k], sg * (k_s * ds_[k]), ha[k],
                                              hb[k], ca[k], sa[k], cb[k], sb[k], lta[k], ltb[k])
    a_rest, a_ha, a_hb, a_kl, a_ks, a_kt = acc[0], acc[1], acc[2], acc[3], acc[4], acc[5]
    for k in range(m):
        a_rest[k] -= kl[k] * dl_[k]
        a_kl[k] -= el_[k] * dl_[k]
        a_ks[k] -= es_[k] * ds_[k]
    for k in range(m):
        a_kt[k] -= (qta[k] + qtb[k]) * dp_[k]
    for k in range(m):
        sg, k_l, k_s = sig[k], kl[k], ks[k]
        _, _, gha, ghb = hinge_products(k_l * el_[k], sg * (k_s * es_[k]), k_l * dl_[k], sg * (k_s * ds_[k]), ha[k],
                                        hb[k], ca[k], sa[k], cb[k], sb[k], lta[k], ltb[k])
        a_ha[k] -= gha
        a_hb[k] -= ghb
    ola, olb, osa, osb = out[la0:], out[la0 + off :], out[sa0:], out[sa0 + off :]
    ota, otb = out[2 * n :], out[2 * n + off :]
    t0a, t0b = acc_t0, acc_t0[off:]
    for k in range(m):  # each end in its own loops (an end is another hinge's other end)
        ola[k] += xl[k]
        osa[k] += xs[k]
    for k in range(m):
        ota[k] -= ta_[k] + kd[k]
        t0a[k] -= ta_[k]
    for k in range(m):
        olb[k] -= xl[k]
        osb[k] -= xs[k]
    for k in range(m):
        otb[k] -= tb_[k] + kd[k]
        t0b[k] -= tb_[k]


@jit
def sheet_grid_adjoint(q, theta0, nc, xc, yc, lam, out, acc_x, acc_y, acc_t0, r):
    """``sheet_adjoint`` of a grid sheet in column form (``sheet_grid_columns``): (∂F/∂q)ᵀλ added
    to ``out``, parameter adjoints to the family accumulators and θ0's; r (N_F + 2, n) scratch."""
    n = theta0.shape[0]
    cs, sn = r[N_F], r[N_F + 1]
    th = q[2 * n :]
    for i in range(n):
        s, c = sincos(theta0[i] + th[i])
        cs[i] = c
        sn[i] = s
    _family(q, lam, cs, sn, xc, 1, 0, n, n, n - 1, r, acc_x, out, acc_t0)
    _family(q, lam, cs, sn, yc, nc, n, 0, n, n - nc, r, acc_y, out, acc_t0)


# ---------------------------------------------------------------- uniform grid sheets, fused reverse
#
# A grid sheet whose hinges all have the same law but for the shear sign (±1) and whose units
# all have the same θ0 (``sheet_uniform``): the model part of the reverse step with the law's
# parameters as scalars, in the chain's style (``chain_uniform_*``): per family one pass for
# the strains' variations along λ, the Hessian products and the parameter products together
# (``hinge_adjoint``'s algebra regrouped) into padded rows, one pass per family for the
# hinge-parameter adjoints (kept per hinge: a design varies them), and one pass over the sites
# gathering their four hinges. The row ends' dummy x hinges compute with the shared parameters
# and are zeroed in the rows (their parameter adjoints are never read: ``sheet_grid_add``).

#: rows of the uniform sheet reverse step's scratch (``sheet_uniform_scratch``): cos/sin; the x
#: family's products (entry s + 1 for the hinge from site s); the y family's (entry s + n_cols);
#: each family's strains and their variations (entry s)
(W_COS, W_SIN, W_XP, W_XS, W_XA, W_XB, W_XK, W_YP, W_YS, W_YA, W_YB, W_YK, W_EL, W_ES, W_DL, W_DS) = range(16)
N_W = 16


def sheet_uniform(hprm: np.ndarray, theta0: np.ndarray) -> np.ndarray | None:
    """The shared law (rest, h_A, h_B, k_l, k_s, k_θ, θ0) of a sheet whose hinges all have the
    same parameters but for a shear sign of ±1 and whose units the same θ0, or None."""
    cols = [H_REST, H_HALF_A, H_HALF_B, H_KL, H_KS, H_KT]
    law = hprm[:, cols]
    if hprm.shape[0] == 0 or not (np.all(law == law[:1]) and np.all(np.abs(hprm[:, H_SIGN]) == 1.0)
                                  and np.all(theta0 == theta0[:1])):
        return None
    return np.concatenate([law[0], theta0[:1]])


@jit
def sheet_uniform_scratch(n, nc):
    """The scratch (N_W, n + n_cols) of ``sheet_uniform_adjoint``, its padding zeroed."""
    return np.zeros((N_W, n + nc))


@jit
def _uniform_family(qla, qlb, qsa, qsb, qta, qtb, lla, llb, lsa, lsb, lta, ltb, ca, sa, cb, sb, sig, p, m,
                    P_, S_, TA, TB, KD, el_, es_, dl_, ds_):
    """Hinges k < m of a family (views from their A and B ends): the strains el, es and their
    variations dl, ds along λ (kept for ``_uniform_family_params``), and the Hessian products:
    k_l δl (P_), k_s δs (S_), at the two rotations without k_θ (TA, TB), k_θ δφ (KD)."""
    rest, hA, hB, kl, ks, kt = p[0], p[1], p[2], p[3], p[4], p[5]
    for k in range(m):
        c_a, s_a, c_b, s_b, sg, l_a, l_b = ca[k], sa[k], cb[k], sb[k], sig[k], lta[k], ltb[k]
        el = stretch(qlb[k] - qla[k], rest, hA, c_a, hB, c_b)
        es = (qsb[k] - qsa[k]) + sg * skew(hA, s_a, hB, s_b)
        dl = stretch_variation(llb[k] - lla[k], hA, s_a, l_a, hB, s_b, l_b)
        ds = (lsb[k] - lsa[k]) + sg * skew_variation(hA, c_a, l_a, hB, c_b, l_b)
        pp = kl * dl
        ss = ks * ds
        P_[k] = pp
        S_[k] = ss
        TA[k], TB[k], _, _ = hinge_products(kl * el, sg * (ks * es), pp, sg * ss, hA, hB, c_a, s_a, c_b, s_b, l_a, l_b)
        KD[k] = kt * (l_a + l_b)
        el_[k] = el
        es_[k] = es
        dl_[k] = dl
        ds_[k] = ds


@jit
def _uniform_family_params(qta, qtb, lta, ltb, ca, sa, cb, sb, sig, p, m, el_, es_, dl_, ds_, acc):
    """The family's hinge-parameter adjoints (``FAMILY_COLS`` rows of acc) from its strains."""
    hA, hB, kl, ks = p[1], p[2], p[3], p[4]
    a_rest, a_ha, a_hb, a_kl, a_ks, a_kt = acc[0], acc[1], acc[2], acc[3], acc[4], acc[5]
    for k in range(m):
        c_a, s_a, c_b, s_b, sg, l_a, l_b = ca[k], sa[k], cb[k], sb[k], sig[k], lta[k], ltb[k]
        el, es, dl, ds = el_[k], es_[k], dl_[k], ds_[k]
        pp = kl * dl
        _, _, gha, ghb = hinge_products(kl * el, sg * (ks * es), pp, sg * (ks * ds), hA, hB, c_a, s_a, c_b, s_b, l_a, l_b)
        a_rest[k] -= pp
        a_ha[k] -= gha
        a_hb[k] -= ghb
        a_kl[k] -= el * dl
        a_ks[k] -= es * ds
        a_kt[k] -= (qta[k] + qtb[k]) * (l_a + l_b)


@jit
def sheet_uniform_adjoint(q, lam, out, p, nc, sgx, sgy, acc_x, acc_y, acc_t0, r):
    """``sheet_grid_adjoint`` of a uniform grid sheet (``sheet_uniform``'s p; the families' shear
    signs sgx (n − 1), sgy (n − nc), 0 at the dummies): (∂F/∂q)ᵀλ added to ``out``, parameter
    adjoints to the family accumulators and θ0's; r the scratch of ``sheet_uniform_scratch``."""
    n = acc_t0.shape[0]
    cs, sn = r[W_COS, :n], r[W_SIN, :n]
    qu, qv, qt = q[:n], q[n : 2 * n], q[2 * n : 3 * n]
    lu, lv, lt = lam[:n], lam[n : 2 * n], lam[2 * n : 3 * n]
    th0 = p[6]
    for i in range(n):
        s, c = sincos(th0 + qt[i])
        cs[i] = c
        sn[i] = s
    el_, es_, dl_, ds_ = r[W_EL], r[W_ES], r[W_DL], r[W_DS]
    m = n - 1  # x family: site s to s + 1, rows from entry 1
    _uniform_family(qu, qu[1:], qv, qv[1:], qt, qt[1:], lu, lu[1:], lv, lv[1:], lt, lt[1:], cs, sn, cs[1:], sn[1:],
                    sgx, p, m, r[W_XP, 1:], r[W_XS, 1:], r[W_XA, 1:], r[W_XB, 1:], r[W_XK, 1:], el_, es_, dl_, ds_)
    _uniform_family_params(qt, qt[1:], lt, lt[1:], cs, sn, cs[1:], sn[1:], sgx, p, m, el_, es_, dl_, ds_, acc_x)
    for e in range(0, n + 1, nc):  # the dummies at the rows' ends (and the padding)
        for row in range(W_XP, W_XK + 1):
            r[row, e] = 0.0
    m = n - nc  # y family: site s to s + nc, rows from entry nc
    _uniform_family(qv, qv[nc:], qu, qu[nc:], qt, qt[nc:], lv, lv[nc:], lu, lu[nc:], lt, lt[nc:], cs, sn, cs[nc:],
                    sn[nc:], sgy, p, m, r[W_YP, nc:], r[W_YS, nc:], r[W_YA, nc:], r[W_YB, nc:], r[W_YK, nc:], el_,
                    es_, dl_, ds_)
    _uniform_family_params(qt, qt[nc:], lt, lt[nc:], cs, sn, cs[nc:], sn[nc:], sgy, p, m, el_, es_, dl_, ds_, acc_y)
    xp, xs, xa, xb, xk = r[W_XP], r[W_XS], r[W_XA], r[W_XB], r[W_XK]
    xp1, xs1, xa1, xk1 = r[W_XP, 1:], r[W_XS, 1:], r[W_XA, 1:], r[W_XK, 1:]
    yp, ys, ya, yb, yk = r[W_YP], r[W_YS], r[W_YA], r[W_YB], r[W_YK]
    yp1, ys1, ya1, yk1 = r[W_YP, nc:], r[W_YS, nc:], r[W_YA, nc:], r[W_YK, nc:]
    ou, ov, ot = out[:n], out[n : 2 * n], out[2 * n : 3 * n]
    for i in range(n):  # each site: A end of x hinge i and y hinge i, B end of x hinge i − 1 and y hinge i − nc
        ou[i] += (xp1[i] - xp[i]) + (ys1[i] - ys[i])
        ov[i] += (xs1[i] - xs[i]) + (yp1[i] - yp[i])
        t = (xa1[i] + xb[i]) + (ya1[i] + yb[i])
        ot[i] -= t + ((xk1[i] + xk[i]) + (yk1[i] + yk[i]))
        acc_t0[i] -= t


@jit
def sheet_tangent(q, args, dq, d1, d2, out):
    """(∂F/∂q) dq + (∂F/∂p)(d1, d2) into ``out`` (d1: hinge table, d2: θ0 directions); indices
    as ``sheet_adjoint``'s."""
    ha, hb, hax, hprm, theta0 = args[0], args[1], args[2], args[3], args[4]
    n = theta0.shape[0]
    for k in range(out.shape[0]):
        out[k] = 0.0
    cs = np.empty(n)
    sn = np.empty(n)
    unit_angles(q, theta0, cs, sn)
    hf, df = hprm.ravel(), d1.ravel()
    for h in range(ha.shape[0]):
        a, b, la, lb, sa, sb, ta, tb = _sheet_dofs(ha, hb, hax, n, h)
        rest, hA, hB, sig, kl, ks, kt = hinge_row(hf, h)
        drest, dhA, dhB, _, dkl, dks, dkt = hinge_row(df, h)
        d_fl, d_fs, d_ga, d_gb = hinge_tangent_terms(
            q[lb] - q[la], q[sb] - q[sa], q[ta] + q[tb], dq[lb] - dq[la], dq[sb] - dq[sa], dq[ta], dq[tb], d2[a], d2[b],
            rest, hA, hB, sig, kl, ks, kt, drest, dhA, dhB, dkl, dks, dkt, cs[a], sn[a], cs[b], sn[b])
        add_to_ends(out, out, out, la, lb, sa, sb, ta, tb, d_fl, d_fs, d_ga, d_gb)


# ---------------------------------------------------------------- chains of masses


@jit
def mass_adjoint(q, args, lam, out, g1, g2):
    """(∂F/∂q)ᵀλ added to ``out``, (∂F/∂p)ᵀλ to g1 (bond rows), g2 (on-site rows)."""
    bi, bj, bcode, bprm, si, scode, sprm, tab = args
    dprm = np.empty(bprm.shape[1])
    for b in range(bi.shape[0]):
        i = bi[b]
        j = bj[b]
        d2 = law_second(bcode[b], q[j] - q[i], bprm[b], tab, dprm)
        w = d2 * (lam[j] - lam[i])  # F_i = E'(z), F_j = −E'(z), z = q_j − q_i
        out[i] += w
        out[j] -= w
        dl = lam[i] - lam[j]
        for c in range(dprm.shape[0]):
            g1[b, c] += dl * dprm[c]
    for s in range(si.shape[0]):
        i = si[s]
        d2 = law_second(scode[s], q[i], sprm[s], tab, dprm)
        out[i] -= d2 * lam[i]  # F_i = −E'(q_i)
        for c in range(dprm.shape[0]):
            g2[s, c] -= lam[i] * dprm[c]


@jit
def mass_tangent(q, args, dq, d1, d2, out):
    """(∂F/∂q) dq + (∂F/∂p)(d1, d2) into ``out`` (d1: bond rows, d2: on-site rows)."""
    bi, bj, bcode, bprm, si, scode, sprm, tab = args
    dprm = np.empty(bprm.shape[1])
    for k in range(out.shape[0]):
        out[k] = 0.0
    for b in range(bi.shape[0]):
        i = bi[b]
        j = bj[b]
        e2 = law_second(bcode[b], q[j] - q[i], bprm[b], tab, dprm)
        w = e2 * (dq[j] - dq[i])
        for c in range(dprm.shape[0]):
            w += dprm[c] * d1[b, c]
        out[i] += w
        out[j] -= w
    for s in range(si.shape[0]):
        i = si[s]
        e2 = law_second(scode[s], q[i], sprm[s], tab, dprm)
        w = e2 * dq[i]
        for c in range(dprm.shape[0]):
            w += dprm[c] * d2[s, c]
        out[i] -= w


# ---------------------------------------------------------------- models with more terms
#
# The sheet with dipoles, joints and loads, the loaded chain and rotating triangles: the hinge
# kernels above plus the element kernels of ``kernels_extra`` (its docstring: the tables).


@jit
def sheet_full_adjoint(q, args, lam, out, g1, g2):
    """(∂F/∂q)ᵀλ added to ``out``, (∂F/∂p)ᵀλ to g1 (hinge table) and g2 (the t2 vector)."""
    n, o_s, o_core, o_off, o_pos, o_j, o_l, _ = sheet_offsets(args)
    sheet_adjoint(q, args, lam, out, g1, g2)  # hinges; θ0 at g2[:n]
    if args.dipoles[0].shape[0] > 0:
        dipoles_second(q, args.dipoles, n, lam, g2, o_s, o_core, o_off, o_pos, runtime(False), out, g2)
    joints_adjoint(q, n, args.joints, lam, out, g2, o_j)
    loads_adjoint(args.loads, lam, g2, o_l)


@jit
def sheet_full_tangent(q, args, dq, d1, d2, out):
    """(∂F/∂q) dq + (∂F/∂p)(d1, d2) into ``out`` (d1: hinge table, d2: the t2 vector)."""
    n, o_s, o_core, o_off, o_pos, o_j, o_l, _ = sheet_offsets(args)
    sheet_tangent(q, args, dq, d1, d2, out)  # zeroes out; θ0 directions at d2[:n]
    if args.dipoles[0].shape[0] > 0:
        dipoles_second(q, args.dipoles, n, dq, d2, o_s, o_core, o_off, o_pos, runtime(True), out, d2)
    joints_tangent(q, n, args.joints, dq, d2, o_j, out)
    loads_tangent(args.loads, d2, o_l, out)


@jit
def loaded_chain_adjoint(q, args, lam, out, g1, g2):
    """The chain's (site table: g2[:3N] as (N, 3)), then the loads' values (g2[3N:])."""
    chain = args[0]
    n = chain.site_prm.shape[0]
    chain_adjoint(q, chain, lam, out, g1, g2[: 3 * n].reshape((n, 3)))
    loads_adjoint(args[1], lam, g2, 3 * n)


@jit
def loaded_chain_tangent(q, args, dq, d1, d2, out):
    chain = args[0]
    n = chain.site_prm.shape[0]
    chain_tangent(q, chain, dq, d1, d2[: 3 * n].reshape((n, 3)), out)
    loads_tangent(args[1], d2, 3 * n, out)


# ---------------------------------------------------------------- dispatch


@dataclass(frozen=True)
class AdjointKernels:
    """Second-derivative kernels of one args type and its two parameter tables: the names of two
    fields of the args (``tables``), or, for a model whose parameters live in more places,
    ``pack(args) -> (t1, t2)`` and ``unpack(args, t1, t2) -> args`` (e.g. t2 a vector of several
    tables end to end; ``kernels_extra``)."""

    adjoint: Callable
    tangent: Callable
    tables: tuple[str, str] | None = None
    pack: Callable | None = None
    unpack: Callable | None = None


ADJOINT_KERNELS: dict[type, AdjointKernels] = {
    ChainArgs: AdjointKernels(chain_adjoint, chain_tangent, ("hinge_prm", "site_prm")),
    MassArgs: AdjointKernels(mass_adjoint, mass_tangent, ("bond_prm", "site_prm")),
    SheetArgs: AdjointKernels(sheet_full_adjoint, sheet_full_tangent, pack=sheet_pack, unpack=sheet_unpack),
    LoadedChainArgs: AdjointKernels(loaded_chain_adjoint, loaded_chain_tangent, pack=loaded_chain_pack,
                                    unpack=loaded_chain_unpack),
    TriangleArgs: AdjointKernels(triangle_adjoint, triangle_tangent, pack=triangle_pack, unpack=triangle_unpack),
    HarmonicArgs: AdjointKernels(harmonic_adjoint, harmonic_tangent, pack=harmonic_pack, unpack=harmonic_unpack),
    NetworkArgs: AdjointKernels(network_adjoint, network_tangent, pack=network_pack, unpack=network_unpack),
}


def adjoint_kernels_of(args_type: type) -> AdjointKernels:
    try:
        return ADJOINT_KERNELS[args_type]
    except KeyError:
        known = ", ".join(k.__name__ for k in ADJOINT_KERNELS)
        raise TypeError(f"no gradient kernels for model arguments {args_type.__name__} (known: {known})") from None


def param_tables(args) -> tuple[np.ndarray, np.ndarray]:
    """The two differentiable parameter tables of a model's args."""
    k = adjoint_kernels_of(type(args))
    if k.pack is not None:
        return k.pack(args)
    a, b = k.tables
    return getattr(args, a), getattr(args, b)


def with_tables(args, t1: np.ndarray, t2: np.ndarray):
    """A copy of ``args`` with its two parameter tables replaced."""
    k = adjoint_kernels_of(type(args))
    if k.unpack is not None:
        return k.unpack(args, t1, t2)
    a, b = k.tables
    return args._replace(**{a: t1, b: t2})


def model_adjoint(q, args, lam, out, g1, g2):
    """Add (∂F/∂q)ᵀλ to ``out`` and (∂F/∂p)ᵀλ to the parameter-table gradients g1, g2."""
    adjoint_kernels_of(type(args)).adjoint(q, args, lam, out, g1, g2)


def model_tangent(q, args, dq, d1, d2, out):
    """(∂F/∂q) dq + (∂F/∂p)(d1, d2) into ``out``."""
    adjoint_kernels_of(type(args)).tangent(q, args, dq, d1, d2, out)


if not NO_JIT:

    def _cls(args):
        cls = getattr(args, "instance_class", None)
        if cls is None:
            raise TypeError(f"model arguments must be a NamedTuple declared in ADJOINT_KERNELS, got {args}")
        return cls

    @overload(model_adjoint, jit_options=JIT_OPTIONS)
    def _model_adjoint(q, args, lam, out, g1, g2):
        kernel = adjoint_kernels_of(_cls(args)).adjoint

        def impl(q, args, lam, out, g1, g2):
            kernel(q, args, lam, out, g1, g2)

        return impl

    @overload(model_tangent, jit_options=JIT_OPTIONS)
    def _model_tangent(q, args, dq, d1, d2, out):
        kernel = adjoint_kernels_of(_cls(args)).tangent

        def impl(q, args, dq, d1, d2, out):
            kernel(q, args, dq, d1, d2, out)

        return impl
