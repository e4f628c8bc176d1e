"""Second derivatives of the extra terms of the rigid-unit models, and their parameter tables.

Element kernels that ``design.kernels`` combines with its hinge kernels into the adjoint and
tangent kernels (``kernels.model_adjoint``/``model_tangent``) of:

- the rotating-squares sheet with all its terms (``SheetArgs``, ``kernels.sheet_full_adjoint``):
  hinges plus point dipoles (``models.magnets``: ``dipoles_second``), bistable joints
  (``models.joints``: ``joints_adjoint``) and constant loads (``models.loads``: ``loads_adjoint``);
- the loaded rotating-squares chain (``LoadedChainArgs``, ``models.predeform``): the chain's
  kernels plus constant loads;
- independent harmonic oscillators (``HarmonicArgs``: ``harmonic_adjoint``, here in full).

Each element's second derivatives are the directional derivative of its gradient (forward
mode, written by hand from the closed-form law): along a direction (δq, δp), the change δG_q of
∂E/∂q and δG_p of ∂E/∂p. The tangent of the force is −δG_q; by the symmetry of second
derivatives the adjoint products along λ are the same with δq = λ, δp = 0: (∂F/∂q)ᵀλ = −δG_q and
(∂F/∂p)ᵀλ = −∂(λ·∇_q E)/∂p = −δG_p.

Parameter tables (``gradient.Raw.t1``, ``t2``; the ``*_pack``/``*_unpack`` functions below):

- sheet: t1 the hinge table (H, 7); t2 one vector: θ0 (N), then, when present, the dipoles'
  signed moments s (N), their core (r_c, k_c), the pairs' rest offsets (P × 2, row-major) and
  the magnets' body-frame positions (M × 2, shared by the units: the recess), the joints'
  (k, β, ψ*) (J × 3), the loads' values (L) (``sheet_layout``). Without dipoles, joints or loads
  t2 is θ0, as for the hinge-only sheet. Not differentiated: the magnets' directions (the faces'
  normals) and the checkerboard signs.
- loaded chain: t1 the hinge table; t2 the site table (N × 3, row-major) then the loads' values.
- harmonic: t1 the stiffnesses, t2 empty.
"""

from __future__ import annotations

import math

import numpy as np

from flexmm._jit import jit
from flexmm._trig import sincos
from flexmm.models.harmonic import HarmonicArgs
from flexmm.models.loads import LoadedChainArgs
from flexmm.models.sheet_kernels import SheetArgs

# ---------------------------------------------------------------- constant loads


@jit
def loads_adjoint(loads, lam, g, off):
    """E = −Σ f q[dof]: no Hessian; ∂F[dof]/∂f = 1, so g[off + k] += λ[dof_k]."""
    dof = loads[0]
    for k in range(dof.shape[0]):
        g[off + k] += lam[dof[k]]


@jit
def loads_tangent(loads, d, off, out):
    dof = loads[0]
    for k in range(dof.shape[0]):
        out[dof[k]] += d[off + k]


# ---------------------------------------------------------------- bistable joints


@jit
def _joint_second(t, jp, ja, jb, j):
    """Units a, b of joint j (unsigned), V''(ψ) and ∂V'/∂(k, β, ψ*) of its law
    V'(ψ) = k ψ (ψ − βψ*)(ψ − ψ*) at ψ = t[a] + t[b] (t: the rotations; jp: the (k, β, ψ*) rows
    flattened)."""
    a = np.uint64(ja[j])
    b = np.uint64(jb[j])
    psi = t[a] + t[b]
    k, beta, ps = jp[3 * j], jp[3 * j + 1], jp[3 * j + 2]
    u = psi - beta * ps
    w = psi - ps
    return a, b, k * (u * w + psi * w + psi * u), psi * u * w, -k * psi * ps * w, -k * psi * (beta * w + u)


@jit
def joints_adjoint(q, n, joints, lam, out, g, off):
    """ψ = θ_a + θ_b: (∂F/∂θ)ᵀλ = −V''(ψ) (λ_a + λ_b) at both units, −∂V'/∂p (λ_a + λ_b) into g."""
    ja, jb, jp, gj = joints[0], joints[1], joints[2].ravel(), g[off:]
    t, lt, ot = q[2 * n : 3 * n], lam[2 * n : 3 * n], out[2 * n : 3 * n]
    for j in range(ja.shape[0]):
        a, b, v2, dk, db, dps = _joint_second(t, jp, ja, jb, j)
        lp = lt[a] + lt[b]
        ot[a] -= v2 * lp
        ot[b] -= v2 * lp
        gj[3 * j] -= dk * lp
        gj[3 * j + 1] -= db * lp
        gj[3 * j + 2] -= dps * lp


