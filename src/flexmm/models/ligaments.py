"""Rigid units of any shape joined by ligaments at any of their points (docs/physics.md §1.9).

The general planar model of rigid units: unit i has DOFs (u_i, v_i, θ_i), field-major in q
(u block, v block, θ block), θ_i its rotation from the reference configuration. Ligament k joins
point r_a of unit a to point r_b of unit b (body-frame offsets from the units' centres in the
reference configuration). Its strains are read from the gap and the two rotations,

    g  = o + (u_b − u_a, v_b − v_a) + R(θ_b) r_b − R(θ_a) r_a,   Δφ = θ_b − θ_a,   θ̄ = (θ_a + θ_b)/2,

where o = X_b − X_a − g0 is the ligament's rest offset (the centres' separation less the rest gap
g0 between its two points, so g = 0 in a stress-free reference), and its energy is one of three
laws (``LAWS``; the network's ``law``), with axis e, n = J e (J the rotation by +90°) and rest
length ℓ (``L_LEN``; the rest gap is g0 = ℓ e for the DifFlexMM laws):

    paper              E = ½ k_l (g·e)² + ½ k_s (g·n)² + ½ k_θ Δφ²,
    difflexmm_linear   E = ½ k_l (g·e)² + ½ k_s (g·n − ℓ θ̄)² + ½ k_θ Δφ²,
    difflexmm          E = ½ k_l (|c| − ℓ)² + ½ k_s ℓ² γ² + ½ k_θ Δφ²,   c = ℓ e + g,
                       γ = ψ − θ̄ wrapped to [−π, π),  ψ = atan2(c·n, c·e),

the paper's three springs [R0, Eq. (1)] and DifFlexMM's ligament with linearised and nonlinear
strains (axial, shear = bond angle less the mean rotation, rotational). The rotating squares and
triangles of §1.1–1.6 are the paper law on their hinge points (``tests/models/test_ligaments.py``).

Each law gives (``ligament_law``) its energy and the derivatives G = ∂E/∂g, T_d = ∂E/∂Δφ,
T_m = ∂E/∂θ̄; with p = R(θ) r the rotated offsets,

    ∂E/∂x_a = −G,  ∂E/∂x_b = G,  ∂E/∂θ_a = −G·J p_a − T_d + ½ T_m,  ∂E/∂θ_b = G·J p_b + T_d + ½ T_m.

Along δq, δg = δx_b − δx_a + δθ_b J p_b − δθ_a J p_a, δΔφ and δθ̄ (``strain_variation``); the law's
Hessian applied to (δg, δΔφ, δθ̄) (``ligament_hvp``) gives the Hessian-vector product

    δ(∂E/∂x_b) = δG = −δ(∂E/∂x_a),
    δ(∂E/∂θ_b) = δG·J p_b − δθ_b G·p_b + δT_d + ½ δT_m,
    δ(∂E/∂θ_a) = −δG·J p_a + δθ_a G·p_a − δT_d + ½ δT_m,

and the law's derivative along its own parameters (k_l, k_s, k_θ, e, ℓ: ``ligament_param_variation``)
gives the adjoint's and the tangent's parameter products. Each law is written once, in those
three functions, and lifted over the ligament table by ``network_force``, ``network_energy``,
``network_hvp``, ``network_adjoint`` and ``network_tangent`` (one loop for every law: the law is a
switch inside it, and each kernel inlines its loop once per law with the law a constant, so the
switch folds away); energy-based contacts between units (``flexmm.models.unit_contact``) are added
in the same loops. ``network_reference`` is the readable numpy version (the tests' oracle).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from flexmm._jit import fma, jit
from flexmm._trig import sincos
from flexmm.models import unit_contact as uc

#: columns of the ligament table: offsets r_a, r_b, rest offset o, axis e, stiffnesses, rest length ℓ
(L_AX, L_AY, L_BX, L_BY, L_OX, L_OY, L_EX, L_EY, L_KL, L_KS, L_KT, L_LEN) = range(12)
N_LIGAMENT_PARAMS = 12
#: the columns a law reads (its own parameters, as opposed to the ligament's geometry)
LAW_COLUMNS = (L_KL, L_KS, L_KT, L_EX, L_EY, L_LEN)
#: the ligament laws (the network's ``law``): the paper's springs, DifFlexMM's nonlinear and linearised
LAW_PAPER, LAW_DIFFLEXMM, LAW_DIFFLEXMM_LINEAR = 0, 1, 2
LAWS = {"paper": LAW_PAPER, "difflexmm": LAW_DIFFLEXMM, "difflexmm_linear": LAW_DIFFLEXMM_LINEAR}


class NetworkArgs(NamedTuple):
    """What the network kernels read: ``unit_a``/``unit_b`` (L,) the joined units (int64),
    ``ligaments`` (L, N_LIGAMENT_PARAMS) their table, ``cos``/``sin`` (N,) scratch, ``law`` the
    ligament law (``LAWS``), ``contact_units`` (C, 2) and ``contacts`` (C, unit_contact.N_CONTACT_PARAMS)
    the vertex–edge contact pairs (none by default)."""

    unit_a: np.ndarray
    unit_b: np.ndarray
    ligaments: np.ndarray
    cos: np.ndarray
    sin: np.ndarray
    law: int = LAW_PAPER
    contact_units: np.ndarray = uc.NO_PAIRS
    contacts: np.ndarray = uc.NO_CONTACTS


@jit
def rotate(c, s, x, y):
    """R(θ) (x, y) from c = cos θ, s = sin θ."""
    return fma(c, x, -(s * y)), fma(s, x, c * y)


@jit
def ligament_gap(q, n, a, b, prm, cs, sn):
    """(g_x, g_y, p_a, p_b, Δφ, θ̄) of the ligament with row ``prm`` joining units a, b: its gap g,
    the rotated offsets p = R(θ) r of its two points (as (x, y) pairs), θ_b − θ_a and (θ_a + θ_b)/2."""
    pax, pay = rotate(cs[a], sn[a], prm[L_AX], prm[L_AY])
    pbx, pby = rotate(cs[b], sn[b], prm[L_BX], prm[L_BY])
    gx = prm[L_OX] + (q[b] - q[a]) + (pbx - pax)
    gy = prm[L_OY] + (q[n + b] - q[n + a]) + (pby - pay)
    ta, tb = q[2 * n + a], q[2 * n + b]
    return gx, gy, pax, pay, pbx, pby, tb - ta, 0.5 * (ta + tb)


@jit
def bond_frame(gx, gy, tbar, prm):
    """DifFlexMM's nonlinear strains: the bond c = ℓe + g, its length r, the shear strain γ (the
    bond's angle from e less θ̄, wrapped to [−π, π)), A = k_l (r − ℓ) and B = k_s ℓ² γ."""
    ell, ex, ey = prm[L_LEN], prm[L_EX], prm[L_EY]
    cx, cy = gx + ell * ex, gy + ell * ey
    r = math.sqrt(cx * cx + cy * cy)
    gam = math.atan2(cy * ex - cx * ey, cx * ex + cy * ey) - tbar
    if abs(gam) > math.pi:
        gam = (gam + math.pi) % (2.0 * math.pi) - math.pi
    return cx, cy, r, gam, prm[L_KL] * (r - ell), prm[L_KS] * ell * ell * gam


