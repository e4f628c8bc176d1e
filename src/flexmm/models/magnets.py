"""Point dipoles fixed in rigid units: pair energies between neighbouring units (docs/physics.md §1.2).

Magnet k of unit i sits at X_i + R(φ_i) p_k with moment s_i R(φ_i) d_k (φ_i = σ_i(θ0_i + θ_i),
p_k, d_k in the unit's body frame, s_i the signed moment). Between units a and b,

    U = Σ_kl s_a s_b [ (m_k·m_l)/r³ − 3 (m_k·r)(m_l·r)/r⁵ ],   r = r_l − r_k,

in units where the prefactor μ0/(4π) is folded into s (nondimensional: s² = μ0 m²/(4π E a³)),
plus a core per magnet pair, for |r| < r_c (the faces carrying the magnets touch),

    U_core = (k_c r_c²/18) (x³ − 1)²,   x = r_c/|r|,

zero with zero slope at r_c, stiffness k_c there and ∝ |r|⁻⁶ inside, so it beats the r⁻³
attraction: a closing void stops, by rotation and by translation alike.
Exact gradient by the chain rule: ∂r/∂X = ∓1, ∂r/∂φ = ±J R p, ∂m/∂φ = J m (J the 90° rotation).

State layout (rigid-unit sheet): q = [u (N), v (N), θ (N)]. Pair table ``pab (P, 2)`` with rest
offsets ``off (P, 2)`` = X0_b − X0_a (periodic wraps use the short vector).
"""

from __future__ import annotations

import math

import numpy as np

from flexmm._jit import jit

MU0_OVER_4PI = 1e-7  # T m / A


def face_magnets(recess: float) -> tuple[np.ndarray, np.ndarray]:
    """Body-frame positions and outward unit normals of one magnet per face of a unit (a = 1).

    The unit's corners (hinge points) are (±½, 0), (0, ±½); face midpoints (±¼, ±¼); each
    magnet is ``recess`` inside its face. Returns ``(pos (4, 2), dirs (4, 2))``.
    """
    r2 = 1.0 / math.sqrt(2.0)
    dirs = np.array([[r2, r2], [-r2, r2], [-r2, -r2], [r2, -r2]])
    pos = 0.25 * np.sign(dirs) - recess * dirs
    return pos, dirs


def empty_dipoles(n_sites: int) -> tuple:
    """Dipole arguments with no magnets (the kernels then skip the term)."""
    return (np.zeros((0, 2), np.int64), np.zeros((0, 2)), np.zeros((0, 2)), np.zeros((0, 2)),
            np.zeros(n_sites), np.ones(n_sites), np.zeros(n_sites), np.zeros(2))


@jit
def _pair(rx, ry, m1x, m1y, m2x, m2y, rc, kc):
    """Dipole pair energy (prefactor 1) plus core, and gradients w.r.t. r, m1, m2."""
    r2 = rx * rx + ry * ry
    inv = 1.0 / math.sqrt(r2)
    i3 = inv * inv * inv
    i5 = i3 * inv * inv
    A = m1x * m2x + m1y * m2y
    B1 = m1x * rx + m1y * ry
    B2 = m2x * rx + m2y * ry
    e = A * i3 - 3.0 * B1 * B2 * i5
    c = -3.0 * A * i5 + 15.0 * B1 * B2 * i5 * inv * inv
    grx = c * rx - 3.0 * (m1x * B2 + m2x * B1) * i5
    gry = c * ry - 3.0 * (m1y * B2 + m2y * B1) * i5
    x = rc * inv
    if x > 1.0:
        x3 = x * x * x
        e += kc * rc * rc * (x3 - 1.0) ** 2 / 18.0
        dr = -kc * rc * (x3 - 1.0) * x3 * x / 3.0  # dU_core/d|r|
        grx += dr * rx * inv
        gry += dr * ry * inv
    g1x = m2x * i3 - 3.0 * B2 * rx * i5
    g1y = m2y * i3 - 3.0 * B2 * ry * i5
    g2x = m1x * i3 - 3.0 * B1 * rx * i5
    g2y = m1y * i3 - 3.0 * B1 * ry * i5
    return e, grx, gry, g1x, g1y, g2x, g2y