@jit
def joints_tangent(q, n, joints, dq, d, off, out):
    """−(V''(ψ) (δθ_a + δθ_b) + ∂V'/∂p · δp) added at both units (δp: d[off:], the joints' rows)."""
    ja, jb, jp, dj = joints[0], joints[1], joints[2].ravel(), d[off:]
    t, dt, ot = q[2 * n : 3 * n], dq[2 * n : 3 * n], out[2 * n : 3 * n]
    for j in range(ja.shape[0]):
        a, b, v2, dk, db, dps = _joint_second(t, jp, ja, jb, j)
        dv = v2 * (dt[a] + dt[b]) + dk * dj[3 * j] + db * dj[3 * j + 1] + dps * dj[3 * j + 2]
        ot[a] -= dv
        ot[b] -= dv


# ---------------------------------------------------------------- point dipoles


@jit
def _pair_second(rx, ry, drx, dry, m1x, m1y, dm1x, dm1y, m2x, m2y, dm2x, dm2y, rc, drc, kc, dkc, res):
    """``magnets._pair``'s gradient and its directional derivative along (δr, δm1, δm2, δr_c, δk_c).

    ``res`` (16,) gets: g_r (2), g_1 (2), g_2 (2), ∂E/∂r_c, ∂E/∂k_c, then the directional
    derivatives of those eight in the same order.
    """
    r2 = rx * rx + ry * ry
    inv = 1.0 / math.sqrt(r2)
    i3 = inv * inv * inv
    i5 = i3 * inv * inv
    i7 = i5 * inv * inv
    i9 = i7 * inv * inv
    rho = rx * drx + ry * dry  # r·δr
    d_inv = -i3 * rho
    d_i3 = -3.0 * i5 * rho
    d_i5 = -5.0 * i7 * rho
    d_i7 = -7.0 * i9 * rho
    A = m1x * m2x + m1y * m2y
    B1 = m1x * rx + m1y * ry
    B2 = m2x * rx + m2y * ry
    dA = dm1x * m2x + dm1y * m2y + m1x * dm2x + m1y * dm2y
    dB1 = dm1x * rx + dm1y * ry + m1x * drx + m1y * dry
    dB2 = dm2x * rx + dm2y * ry + m2x * drx + m2y * dry
    c = -3.0 * A * i5 + 15.0 * B1 * B2 * i7
    dc = -3.0 * (dA * i5 + A * d_i5) + 15.0 * ((dB1 * B2 + B1 * dB2) * i7 + B1 * B2 * d_i7)
    wx = m1x * B2 + m2x * B1
    wy = m1y * B2 + m2y * B1
    dwx = dm1x * B2 + m1x * dB2 + dm2x * B1 + m2x * dB1
    dwy = dm1y * B2 + m1y * dB2 + dm2y * B1 + m2y * dB1
    res[0] = c * rx - 3.0 * wx * i5
    res[1] = c * ry - 3.0 * wy * i5
    res[8] = dc * rx + c * drx - 3.0 * (dwx * i5 + wx * d_i5)
    res[9] = dc * ry + c * dry - 3.0 * (dwy * i5 + wy * d_i5)
    res[2] = m2x * i3 - 3.0 * B2 * rx * i5
    res[3] = m2y * i3 - 3.0 * B2 * ry * i5
    res[10] = dm2x * i3 + m2x * d_i3 - 3.0 * ((dB2 * rx + B2 * drx) * i5 + B2 * rx * d_i5)
    res[11] = dm2y * i3 + m2y * d_i3 - 3.0 * ((dB2 * ry + B2 * dry) * i5 + B2 * ry * d_i5)
    res[4] = m1x * i3 - 3.0 * B1 * rx * i5
    res[5] = m1y * i3 - 3.0 * B1 * ry * i5
    res[12] = dm1x * i3 + m1x * d_i3 - 3.0 * ((dB1 * rx + B1 * drx) * i5 + B1 * rx * d_i5)
    res[13] = dm1y * i3 + m1y * d_i3 - 3.0 * ((dB1 * ry + B1 * dry) * i5 + B1 * ry * d_i5)
    res[6] = res[7] = res[14] = res[15] = 0.0
    x = rc * inv
    if x > 1.0:  # the core (kc rc²/18)(x³ − 1)², x = r_c/|r|
        x3 = x * x * x
        dx = drc * inv + rc * d_inv
        dr_ = -kc * rc * (x3 - 1.0) * x3 * x / 3.0  # dU_core/d|r|
        ddr = -(dkc * rc + kc * drc) * (x3 - 1.0) * x3 * x / 3.0 - kc * rc * (7.0 * x3 - 4.0) * x3 * dx / 3.0
        res[0] += dr_ * rx * inv
        res[1] += dr_ * ry * inv
        res[8] += (ddr * inv + dr_ * d_inv) * rx + dr_ * inv * drx
        res[9] += (ddr * inv + dr_ * d_inv) * ry + dr_ * inv * dry
        res[6] = kc * rc * (x3 - 1.0) * (4.0 * x3 - 1.0) / 9.0
        res[14] = ((dkc * rc + kc * drc) * (x3 - 1.0) * (4.0 * x3 - 1.0)
                   + kc * rc * x * x * (24.0 * x3 - 15.0) * dx) / 9.0
        res[7] = rc * rc * (x3 - 1.0) ** 2 / 18.0
        res[15] = rc * (x3 - 1.0) * (drc * (x3 - 1.0) + 3.0 * rc * x * x * dx) / 9.0