@jit
def ligament_law(gx, gy, dphi, tbar, prm, law):
    """(E, G_x, G_y, T_d, T_m) of one ligament: its energy, ∂E/∂g, ∂E/∂Δφ and ∂E/∂θ̄."""
    fp = prm[L_KT] * dphi
    if law == LAW_DIFFLEXMM:
        cx, cy, r, gam, big_a, big_b = bond_frame(gx, gy, tbar, prm)
        # G = A c/r + B J c/r²
        w = big_b / (r * r)
        energy = 0.5 * (big_a * (r - prm[L_LEN]) + big_b * gam + fp * dphi)
        return energy, big_a * cx / r - w * cy, big_a * cy / r + w * cx, fp, -big_b
    ex, ey = prm[L_EX], prm[L_EY]
    el = fma(gx, ex, gy * ey)  # g·e
    es = fma(gy, ex, -(gx * ey))  # g·n, n = (−e_y, e_x)
    tm = 0.0
    if law == LAW_DIFFLEXMM_LINEAR:
        es -= prm[L_LEN] * tbar
    fl = prm[L_KL] * el
    fs = prm[L_KS] * es
    if law == LAW_DIFFLEXMM_LINEAR:
        tm = -fs * prm[L_LEN]
    energy = 0.5 * (fl * el + fs * es + fp * dphi)
    return energy, fma(fl, ex, -(fs * ey)), fma(fl, ey, fs * ex), fp, tm