@jit
def dipole_terms(q, dip, out, want_force):
    """Add −∂U/∂q of all magnet pairs to ``out`` (if ``want_force``); return U.

    ``dip`` = (pab (P, 2), off (P, 2), pos (M, 2), dirs (M, 2), theta0 (N,), sigma (N,), s (N,),
    core (2,) = r_c, k_c).
    """
    pab, off, pos, dirs, theta0, sig, s, core = dip
    n = theta0.shape[0]
    total = 0.0
    for p in range(pab.shape[0]):
        a = pab[p, 0]
        b = pab[p, 1]
        pa = sig[a] * (theta0[a] + q[2 * n + a])
        pb = sig[b] * (theta0[b] + q[2 * n + b])
        ca, sa, cb, sb = math.cos(pa), math.sin(pa), math.cos(pb), math.sin(pb)
        dx = off[p, 0] + q[b] - q[a]
        dy = off[p, 1] + q[n + b] - q[n + a]
        fa = 0.0
        fb = 0.0
        gx = 0.0
        gy = 0.0
        for k in range(pos.shape[0]):
            # magnet k of a: position R_a p_k, moment s_a R_a d_k
            pkx = ca * pos[k, 0] - sa * pos[k, 1]
            pky = sa * pos[k, 0] + ca * pos[k, 1]
            m1x = s[a] * (ca * dirs[k, 0] - sa * dirs[k, 1])
            m1y = s[a] * (sa * dirs[k, 0] + ca * dirs[k, 1])
            for l in range(pos.shape[0]):
                plx = cb * pos[l, 0] - sb * pos[l, 1]
                ply = sb * pos[l, 0] + cb * pos[l, 1]
                m2x = s[b] * (cb * dirs[l, 0] - sb * dirs[l, 1])
                m2y = s[b] * (sb * dirs[l, 0] + cb * dirs[l, 1])
                e, grx, gry, g1x, g1y, g2x, g2y = _pair(dx + plx - pkx, dy + ply - pky, m1x, m1y, m2x, m2y,
                                                        core[0], core[1])
                total += e
                if want_force:
                    gx += grx
                    gy += gry
                    # dr/dφa = −J R_a p_k = (pky, −pkx); dm1/dφa = J m1 = (−m1y, m1x)
                    fa += grx * pky - gry * pkx - g1x * m1y + g1y * m1x
                    # dr/dφb = J R_b p_l = (−ply, plx); dm2/dφb = (−m2y, m2x)
                    fb += -grx * ply + gry * plx - g2x * m2y + g2y * m2x
        if want_force:
            out[a] += gx
            out[b] -= gx
            out[n + a] += gy
            out[n + b] -= gy
            out[2 * n + a] -= sig[a] * fa
            out[2 * n + b] -= sig[b] * fb
    return total


def dipole_reference(q: np.ndarray, dip: tuple) -> tuple[float, np.ndarray]:
    """Numpy version of ``dipole_terms`` (vectorised over pairs and magnets), for the tests."""
    pab, off, pos, dirs, theta0, sig, s, (rc, kc) = dip
    n = theta0.size
    f = np.zeros_like(q)
    if pab.shape[0] == 0:
        return 0.0, f
    a, b = pab[:, 0], pab[:, 1]
    th = q[2 * n : 3 * n]
    phi = sig * (theta0 + th)

    def rot(ang, v):  # (P,), (M, 2) -> (P, M, 2)
        c, s_ = np.cos(ang)[:, None], np.sin(ang)[:, None]
        return np.stack([c * v[None, :, 0] - s_ * v[None, :, 1], s_ * v[None, :, 0] + c * v[None, :, 1]], -1)

    def jrot(v):  # 90° rotation of (..., 2)
        return np.stack([-v[..., 1], v[..., 0]], -1)

    Pa, Pb = rot(phi[a], pos), rot(phi[b], pos)
    Ma, Mb = s[a, None, None] * rot(phi[a], dirs), s[b, None, None] * rot(phi[b], dirs)
    d = off + np.stack([q[b] - q[a], q[n + b] - q[n + a]], -1)
    r = d[:, None, None, :] + Pb[:, None, :, :] - Pa[:, :, None, :]  # (P, Ma, Mb, 2)
    m1, m2 = Ma[:, :, None, :], Mb[:, None, :, :]
    rn = np.linalg.norm(r, axis=-1)
    A = np.sum(m1 * m2, -1)
    B1, B2 = np.sum(m1 * r, -1), np.sum(m2 * r, -1)
    x = np.maximum(rc / rn, 1.0)
    energy = float(np.sum(A / rn**3 - 3 * B1 * B2 / rn**5 + kc * rc**2 * (x**3 - 1) ** 2 / 18))
    dcore = -kc * rc * (x**3 - 1) * x**4 / 3
    gr = ((-3 * A / rn**5 + 15 * B1 * B2 / rn**7 + dcore / rn)[..., None] * r
          - 3 * (m1 * B2[..., None] + m2 * B1[..., None]) / rn[..., None] ** 5)
    g1 = m2 / rn[..., None] ** 3 - 3 * B2[..., None] * r / rn[..., None] ** 5
    g2 = m1 / rn[..., None] ** 3 - 3 * B1[..., None] * r / rn[..., None] ** 5
    g = gr.sum((1, 2))
    dphia = np.sum(gr * -jrot(Pa[:, :, None, :]), (1, 2, 3)) + np.sum(g1 * jrot(m1), (1, 2, 3))
    dphib = np.sum(gr * jrot(Pb[:, None, :, :]), (1, 2, 3)) + np.sum(g2 * jrot(m2), (1, 2, 3))
    np.add.at(f, a, g[:, 0])
    np.add.at(f, b, -g[:, 0])
    np.add.at(f, n + a, g[:, 1])
    np.add.at(f, n + b, -g[:, 1])
    np.add.at(f, 2 * n + a, -sig[a] * dphia)
    np.add.at(f, 2 * n + b, -sig[b] * dphib)
    return energy, f