@jit
def dipoles_second(q, dip, n, dq, d, o_s, o_core, o_off, o_pos, tangent, out, g):
    """The dipole pairs' second derivatives along δq = ``dq`` and (tangent only) the parameter
    direction ``d`` (the sheet's t2 vector): −δG_q added to ``out``; unless ``tangent``, −δG_p
    added to ``g`` (θ0 at 0, moments at o_s, core at o_core, offsets at o_off, the magnets'
    body-frame positions at o_pos)."""
    pab, off, pos, dirs, theta0, sig, s, core = dip
    rc, kc = core[0], core[1]
    drc = d[o_core] if tangent else 0.0
    dkc = d[o_core + 1] if tangent else 0.0
    res = np.empty(16)
    for p in range(pab.shape[0]):
        a = pab[p, 0]
        b = pab[p, 1]
        sga, sgb = sig[a], sig[b]
        pa = sga * (theta0[a] + q[2 * n + a])
        pb = sgb * (theta0[b] + q[2 * n + b])
        ca, sa, cb, sb = math.cos(pa), math.sin(pa), math.cos(pb), math.sin(pb)
        dx = off[p, 0] + q[b] - q[a]
        dy = off[p, 1] + q[n + b] - q[n + a]
        ddx = dq[b] - dq[a]
        ddy = dq[n + b] - dq[n + a]
        dpa = sga * dq[2 * n + a]
        dpb = sgb * dq[2 * n + b]
        dsa = dsb = 0.0
        if tangent:
            ddx += d[o_off + 2 * p]
            ddy += d[o_off + 2 * p + 1]
            dpa += sga * d[a]
            dpb += sgb * d[b]
            dsa = d[o_s + a]
            dsb = d[o_s + b]
        s_a, s_b = s[a], s[b]
        # δ of ∂E/∂d (x, y), ∂E/∂φa, ∂E/∂φb, ∂E/∂s_a, ∂E/∂s_b, ∂E/∂r_c, ∂E/∂k_c
        gdx = gdy = gfa = gfb = gsa = gsb = grc = gkc = 0.0
        for k in range(pos.shape[0]):
            pkx = ca * pos[k, 0] - sa * pos[k, 1]  # R_a p_k
            pky = sa * pos[k, 0] + ca * pos[k, 1]
            ukx = ca * dirs[k, 0] - sa * dirs[k, 1]  # R_a d_k
            uky = sa * dirs[k, 0] + ca * dirs[k, 1]
            m1x, m1y = s_a * ukx, s_a * uky
            # δ(R_a p_k) = J R_a p_k δφa; δm1 = δs_a R_a d_k + J m1 δφa
            epkx = epky = 0.0  # R_a δp_k
            if tangent:
                epkx = ca * d[o_pos + 2 * k] - sa * d[o_pos + 2 * k + 1]
                epky = sa * d[o_pos + 2 * k] + ca * d[o_pos + 2 * k + 1]
            dpkx, dpky = -pky * dpa + epkx, pkx * dpa + epky
            dm1x = dsa * ukx - m1y * dpa
            dm1y = dsa * uky + m1x * dpa
            for l in range(pos.shape[0]):
                plx = cb * pos[l, 0] - sb * pos[l, 1]
                ply = sb * pos[l, 0] + cb * pos[l, 1]
                ulx = cb * dirs[l, 0] - sb * dirs[l, 1]
                uly = sb * dirs[l, 0] + cb * dirs[l, 1]
                m2x, m2y = s_b * ulx, s_b * uly
                eplx = eply = 0.0
                if tangent:
                    eplx = cb * d[o_pos + 2 * l] - sb * d[o_pos + 2 * l + 1]
                    eply = sb * d[o_pos + 2 * l] + cb * d[o_pos + 2 * l + 1]
                dplx, dply = -ply * dpb + eplx, plx * dpb + eply
                dm2x = dsb * ulx - m2y * dpb
                dm2y = dsb * uly + m2x * dpb
                _pair_second(dx + plx - pkx, dy + ply - pky, ddx + dplx - dpkx, ddy + dply - dpky,
                             m1x, m1y, dm1x, dm1y, m2x, m2y, dm2x, dm2y, rc, drc, kc, dkc, res)
                grx, gry, g1x, g1y, g2x, g2y = res[0], res[1], res[2], res[3], res[4], res[5]
                hrx, hry, h1x, h1y, h2x, h2y = res[8], res[9], res[10], res[11], res[12], res[13]
                gdx += hrx
                gdy += hry
                # ∂E/∂φa = g_r·(−J P_k) + g_1·(J m1); J v = (−v_y, v_x)
                gfa += (hrx * pky - hry * pkx + grx * pkx * dpa + gry * pky * dpa + grx * epky - gry * epkx
                        - h1x * m1y + h1y * m1x + (-g1x * uky + g1y * ukx) * dsa - (g1x * m1x + g1y * m1y) * dpa)
                gfb += (-hrx * ply + hry * plx - grx * plx * dpb - gry * ply * dpb - grx * eply + gry * eplx
                        - h2x * m2y + h2y * m2x + (-g2x * uly + g2y * ulx) * dsb - (g2x * m2x + g2y * m2y) * dpb)
                gsa += h1x * ukx + h1y * uky + (-g1x * uky + g1y * ukx) * dpa
                gsb += h2x * ulx + h2y * uly + (-g2x * uly + g2y * ulx) * dpb
                grc += res[14]
                gkc += res[15]
                if not tangent:  # ∂E/∂p_k = −R_aᵀ g_r, ∂E/∂p_l = R_bᵀ g_r (δR = J R δφ)
                    wx, wy = -gry * dpa - hrx, grx * dpa - hry
                    g[o_pos + 2 * k] -= ca * wx + sa * wy
                    g[o_pos + 2 * k + 1] -= -sa * wx + ca * wy
                    wx, wy = hrx + gry * dpb, hry - grx * dpb
                    g[o_pos + 2 * l] -= cb * wx + sb * wy
                    g[o_pos + 2 * l + 1] -= -sb * wx + cb * wy
        out[a] += gdx
        out[b] -= gdx
        out[n + a] += gdy
        out[n + b] -= gdy
        out[2 * n + a] -= sga * gfa
        out[2 * n + b] -= sgb * gfb
        if not tangent:
            g[a] -= sga * gfa
            g[b] -= sgb * gfb
            g[o_s + a] -= gsa
            g[o_s + b] -= gsb
            g[o_core] -= grc
            g[o_core + 1] -= gkc
            g[o_off + 2 * p] -= gdx
            g[o_off + 2 * p + 1] -= gdy


