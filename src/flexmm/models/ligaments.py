"""Rigid units of any shape joined by ligaments at any of their points (docs/physics.md §1.9).

The general planar model of rigid units: unit i has DOFs (u_i, v_i, θ_i), field-major in q
(u block, v block, θ block), θ_i its rotation from the reference configuration. Ligament k joins
point r_a of unit a to point r_b of unit b (body-frame offsets from the units' centres in the
reference configuration) with three linear springs in its own frame (axis e, normal n = J e, J the
rotation by +90°):

    g  = o + (u_b − u_a, v_b − v_a) + R(θ_b) r_b − R(θ_a) r_a,
    E  = ½ k_l (g·e)² + ½ k_s (g·n)² + ½ k_θ (θ_b − θ_a)²,

where o = X_b − X_a − g0 is the ligament's rest offset (the centres' separation less the rest gap
between its two points, so g = 0 in a stress-free reference). The rotating squares and triangles of
§1.1–1.6 are this law on their hinge points (``tests/models/test_ligaments.py`` checks the forces
equal the lattices' own kernels).

With p = R(θ) r the rotated offsets and G = ∂E/∂g = k_l (g·e) e + k_s (g·n) n:

    ∂E/∂x_a = −G,   ∂E/∂x_b = G,   ∂E/∂θ_a = −G·J p_a − k_θ Δφ,   ∂E/∂θ_b = G·J p_b + k_θ Δφ,

and along a direction δq, with δg = δx_b − δx_a + δθ_b J p_b − δθ_a J p_a and K = k_l e eᵀ + k_s n nᵀ,
the Hessian-vector product

    δ(∂E/∂x_b) = K δg = −δ(∂E/∂x_a),
    δ(∂E/∂θ_b) = (K δg)·J p_b − δθ_b G·p_b + k_θ δΔφ,   δ(∂E/∂θ_a) = −(K δg)·J p_a + δθ_a G·p_a − k_θ δΔφ.

The law is written once (``ligament_gap``, ``ligament_law``, ``ligament_hvp``) and lifted over the
ligament table by ``network_force``, ``network_energy`` and ``network_hvp``; ``network_reference``
is the readable numpy version (the tests' oracle).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from flexmm._jit import fma, jit
from flexmm._trig import sincos

#: columns of the ligament table: offsets r_a, r_b, rest offset o, axis e, stiffnesses
(L_AX, L_AY, L_BX, L_BY, L_OX, L_OY, L_EX, L_EY, L_KL, L_KS, L_KT) = range(11)
N_LIGAMENT_PARAMS = 11


class NetworkArgs(NamedTuple):
    """What the network kernels read: ``unit_a``/``unit_b`` (L,) the joined units (int64),
    ``ligaments`` (L, N_LIGAMENT_PARAMS) their table, ``cos``/``sin`` (N,) scratch."""

    unit_a: np.ndarray
    unit_b: np.ndarray
    ligaments: np.ndarray
    cos: np.ndarray
    sin: np.ndarray


@jit
def rotate(c, s, x, y):
    """R(θ) (x, y) from c = cos θ, s = sin θ."""
    return fma(c, x, -(s * y)), fma(s, x, c * y)


@jit
def ligament_gap(q, n, a, b, prm, cs, sn):
    """(g_x, g_y, p_a, p_b, Δφ) of the ligament with row ``prm`` joining units a, b: its gap g, the
    rotated offsets p = R(θ) r of its two points (as (x, y) pairs) and θ_b − θ_a."""
    pax, pay = rotate(cs[a], sn[a], prm[L_AX], prm[L_AY])
    pbx, pby = rotate(cs[b], sn[b], prm[L_BX], prm[L_BY])
    gx = prm[L_OX] + (q[b] - q[a]) + (pbx - pax)
    gy = prm[L_OY] + (q[n + b] - q[n + a]) + (pby - pay)
    return gx, gy, pax, pay, pbx, pby, q[2 * n + b] - q[2 * n + a]


@jit
def ligament_law(gx, gy, dphi, prm):
    """(E, G_x, G_y, k_θ Δφ) of one ligament: its energy and ∂E/∂g, ∂E/∂Δφ."""
    ex, ey = prm[L_EX], prm[L_EY]
    el = fma(gx, ex, gy * ey)  # g·e
    es = fma(gy, ex, -(gx * ey))  # g·n, n = (−e_y, e_x)
    fl = prm[L_KL] * el
    fs = prm[L_KS] * es
    fp = prm[L_KT] * dphi
    energy = 0.5 * (fl * el + fs * es + fp * dphi)
    return energy, fma(fl, ex, -(fs * ey)), fma(fl, ey, fs * ex), fp


@jit
def ligament_hvp(gxd, gyd, ddphi, prm):
    """(K δg, k_θ δΔφ) of one ligament: the law's Hessian applied to (δg, δΔφ)."""
    _, kx, ky, kp = ligament_law(gxd, gyd, ddphi, prm)
    return kx, ky, kp