@jit
def bond_variation(cx, cy, r, big_a, big_b, prm, dcx, dcy, da0, dgam0, db0):
    """(δG_x, δG_y, δT_m) of the nonlinear DifFlexMM law at its ``bond_frame`` when the bond c
    moves by δc and A, γ, B move by da0, dgam0, db0 besides (parameter changes), from G = A u + B w,
    T_m = −B, u = c/r, w = J u/r: δu = J u (J u·δc)/r, δw = −[u (J u·δc) + J u (u·δc)]/r²,
    δγ = w·δc + dgam0."""
    ux, uy = cx / r, cy / r
    al = ux * dcx + uy * dcy  # u·δc
    be = ux * dcy - uy * dcx  # J u·δc
    da = prm[L_KL] * al + da0
    db = prm[L_KS] * prm[L_LEN] * prm[L_LEN] * (be / r + dgam0) + db0
    rr = r * r
    dgx = da * ux - (big_a * be / r + db / r) * uy - big_b * (ux * be - uy * al) / rr
    dgy = da * uy + (big_a * be / r + db / r) * ux - big_b * (uy * be + ux * al) / rr
    return dgx, dgy, -db


@jit
def ligament_hvp(gx, gy, dphi, tbar, dgx, dgy, ddphi, dtbar, prm, law):
    """(δG_x, δG_y, δT_d, δT_m): the law's Hessian at (g, Δφ, θ̄) applied to (δg, δΔφ, δθ̄)."""
    if law == LAW_DIFFLEXMM:
        cx, cy, r, _, big_a, big_b = bond_frame(gx, gy, tbar, prm)
        kx, ky, km = bond_variation(cx, cy, r, big_a, big_b, prm, dgx, dgy, 0.0, -dtbar, 0.0)
        return kx, ky, prm[L_KT] * ddphi, km
    # the paper's and the linearised laws are quadratic: their gradient is their Hessian's product
    _, kx, ky, kp, km = ligament_law(dgx, dgy, ddphi, dtbar, prm, law)
    return kx, ky, kp, km


@jit
def bond_param_variation(cx, cy, r, gam, big_a, big_b, dphi, prm, dp):
    """``ligament_param_variation`` of the nonlinear DifFlexMM law at its ``bond_frame``: c = ℓe + g
    moves by ℓ δe + δℓ e, and ψ (the bond's angle less e's) by −(J e·δe)/|e|² besides."""
    dkl, dks, dex, dey, dell = dp[L_KL], dp[L_KS], dp[L_EX], dp[L_EY], dp[L_LEN]
    ex, ey, ell, kl, ks = prm[L_EX], prm[L_EY], prm[L_LEN], prm[L_KL], prm[L_KS]
    da0 = dkl * (r - ell) - kl * dell
    dgam0 = -(ex * dey - ey * dex) / (ex * ex + ey * ey)
    db0 = (dks * ell + 2.0 * ks * dell) * ell * gam
    kx, ky, km = bond_variation(cx, cy, r, big_a, big_b, prm, ell * dex + dell * ex, ell * dey + dell * ey,
                                da0, dgam0, db0)
    return kx, ky, dp[L_KT] * dphi, km


@jit
def ligament_param_variation(gx, gy, dphi, tbar, prm, law, dp):
    """(δG_x, δG_y, δT_d, δT_m) at fixed (g, Δφ, θ̄) along a direction ``dp`` of the law's own
    parameters (the ``LAW_COLUMNS`` of a table row: k_l, k_s, k_θ, e, ℓ)."""
    if law == LAW_DIFFLEXMM:
        cx, cy, r, gam, big_a, big_b = bond_frame(gx, gy, tbar, prm)
        return bond_param_variation(cx, cy, r, gam, big_a, big_b, dphi, prm, dp)
    dkl, dks, dex, dey, dell = dp[L_KL], dp[L_KS], dp[L_EX], dp[L_EY], dp[L_LEN]
    ex, ey, ell, kl, ks = prm[L_EX], prm[L_EY], prm[L_LEN], prm[L_KL], prm[L_KS]
    lin = 1.0 if law == LAW_DIFFLEXMM_LINEAR else 0.0
    el = gx * ex + gy * ey
    es = gy * ex - gx * ey - lin * ell * tbar
    del_ = gx * dex + gy * dey
    des = gy * dex - gx * dey - lin * dell * tbar
    # G = k_l (g·e) e + k_s s n, n = (−e_y, e_x), s = g·n − ℓθ̄ (linearised) or g·n; T_m = −k_s ℓ s
    fl, dfl = kl * el, dkl * el + kl * del_
    fs, dfs = ks * es, dks * es + ks * des
    kx = dfl * ex + fl * dex - (dfs * ey + fs * dey)
    ky = dfl * ey + fl * dey + (dfs * ex + fs * dex)
    return kx, ky, dp[L_KT] * dphi, -lin * (dfs * ell + fs * dell)