# ---------------------------------------------------------------- the sheet with all its terms


@jit
def sheet_layout(n, npairs, nmagnets, njoints, nloads):
    """Offsets in the sheet's t2 vector: (moments, core, offsets, positions, joints, loads, length)."""
    o = n
    o_s = o_core = o_off = o_pos = o
    if npairs > 0:
        o_s = o
        o_core = o + n
        o_off = o + n + 2
        o_pos = o_off + 2 * npairs
        o = o_pos + 2 * nmagnets
    o_j = o
    o_l = o_j + 3 * njoints
    return o_s, o_core, o_off, o_pos, o_j, o_l, o_l + nloads


@jit
def sheet_offsets(args):
    """(N, offsets of ``sheet_layout``) of a sheet's args."""
    n = args.theta0.shape[0]
    return (n,) + sheet_layout(n, args.dipoles[0].shape[0], args.dipoles[2].shape[0], args.joints[0].shape[0],
                               args.loads[0].shape[0])


def sheet_pack(args: SheetArgs) -> tuple[np.ndarray, np.ndarray]:
    """(hinge table, t2 vector) of a sheet (``sheet_layout``)."""
    pab, off, pos, _, _, _, s, core = args.dipoles
    parts = [args.theta0]
    if pab.shape[0]:
        parts += [s, core, off.ravel(), pos.ravel()]
    parts += [args.joints[2].ravel(), args.loads[1]]
    return args.hinge_prm, np.concatenate(parts).astype(float)