@jit
def network_angles(q, n, cs, sn):
    """cos/sin of every unit's rotation θ into cs, sn."""
    for i in range(n):
        s, c = sincos(q[2 * n + i])
        cs[i] = c
        sn[i] = s


@jit
def _network(q, args, out, want_force):
    """Energy of every ligament, and −∂E/∂q added to ``out`` when ``want_force``."""
    ua, ub, lig, cs, sn = args
    n = cs.shape[0]
    network_angles(q, n, cs, sn)
    total = 0.0
    for k in range(ua.shape[0]):
        a = ua[k]
        b = ub[k]
        prm = lig[k]
        gx, gy, pax, pay, pbx, pby, dphi = ligament_gap(q, n, a, b, prm, cs, sn)
        e, fx, fy, fp = ligament_law(gx, gy, dphi, prm)
        total += e
        if want_force:
            out[a] += fx
            out[n + a] += fy
            out[b] -= fx
            out[n + b] -= fy
            # ∂E/∂θ_a = −G·J p_a − k_θ Δφ, with G·J p = G_y p_x − G_x p_y
            out[2 * n + a] += fma(fy, pax, -(fx * pay)) + fp
            out[2 * n + b] -= fma(fy, pbx, -(fx * pby)) + fp
    return total


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
    """(δg_x, δg_y, δΔφ): the variation of the gap and of θ_b − θ_a along λ,
    δg = δx_b − δx_a + λ_θb J p_b − λ_θa J p_a with J p = (−p_y, p_x)."""
    ta, tb = lam[2 * n + a], lam[2 * n + b]
    wx = (lam[b] - lam[a]) - (tb * pby - ta * pay)
    wy = (lam[n + b] - lam[n + a]) + (tb * pbx - ta * pax)
    return wx, wy, tb - ta


@jit
def network_hvp(q, args, dq, out):
    """∇²E(q) dq of a ligament network into ``out`` (3N,): the Hessian-vector product the
    adjoint and tangent steps and the linear analysis need."""
    ua, ub, lig, cs, sn = args
    n = cs.shape[0]
    network_angles(q, n, cs, sn)
    for k in range(out.shape[0]):
        out[k] = 0.0
    for k in range(ua.shape[0]):
        a = ua[k]
        b = ub[k]
        prm = lig[k]
        gx, gy, pax, pay, pbx, pby, dphi = ligament_gap(q, n, a, b, prm, cs, sn)
        _, fx, fy, _ = ligament_law(gx, gy, dphi, prm)
        ta, tb = dq[2 * n + a], dq[2 * n + b]
        dgx, dgy, dphi_q = strain_variation(dq, n, a, b, pax, pay, pbx, pby)
        kx, ky, kp = ligament_hvp(dgx, dgy, dphi_q, prm)
        out[b] += kx
        out[n + b] += ky
        out[a] -= kx
        out[n + a] -= ky
        out[2 * n + b] += fma(ky, pbx, -(kx * pby)) - tb * fma(fx, pbx, fy * pby) + kp
        out[2 * n + a] -= fma(ky, pax, -(kx * pay)) - ta * fma(fx, pax, fy * pay) + kp