@jit
def ligament_param_products(gx, gy, dphi, tbar, prm, law, wx, wy, dl, dm, unit, row):
    """The adjoint's law part: row[j] −= ∂(G·w + T_d δΔφ + T_m δθ̄)/∂p_j for the law's columns
    (``ligament_param_variation`` along each column; the nonlinear law's frame computed once);
    ``unit`` a zeroed scratch row."""
    cx, cy, r, gam, big_a, big_b = 0.0, 0.0, 1.0, 0.0, 0.0, 0.0
    if law == LAW_DIFFLEXMM:
        cx, cy, r, gam, big_a, big_b = bond_frame(gx, gy, tbar, prm)
    for col in LAW_COLUMNS:
        unit[col] = 1.0
        if law == LAW_DIFFLEXMM:
            px, py, pd, pm = bond_param_variation(cx, cy, r, gam, big_a, big_b, dphi, prm, unit)
        else:
            px, py, pd, pm = ligament_param_variation(gx, gy, dphi, tbar, prm, law, unit)
        unit[col] = 0.0
        row[col] -= px * wx + py * wy + pd * dl + pm * dm


@jit
def network_angles(q, n, cs, sn):
    """cos/sin of every unit's rotation θ into cs, sn."""
    for i in range(n):
        s, c = sincos(q[2 * n + i])
        cs[i] = c
        sn[i] = s


@jit(inline=True)
def _ligaments(q, n, ua, ub, lig, cs, sn, out, want_force, law):
    """Energy of every ligament, and −∂E/∂q added to ``out`` when ``want_force``."""
    total = 0.0
    for k in range(ua.shape[0]):
        a = ua[k]
        b = ub[k]
        prm = lig[k]
        gx, gy, pax, pay, pbx, pby, dphi, tbar = ligament_gap(q, n, a, b, prm, cs, sn)
        e, fx, fy, fp, tm = ligament_law(gx, gy, dphi, tbar, prm, law)
        total += e
        if want_force:
            out[a] += fx
            out[n + a] += fy
            out[b] -= fx
            out[n + b] -= fy
            # ∂E/∂θ_a = −G·J p_a − T_d + ½T_m, with G·J p = G_y p_x − G_x p_y
            out[2 * n + a] += fma(fy, pax, -(fx * pay)) + fp - 0.5 * tm
            out[2 * n + b] -= fma(fy, pbx, -(fx * pby)) + fp + 0.5 * tm
    return total


@jit
def _network(q, args, out, want_force):
    """Energy of every ligament and contact, and −∂E/∂q added to ``out`` when ``want_force``.
    Each ligament loop below is the one of ``_ligaments``, inlined with the law as a constant
    (the law's branches fold away: a switch per ligament costs the paper's law 2–3x)."""
    ua, ub, lig, cs, sn, law = args[0], args[1], args[2], args[3], args[4], args[5]
    n = cs.shape[0]
    network_angles(q, n, cs, sn)
    if law == LAW_DIFFLEXMM:
        total = _ligaments(q, n, ua, ub, lig, cs, sn, out, want_force, LAW_DIFFLEXMM)
    elif law == LAW_DIFFLEXMM_LINEAR:
        total = _ligaments(q, n, ua, ub, lig, cs, sn, out, want_force, LAW_DIFFLEXMM_LINEAR)
    else:
        total = _ligaments(q, n, ua, ub, lig, cs, sn, out, want_force, LAW_PAPER)
    return total + uc.contacts(q, n, cs, sn, args[6], args[7], out, want_force)


@jit
def network_force(q, args, out):
    """−∂E/∂q of a ligament network into ``out`` (3N,)."""
    for k in range(out.shape[0]):
        out[k] = 0.0
    _network(q, args, out, True)


@jit
def network_energy(q, args):
    """Potential energy of a ligament network."""
    return _network(q, args, np.empty(0), False)