def sheet_unpack(args: SheetArgs, t1: np.ndarray, t2: np.ndarray) -> SheetArgs:
    """A copy of a sheet's args with its tables replaced (θ0 also the dipoles' copy of it)."""
    n = args.theta0.shape[0]
    pab, off, pos, dirs, _, sig, s, core = args.dipoles
    ja, jb, jp = args.joints
    dof = args.loads[0]
    o_s, o_core, o_off, o_pos, o_j, o_l, size = sheet_layout(n, pab.shape[0], pos.shape[0], ja.shape[0], dof.shape[0])
    if t2.shape != (size,):
        raise ValueError(f"sheet parameter vector of shape {t2.shape}, expected ({size},)")
    theta0 = np.ascontiguousarray(t2[:n])
    if pab.shape[0]:
        s = t2[o_s:o_core].copy()
        core = t2[o_core:o_off].copy()
        off = t2[o_off:o_pos].reshape(off.shape).copy()
        pos = t2[o_pos:o_j].reshape(pos.shape).copy()
    dip = (pab, off, pos, dirs, theta0, sig, s, core)
    joints = (ja, jb, t2[o_j:o_l].reshape(jp.shape).copy())
    return args._replace(hinge_prm=t1, theta0=theta0, dipoles=dip, joints=joints, loads=(dof, t2[o_l:].copy()))


# ---------------------------------------------------------------- loaded chain


def loaded_chain_pack(args: LoadedChainArgs) -> tuple[np.ndarray, np.ndarray]:
    return args.chain.hinge_prm, np.concatenate([args.chain.site_prm.ravel(), args.loads[1]]).astype(float)


def loaded_chain_unpack(args: LoadedChainArgs, t1: np.ndarray, t2: np.ndarray) -> LoadedChainArgs:
    sprm = args.chain.site_prm
    if t2.shape != (sprm.size + args.loads[1].size,):
        raise ValueError(f"loaded-chain parameter vector of shape {t2.shape}, expected "
                         f"({sprm.size + args.loads[1].size},)")
    chain = args.chain._replace(hinge_prm=t1, site_prm=t2[: sprm.size].reshape(sprm.shape).copy())
    return LoadedChainArgs(chain, (args.loads[0], t2[sprm.size :].copy()))


# ---------------------------------------------------------------- rigid units' helpers


@jit
def unit_angles(q, theta0, cs, sn):
    """cos/sin of θ0 + θ of every unit into cs, sn (one loop: vectorised ``_trig.sincos``)."""
    n = theta0.shape[0]
    for i in range(n):
        s, c = sincos(theta0[i] + q[2 * n + i])
        cs[i] = c
        sn[i] = s


@jit
def add_to_ends(o_l, o_s, o_t, la, lb, sa, sb, ta, tb, fl, fs, ga, gb):
    """A hinge's derivatives (fl, fs, ga, gb) along (d_l, d_s, θ_A, θ_B), negated, on its units'
    DOFs: +fl at o_l[la], −fl at o_l[lb], +fs at o_s[sa], −fs at o_s[sb], −ga at o_t[ta], −gb at
    o_t[tb] (d_l = x_B − x_A along the axis, d_s across; the sheet's hinges pass ``out`` thrice
    with DOF indices)."""
    o_l[la] += fl
    o_l[lb] -= fl
    o_s[sa] += fs
    o_s[sb] -= fs
    o_t[ta] -= ga
    o_t[tb] -= gb


# ---------------------------------------------------------------- harmonic oscillators


@jit
def harmonic_adjoint(q, args, lam, out, g1, g2):
    """F_k = −k_k q_k: (∂F/∂q)ᵀλ = −k λ, (∂F/∂k)ᵀλ = −q λ."""
    k = args.stiffness
    for i in range(q.shape[0]):
        out[i] -= k[i] * lam[i]
        g1[i] -= q[i] * lam[i]


@jit
def harmonic_tangent(q, args, dq, d1, d2, out):
    k = args.stiffness
    for i in range(q.shape[0]):
        out[i] = -(k[i] * dq[i] + d1[i] * q[i])


def harmonic_pack(args: HarmonicArgs) -> tuple[np.ndarray, np.ndarray]:
    return args.stiffness, np.zeros(0)


def harmonic_unpack(args: HarmonicArgs, t1: np.ndarray, t2: np.ndarray) -> HarmonicArgs:
    return HarmonicArgs(t1)