@jit
def network_adjoint(q, args, lam, out, g1, g2):
    """(∂F/∂q)ᵀλ = −∇²E λ added to ``out`` and (∂F/∂p)ᵀλ = −∂(λ·∇E)/∂p to g1 (the ligament table's
    gradient, (L, N_LIGAMENT_PARAMS); g2 unused). With w = δg along λ, K = k_l e eᵀ + k_s n nᵀ and
    G = K g: λ·∇E = gᵀK w + k_θ Δφ δΔφ, so ∂/∂o = K w, ∂/∂r_b = R(θ_b)ᵀ (K w − λ_θb J G),
    ∂/∂r_a = −R(θ_a)ᵀ (K w − λ_θa J G), ∂/∂k_l = (g·e)(w·e), ∂/∂k_s = (g·n)(w·n),
    ∂/∂k_θ = Δφ δΔφ, and ∂/∂e from e and n = (−e_y, e_x)."""
    ua, ub, lig, cs, sn = args
    n = cs.shape[0]
    hv = np.empty_like(out)
    network_hvp(q, args, lam, hv)  # also leaves cos/sin of θ in cs, sn
    for k in range(out.shape[0]):
        out[k] -= hv[k]
    for k in range(ua.shape[0]):
        a = ua[k]
        b = ub[k]
        prm = lig[k]
        gx, gy, pax, pay, pbx, pby, dphi = ligament_gap(q, n, a, b, prm, cs, sn)
        wx, wy, dl = strain_variation(lam, n, a, b, pax, pay, pbx, pby)
        _, fx, fy, _ = ligament_law(gx, gy, dphi, prm)
        kx, ky, _ = ligament_hvp(wx, wy, dl, prm)
        ex, ey = prm[L_EX], prm[L_EY]
        ge, gn = gx * ex + gy * ey, gy * ex - gx * ey
        we, wn = wx * ex + wy * ey, wy * ex - wx * ey
        kl, ks = prm[L_KL], prm[L_KS]
        ta, tb = lam[2 * n + a], lam[2 * n + b]
        # K w − λ_θ J G, J G = (−G_y, G_x), rotated back by R(θ)ᵀ
        xa, ya = kx + ta * fy, ky - ta * fx
        xb, yb = kx + tb * fy, ky - tb * fx
        ca, sa, cb, sb = cs[a], sn[a], cs[b], sn[b]
        g1[k, L_AX] += ca * xa + sa * ya
        g1[k, L_AY] += -sa * xa + ca * ya
        g1[k, L_BX] -= cb * xb + sb * yb
        g1[k, L_BY] -= -sb * xb + cb * yb
        g1[k, L_OX] -= kx
        g1[k, L_OY] -= ky
        g1[k, L_EX] -= kl * (gx * we + ge * wx) + ks * (gy * wn + gn * wy)
        g1[k, L_EY] -= kl * (gy * we + ge * wy) - ks * (gx * wn + gn * wx)
        g1[k, L_KL] -= ge * we
        g1[k, L_KS] -= gn * wn
        g1[k, L_KT] -= dphi * dl