@jit
def strain_variation(lam, n, a, b, pax, pay, pbx, pby):
    """(δg_x, δg_y, δΔφ, δθ̄): the variation of the gap, of θ_b − θ_a and of (θ_a + θ_b)/2 along
    λ, δg = δx_b − δx_a + λ_θb J p_b − λ_θa J p_a with J p = (−p_y, p_x)."""
    ta, tb = lam[2 * n + a], lam[2 * n + b]
    wx = (lam[b] - lam[a]) - (tb * pby - ta * pay)
    wy = (lam[n + b] - lam[n + a]) + (tb * pbx - ta * pax)
    return wx, wy, tb - ta, 0.5 * (ta + tb)


@jit(inline=True)
def _ligaments_hvp(q, n, ua, ub, lig, cs, sn, dq, out, law):
    """∇²E dq of every ligament added to ``out``."""
    for k in range(ua.shape[0]):
        a = ua[k]
        b = ub[k]
        prm = lig[k]
        gx, gy, pax, pay, pbx, pby, dphi, tbar = ligament_gap(q, n, a, b, prm, cs, sn)
        _, fx, fy, _, _ = ligament_law(gx, gy, dphi, tbar, prm, law)
        ta, tb = dq[2 * n + a], dq[2 * n + b]
        dgx, dgy, dphi_q, dtbar = strain_variation(dq, n, a, b, pax, pay, pbx, pby)
        kx, ky, kp, km = ligament_hvp(gx, gy, dphi, tbar, dgx, dgy, dphi_q, dtbar, prm, law)
        out[b] += kx
        out[n + b] += ky
        out[a] -= kx
        out[n + a] -= ky
        out[2 * n + b] += fma(ky, pbx, -(kx * pby)) - tb * fma(fx, pbx, fy * pby) + kp + 0.5 * km
        out[2 * n + a] -= fma(ky, pax, -(kx * pay)) - ta * fma(fx, pax, fy * pay) + kp - 0.5 * km


@jit
def network_hvp(q, args, dq, out):
    """∇²E(q) dq of a ligament network into ``out`` (3N,): the Hessian-vector product the
    adjoint and tangent steps and the linear analysis need (contacts included)."""
    ua, ub, lig, cs, sn, law = args[0], args[1], args[2], args[3], args[4], args[5]
    n = cs.shape[0]
    network_angles(q, n, cs, sn)
    for k in range(out.shape[0]):
        out[k] = 0.0
    if law == LAW_DIFFLEXMM:
        _ligaments_hvp(q, n, ua, ub, lig, cs, sn, dq, out, LAW_DIFFLEXMM)
    elif law == LAW_DIFFLEXMM_LINEAR:
        _ligaments_hvp(q, n, ua, ub, lig, cs, sn, dq, out, LAW_DIFFLEXMM_LINEAR)
    else:
        _ligaments_hvp(q, n, ua, ub, lig, cs, sn, dq, out, LAW_PAPER)
    uc.contacts_hvp(q, n, cs, sn, args[6], args[7], dq, out)


@jit(inline=True)
def _ligaments_adjoint(q, n, ua, ub, lig, cs, sn, lam, g1, law):
    """−∂(λ·∇E)/∂p of every ligament added to its row of g1 (``network_adjoint``)."""
    unit = np.zeros(N_LIGAMENT_PARAMS)
    for k in range(ua.shape[0]):
        a = ua[k]
        b = ub[k]
        prm = lig[k]
        gx, gy, pax, pay, pbx, pby, dphi, tbar = ligament_gap(q, n, a, b, prm, cs, sn)
        wx, wy, dl, dm = strain_variation(lam, n, a, b, pax, pay, pbx, pby)
        _, fx, fy, _, _ = ligament_law(gx, gy, dphi, tbar, prm, law)
        kx, ky, _, _ = ligament_hvp(gx, gy, dphi, tbar, wx, wy, dl, dm, prm, law)
        ta, tb = lam[2 * n + a], lam[2 * n + b]
        # H w − λ_θ J G, J G = (−G_y, G_x), rotated back by R(θ)ᵀ
        xa, ya = kx + ta * fy, ky - ta * fx
        xb, yb = kx + tb * fy, ky - tb * fx
        ca, sa, cb, sb = cs[a], sn[a], cs[b], sn[b]
        g1[k, L_AX] += ca * xa + sa * ya
        g1[k, L_AY] += -sa * xa + ca * ya
        g1[k, L_BX] -= cb * xb + sb * yb
        g1[k, L_BY] -= -sb * xb + cb * yb
        g1[k, L_OX] -= kx
        g1[k, L_OY] -= ky
        ligament_param_products(gx, gy, dphi, tbar, prm, law, wx, wy, dl, dm, unit, g1[k])


@jit
def network_adjoint(q, args, lam, out, g1, g2):
    """(∂F/∂q)ᵀλ = −∇²E λ added to ``out`` and (∂F/∂p)ᵀλ = −∂(λ·∇E)/∂p to g1 (the ligament table's
    gradient, (L, N_LIGAMENT_PARAMS)) and g2 (the contact table's, ``unit_contact.contacts_adjoint``). With (w, δΔφ, δθ̄) the strains' variation along λ:
    λ·∇E = G·w + T_d δΔφ + T_m δθ̄, so ∂/∂o = H w (H w: the g part of the law's Hessian applied
    to the variation), ∂/∂r_b = R(θ_b)ᵀ (H w − λ_θb J G), ∂/∂r_a = −R(θ_a)ᵀ (H w − λ_θa J G), and
    the law's own parameters from ``ligament_param_variation`` column by column."""
    ua, ub, lig, cs, sn, law = args[0], args[1], args[2], args[3], args[4], args[5]
    n = cs.shape[0]
    hv = np.empty_like(out)
    network_hvp(q, args, lam, hv)  # also leaves cos/sin of θ in cs, sn
    for k in range(out.shape[0]):
        out[k] -= hv[k]
    if law == LAW_DIFFLEXMM:
        _ligaments_adjoint(q, n, ua, ub, lig, cs, sn, lam, g1, LAW_DIFFLEXMM)
    elif law == LAW_DIFFLEXMM_LINEAR:
        _ligaments_adjoint(q, n, ua, ub, lig, cs, sn, lam, g1, LAW_DIFFLEXMM_LINEAR)
    else:
        _ligaments_adjoint(q, n, ua, ub, lig, cs, sn, lam, g1, LAW_PAPER)
    uc.contacts_adjoint(q, n, cs, sn, args[6], args[7], lam, g2)


@jit(inline=True)
def _ligaments_tangent(q, n, ua, ub, lig, cs, sn, d1, out, law):
    """−δ_p(∇E) of every ligament along the table direction d1, added to ``out``."""
    for k in range(ua.shape[0]):
        a = ua[k]
        b = ub[k]
        prm = lig[k]
        dp = d1[k]
        gx, gy, pax, pay, pbx, pby, dphi, tbar = ligament_gap(q, n, a, b, prm, cs, sn)
        _, fx, fy, _, _ = ligament_law(gx, gy, dphi, tbar, prm, law)
        # δg from the offsets: δo + R(θ_b) δr_b − R(θ_a) δr_a; δp of the rotated offsets
        dax, day = rotate(cs[a], sn[a], dp[L_AX], dp[L_AY])
        dbx, dby = rotate(cs[b], sn[b], dp[L_BX], dp[L_BY])
        dgx, dgy = dp[L_OX] + dbx - dax, dp[L_OY] + dby - day
        kx, ky, kp, km = ligament_hvp(gx, gy, dphi, tbar, dgx, dgy, 0.0, 0.0, prm, law)
        px, py, pd, pm = ligament_param_variation(gx, gy, dphi, tbar, prm, law, dp)
        dfx, dfy, dfp, dfm = kx + px, ky + py, kp + pd, km + pm
        out[a] += dfx
        out[n + a] += dfy
        out[b] -= dfx
        out[n + b] -= dfy
        # torques: δ(G·J p) = δG·J p + G·J δp
        out[2 * n + a] += fma(dfy, pax, -(dfx * pay)) + fma(fy, dax, -(fx * day)) + dfp - 0.5 * dfm
        out[2 * n + b] -= fma(dfy, pbx, -(dfx * pby)) + fma(fy, dbx, -(fx * dby)) + dfp + 0.5 * dfm