@jit
def network_tangent(q, args, dq, d1, d2, out):
    """(∂F/∂q) dq + (∂F/∂p) dp into ``out``, dp = d1 the ligament table's direction (d2 unused):
    −∇²E dq − δ_p(∇E), the parameter variation of the gradient of ``_network`` term by term."""
    ua, ub, lig, cs, sn = args
    n = cs.shape[0]
    network_hvp(q, args, dq, out)  # also leaves cos/sin of θ in cs, sn
    for k in range(out.shape[0]):
        out[k] = -out[k]
    for k in range(ua.shape[0]):
        a = ua[k]
        b = ub[k]
        prm = lig[k]
        dp = d1[k]
        gx, gy, pax, pay, pbx, pby, dphi = ligament_gap(q, n, a, b, prm, cs, sn)
        _, fx, fy, _ = ligament_law(gx, gy, dphi, prm)
        # δg from the offsets: δo + R(θ_b) δr_b − R(θ_a) δr_a; δp of the rotated offsets
        dax, day = rotate(cs[a], sn[a], dp[L_AX], dp[L_AY])
        dbx, dby = rotate(cs[b], sn[b], dp[L_BX], dp[L_BY])
        dgx, dgy = dp[L_OX] + dbx - dax, dp[L_OY] + dby - day
        kx, ky, _ = ligament_hvp(dgx, dgy, 0.0, prm)
        # δK g: from the stiffnesses and the axis (n = (−e_y, e_x))
        ex, ey, dex, dey = prm[L_EX], prm[L_EY], dp[L_EX], dp[L_EY]
        ge, gn = gx * ex + gy * ey, gy * ex - gx * ey
        dge, dgn = gx * dex + gy * dey, gy * dex - gx * dey
        kl, ks = prm[L_KL], prm[L_KS]
        el = dp[L_KL] * ge + kl * dge
        es = dp[L_KS] * gn + ks * dgn
        dfx = kx + el * ex + kl * ge * dex - (es * ey + ks * gn * dey)
        dfy = ky + el * ey + kl * ge * dey + (es * ex + ks * gn * dex)
        dfp = dp[L_KT] * dphi
        out[a] += dfx
        out[n + a] += dfy
        out[b] -= dfx
        out[n + b] -= dfy
        # torques: δ(G·J p) = δG·J p + G·J δp
        out[2 * n + a] += fma(dfy, pax, -(dfx * pay)) + fma(fy, dax, -(fx * day)) + dfp
        out[2 * n + b] -= fma(dfy, pbx, -(dfx * pby)) + fma(fy, dbx, -(fx * dby)) + dfp


def network_pack(args) -> tuple[np.ndarray, np.ndarray]:
    """The differentiable tables of a network: its ligament table, and no second table."""
    return args.ligaments, np.zeros(0)


def network_unpack(args, t1: np.ndarray, t2: np.ndarray):
    """``args`` with its ligament table replaced."""
    return args._replace(ligaments=t1)


def network_reference(q: np.ndarray, args: tuple) -> tuple[float, np.ndarray]:
    """Readable numpy version of the network energy and forces (vectorised over ligaments)."""
    ua, ub, lig = args[0], args[1], args[2]
    n = args[3].shape[0]
    x, th = q[: 2 * n].reshape(2, n), q[2 * n : 3 * n]
    p = lig.T

    def rotated(unit, rx, ry):
        c, s = np.cos(th[unit]), np.sin(th[unit])
        return np.stack([c * rx - s * ry, s * rx + c * ry])

    pa, pb = rotated(ua, p[L_AX], p[L_AY]), rotated(ub, p[L_BX], p[L_BY])
    g = p[[L_OX, L_OY]] + x[:, ub] - x[:, ua] + pb - pa
    e, nrm = p[[L_EX, L_EY]], np.stack([-p[L_EY], p[L_EX]])
    el, es, dphi = np.sum(g * e, 0), np.sum(g * nrm, 0), th[ub] - th[ua]
    energy = 0.5 * float(np.sum(p[L_KL] * el**2 + p[L_KS] * es**2 + p[L_KT] * dphi**2))
    grad = p[L_KL] * el * e + p[L_KS] * es * nrm  # ∂E/∂g, (2, L)

    def cross(v, w):  # v·J w = v_y w_x − v_x w_y
        return v[1] * w[0] - v[0] * w[1]

    f = np.zeros(3 * n)
    for dim in range(2):
        np.add.at(f, dim * n + ua, grad[dim])
        np.add.at(f, dim * n + ub, -grad[dim])
    np.add.at(f, 2 * n + ua, cross(grad, pa) + p[L_KT] * dphi)
    np.add.at(f, 2 * n + ub, -cross(grad, pb) - p[L_KT] * dphi)
    return energy, f