@jit
def network_tangent(q, args, dq, d1, d2, out):
    """(∂F/∂q) dq + (∂F/∂p) dp into ``out``, dp = (d1, d2) the ligament and contact tables' directions:
    −∇²E dq − δ_p(∇E), the parameter variation of the gradient of ``_network`` term by term."""
    ua, ub, lig, cs, sn, law = args[0], args[1], args[2], args[3], args[4], args[5]
    n = cs.shape[0]
    network_hvp(q, args, dq, out)  # also leaves cos/sin of θ in cs, sn
    for k in range(out.shape[0]):
        out[k] = -out[k]
    if law == LAW_DIFFLEXMM:
        _ligaments_tangent(q, n, ua, ub, lig, cs, sn, d1, out, LAW_DIFFLEXMM)
    elif law == LAW_DIFFLEXMM_LINEAR:
        _ligaments_tangent(q, n, ua, ub, lig, cs, sn, d1, out, LAW_DIFFLEXMM_LINEAR)
    else:
        _ligaments_tangent(q, n, ua, ub, lig, cs, sn, d1, out, LAW_PAPER)
    uc.contacts_tangent(q, n, cs, sn, args[6], args[7], d2, out)


def network_pack(args) -> tuple[np.ndarray, np.ndarray]:
    """The differentiable tables of a network: its ligament table and its contact table."""
    return args.ligaments, args.contacts


def network_unpack(args, t1: np.ndarray, t2: np.ndarray):
    """``args`` with its ligament and contact tables replaced."""
    return args._replace(ligaments=t1, contacts=t2)


def law_reference(g: np.ndarray, dphi: np.ndarray, tbar: np.ndarray, p: np.ndarray, law: int):
    """Energies (L,), ∂E/∂g (2, L), ∂E/∂Δφ and ∂E/∂θ̄ (L,) of the ligaments (numpy; ``p`` the
    transposed table)."""
    e, nrm = p[[L_EX, L_EY]], np.stack([-p[L_EY], p[L_EX]])
    ell, kl, ks, kt = p[L_LEN], p[L_KL], p[L_KS], p[L_KT]
    if law == LAW_DIFFLEXMM:
        c = ell * e + g
        r = np.hypot(c[0], c[1])
        gam = np.arctan2(np.sum(c * nrm, 0), np.sum(c * e, 0)) - tbar
        gam = np.where(np.abs(gam) > np.pi, np.mod(gam + np.pi, 2 * np.pi) - np.pi, gam)
        energy = 0.5 * (kl * (r - ell) ** 2 + ks * (ell * gam) ** 2 + kt * dphi**2)
        jc = np.stack([-c[1], c[0]])
        return energy, kl * (r - ell) * c / r + ks * ell**2 * gam * jc / r**2, kt * dphi, -ks * ell**2 * gam
    lin = 1.0 if law == LAW_DIFFLEXMM_LINEAR else 0.0
    el, es = np.sum(g * e, 0), np.sum(g * nrm, 0) - lin * ell * tbar
    energy = 0.5 * (kl * el**2 + ks * es**2 + kt * dphi**2)
    return energy, kl * el * e + ks * es * nrm, kt * dphi, -lin * ks * ell * es


def network_reference(q: np.ndarray, args: tuple) -> tuple[float, np.ndarray]:
    """Readable numpy version of the network energy and forces (vectorised over ligaments)."""
    ua, ub, lig = args.unit_a, args.unit_b, args.ligaments
    n = args.cos.shape[0]
    x, th = q[: 2 * n].reshape(2, n), q[2 * n : 3 * n]
    p = lig.T

    def rotated(unit, rx, ry):
        c, s = np.cos(th[unit]), np.sin(th[unit])
        return np.stack([c * rx - s * ry, s * rx + c * ry])

    pa, pb = rotated(ua, p[L_AX], p[L_AY]), rotated(ub, p[L_BX], p[L_BY])
    g = p[[L_OX, L_OY]] + x[:, ub] - x[:, ua] + pb - pa
    energies, grad, td, tm = law_reference(g, th[ub] - th[ua], 0.5 * (th[ua] + th[ub]), p, args.law)

    def cross(v, w):  # v·J w = v_y w_x − v_x w_y
        return v[1] * w[0] - v[0] * w[1]

    f = np.zeros(3 * n, np.result_type(q, lig))  # complex for a complex step
    for dim in range(2):
        np.add.at(f, dim * n + ua, grad[dim])
        np.add.at(f, dim * n + ub, -grad[dim])
    np.add.at(f, 2 * n + ua, cross(grad, pa) + td - 0.5 * tm)
    np.add.at(f, 2 * n + ub, -cross(grad, pb) - td - 0.5 * tm)
    e_c, f_c = uc.contacts_reference(q, n, args.contact_units, args.contacts)
    return float(np.sum(energies)) + e_c, f + f_c
