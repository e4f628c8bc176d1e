"""Energy-based contact between rigid units that share a pore (docs/physics.md §1.9).

A contact pair is a vertex P of unit p and an edge E0E1 of unit e (body-frame offsets r_P, r_0,
r_1 from the units' centres; D = X_p − X_e the centres' rest separation). With d the distance
from P to the segment,

    w = D + x_p − x_e + R(θ_p) r_P − R(θ_e) r_0,   s = R(θ_e)(r_1 − r_0),
    t = clamp(w·s / s·s, 0, 1),   δ = w − t s,   d = |δ|,

the pair stores the energy

    E(d) = ½ k (c − d)³ / d   for d < c,   0 for d ≥ c,

a barrier with cutoff c and stiffness −dF/dd = E''(d) = k[(c/d)³ − 1]: zero at the cutoff
(energy, force and stiffness are continuous there, so an integrator sees a smooth law), k at
d = 2^(−1/3) c, 7k at c/2, and unbounded as d → 0, so the vertex never crosses the edge. The
force F = E'(d) δ/d acts on P and −F on the edge at its closest point (the envelope theorem:
t's own variation does not enter the gradient), so
∂E/∂x_p = F, ∂E/∂x_e = −F, ∂E/∂θ_p = F·J p_P, ∂E/∂θ_e = −F·J(p_0 + t s), p = R(θ) r.

The pairs come from the topology (``contact_pairs``): a ligament joining vertex i of unit A to
vertex j of unit B bounds two pores, one on each side, and on each side the two edges that meet
the ligament face each other across that pore (A's edge i→i+1 and B's edge j−1→j on one side,
A's i−1→i and B's j→j+1 on the other, polygons counter-clockwise). As the pore closes those edges
turn towards each other about the ligament, so each edge's far vertex approaches the other edge:
the pairs are (A_{i+1}, B's edge), (B_{j−1}, A's edge) and the same on the other side. The joined
vertices themselves are held by the ligament and are not pairs. Pairs are fixed at build.

``contacts``, ``contacts_hvp``, ``contacts_adjoint`` and ``contacts_tangent`` are added inside the
network's kernels (``flexmm.models.ligaments``); the contact table is the network's second
parameter table. ``contacts_reference`` is the numpy version.
"""

from __future__ import annotations

import math

import numpy as np

from flexmm._jit import fma, jit
from flexmm.errors import FlexmmError

#: columns of the contact table: vertex offset r_P, edge offsets r_0, r_1, rest separation D, k, c
(C_PX, C_PY, C_0X, C_0Y, C_1X, C_1Y, C_DX, C_DY, C_K, C_CUT) = range(10)
N_CONTACT_PARAMS = 10
#: no contact pairs (the default of a network's contact tables)
NO_PAIRS = np.zeros((0, 2), np.int64)
NO_CONTACTS = np.zeros((0, N_CONTACT_PARAMS))


class ContactError(FlexmmError, ValueError):
    """A contact law that the built geometry contradicts (units already inside the cutoff at rest)."""


@jit
def barrier(d, k, c):
    """(E, E', E'') of the contact law at distance d (zero beyond the cutoff c)."""
    if d >= c:
        return 0.0, 0.0, 0.0
    gap = c - d
    e = 0.5 * k * gap * gap * gap / d
    de = -0.5 * k * gap * gap * (c + 2.0 * d) / (d * d)
    ratio = c / d
    return e, de, k * (ratio * ratio * ratio - 1.0)


@jit
def _turn(c, s, x, y):
    return fma(c, x, -(s * y)), fma(s, x, c * y)


@jit
def pair_frame(q, n, cs, sn, iv, ie, prm):
    """(p_P, p_0, s, w, t, inside, δ, d²) of one pair: the rotated offsets of the vertex and the
    edge's start, the edge vector, the vertex relative to the edge's start, the closest point's
    parameter (and whether it lies strictly inside the edge), the separation and its squared length."""
    ppx, ppy = _turn(cs[iv], sn[iv], prm[C_PX], prm[C_PY])
    p0x, p0y = _turn(cs[ie], sn[ie], prm[C_0X], prm[C_0Y])
    p1x, p1y = _turn(cs[ie], sn[ie], prm[C_1X], prm[C_1Y])
    sx, sy = p1x - p0x, p1y - p0y
    wx = prm[C_DX] + (q[iv] - q[ie]) + (ppx - p0x)
    wy = prm[C_DY] + (q[n + iv] - q[n + ie]) + (ppy - p0y)
    t = (wx * sx + wy * sy) / (sx * sx + sy * sy)
    inside = 0.0 < t < 1.0
    t = min(max(t, 0.0), 1.0)
    dx, dy = wx - t * sx, wy - t * sy
    return ppx, ppy, p0x, p0y, sx, sy, wx, wy, t, inside, dx, dy, dx * dx + dy * dy


@jit
def contacts(q, n, cs, sn, units, table, out, want_force):
    """Energy of the contact pairs, and −∂E/∂q added to ``out`` when ``want_force`` (cs, sn: the
    units' cos/sin θ)."""
    total = 0.0
    for c in range(units.shape[0]):
        prm = table[c]
        iv, ie = units[c, 0], units[c, 1]
        ppx, ppy, p0x, p0y, sx, sy, _, _, t, _, dx, dy, d2 = pair_frame(q, n, cs, sn, iv, ie, prm)
        if d2 >= prm[C_CUT] * prm[C_CUT]:
            continue
        d = math.sqrt(d2)
        e, de, _ = barrier(d, prm[C_K], prm[C_CUT])
        total += e
        if want_force:
            fx, fy = de * dx / d, de * dy / d
            out[iv] -= fx
            out[n + iv] -= fy
            out[ie] += fx
            out[n + ie] += fy
            # F·J p = F_y p_x − F_x p_y
            out[2 * n + iv] -= fy * ppx - fx * ppy
            out[2 * n + ie] += fy * (p0x + t * sx) - fx * (p0y + t * sy)
    return total


@jit
def pair_second(nx, ny, d, de, dde, t, inside, wx, wy, sx, sy, dwx, dwy, dsx, dsy):
    """(δF_w, δF_s) of one pair: the Hessian of its energy in (w, s) applied to (δw, δs). With
    F_w = E'(d) n̂ (n̂ = δ/d), F_s = −t F_w, δt (zero where t is clamped), δδ = δw − t δs − δt s,
    δd = n̂·δδ: δF_w = E'' δd n̂ + E' (δδ − n̂ δd)/d and δF_s = −δt F_w − t δF_w."""
    dt = 0.0
    if inside:
        ss = sx * sx + sy * sy
        dt = (dwx * sx + dwy * sy + wx * dsx + wy * dsy - 2.0 * t * (sx * dsx + sy * dsy)) / ss
    ddx, ddy = dwx - t * dsx - dt * sx, dwy - t * dsy - dt * sy
    dd = nx * ddx + ny * ddy
    dfx = dde * dd * nx + de * (ddx - nx * dd) / d
    dfy = dde * dd * ny + de * (ddy - ny * dd) / d
    return dfx, dfy, -dt * de * nx - t * dfx, -dt * de * ny - t * dfy


@jit
def _variation(dq, n, iv, ie, ppx, ppy, p0x, p0y, sx, sy):
    """(δw, δs) along dq: δw = δx_p − δx_e + δθ_p J p_P − δθ_e J p_0, δs = δθ_e J s (J v = (−v_y, v_x))."""
    tp, te = dq[2 * n + iv], dq[2 * n + ie]
    dwx = dq[iv] - dq[ie] - tp * ppy + te * p0y
    dwy = dq[n + iv] - dq[n + ie] + tp * ppx - te * p0x
    return dwx, dwy, -te * sy, te * sx


@jit
def pair_contact(dx, dy, d2, prm):
    """(touching, d, E'(d), E''(d), n̂, F = E' n̂) of a pair at separation δ = (dx, dy), d² = |δ|²
    (``pair_frame``); not touching (and zeros) at or beyond the cutoff."""
    cut = prm[C_CUT]
    if d2 >= cut * cut:
        return False, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    d = math.sqrt(d2)
    _, de, dde = barrier(d, prm[C_K], cut)
    nx, ny = dx / d, dy / d
    return True, d, de, dde, nx, ny, de * nx, de * ny


@jit
def contacts_hvp(q, n, cs, sn, units, table, dq, out):
    """∇²E dq of the contact pairs added to ``out``: ``pair_second`` along the variations of w and
    s, then the chain rule through them, with their second derivatives in the rotations
    (∂²(R r)/∂θ² = −R r)."""
    for c in range(units.shape[0]):
        prm = table[c]
        iv, ie = units[c, 0], units[c, 1]
        ppx, ppy, p0x, p0y, sx, sy, wx, wy, t, inside, dx, dy, d2 = pair_frame(q, n, cs, sn, iv, ie, prm)
        touching, d, de, dde, nx, ny, fx, fy = pair_contact(dx, dy, d2, prm)
        if not touching:
            continue
        tp, te = dq[2 * n + iv], dq[2 * n + ie]
        dwx, dwy, dsx, dsy = _variation(dq, n, iv, ie, ppx, ppy, p0x, p0y, sx, sy)
        dfx, dfy, dgx, dgy = pair_second(nx, ny, d, de, dde, t, inside, wx, wy, sx, sy, dwx, dwy, dsx, dsy)
        out[iv] += dfx
        out[n + iv] += dfy
        out[ie] -= dfx
        out[n + ie] -= dfy
        out[2 * n + iv] += (dfy * ppx - dfx * ppy) - tp * (fx * ppx + fy * ppy)
        out[2 * n + ie] += (-(dfy * p0x - dfx * p0y) + te * (fx * p0x + fy * p0y)
                            + (dgy * sx - dgx * sy) + t * te * (fx * sx + fy * sy))


@jit
def _rotate_back(c, s, x, y):
    """R(θ)ᵀ (x, y) from c = cos θ, s = sin θ."""
    return c * x + s * y, c * y - s * x


@jit
def contacts_adjoint(q, n, cs, sn, units, table, lam, g2):
    """−∂(λ·∇E)/∂p of the contact pairs added to g2 (C, N_CONTACT_PARAMS) (the state part is
    ``contacts_hvp``'s). λ·∇E = F_w·δw_λ + F_s·δs_λ; with (G_w, G_s) = ``pair_second`` along
    (δw_λ, δs_λ) and δd_λ = n̂·(δw_λ − t δs_λ): ∂/∂D = G_w, ∂/∂r_P = R_pᵀ(G_w − λ_θp J F_w),
    ∂/∂r_0 = −R_eᵀ(G_w + G_s − λ_θe J (F_w + F_s)), ∂/∂r_1 = R_eᵀ(G_s − λ_θe J F_s),
    ∂/∂k = (E'/k) δd_λ, ∂/∂c = −(3k/2)(c² − d²)/d² δd_λ."""
    for c in range(units.shape[0]):
        prm = table[c]
        iv, ie = units[c, 0], units[c, 1]
        ppx, ppy, p0x, p0y, sx, sy, wx, wy, t, inside, dx, dy, d2 = pair_frame(q, n, cs, sn, iv, ie, prm)
        touching, d, de, dde, nx, ny, fx, fy = pair_contact(dx, dy, d2, prm)
        if not touching:
            continue
        cut, k = prm[C_CUT], prm[C_K]
        hx, hy = -t * fx, -t * fy  # F_s
        tp, te = lam[2 * n + iv], lam[2 * n + ie]
        dwx, dwy, dsx, dsy = _variation(lam, n, iv, ie, ppx, ppy, p0x, p0y, sx, sy)
        gwx, gwy, gsx, gsy = pair_second(nx, ny, d, de, dde, t, inside, wx, wy, sx, sy, dwx, dwy, dsx, dsy)
        dd = nx * (dwx - t * dsx) + ny * (dwy - t * dsy)
        row = g2[c]
        row[C_DX] -= gwx
        row[C_DY] -= gwy
        # J v = (−v_y, v_x)
        ax, ay = _rotate_back(cs[iv], sn[iv], gwx + tp * fy, gwy - tp * fx)
        row[C_PX] -= ax
        row[C_PY] -= ay
        bx, by = _rotate_back(cs[ie], sn[ie], gwx + gsx + te * (fy + hy), gwy + gsy - te * (fx + hx))
        row[C_0X] += bx
        row[C_0Y] += by
        ex, ey = _rotate_back(cs[ie], sn[ie], gsx + te * hy, gsy - te * hx)
        row[C_1X] -= ex
        row[C_1Y] -= ey
        row[C_K] -= de / k * dd
        row[C_CUT] += 1.5 * k * (cut * cut - d2) / d2 * dd


@jit
def contacts_tangent(q, n, cs, sn, units, table, d2tab, out):
    """−δ_p(∇E) of the contact pairs along the table direction ``d2tab`` (C, N_CONTACT_PARAMS),
    added to ``out``: δw = δD + R_p δr_P − R_e δr_0 and δs = R_e(δr_1 − δr_0) through
    ``pair_second``, E' through k and c, and the rotated offsets in the torques."""
    for c in range(units.shape[0]):
        prm = table[c]
        dp = d2tab[c]
        iv, ie = units[c, 0], units[c, 1]
        ppx, ppy, p0x, p0y, sx, sy, wx, wy, t, inside, dx, dy, d2 = pair_frame(q, n, cs, sn, iv, ie, prm)
        touching, d, de, dde, nx, ny, fx, fy = pair_contact(dx, dy, d2, prm)
        if not touching:
            continue
        cut, k = prm[C_CUT], prm[C_K]
        hx, hy = -t * fx, -t * fy
        dppx, dppy = _turn(cs[iv], sn[iv], dp[C_PX], dp[C_PY])
        dp0x, dp0y = _turn(cs[ie], sn[ie], dp[C_0X], dp[C_0Y])
        dp1x, dp1y = _turn(cs[ie], sn[ie], dp[C_1X], dp[C_1Y])
        dwx, dwy = dp[C_DX] + dppx - dp0x, dp[C_DY] + dppy - dp0y
        dsx, dsy = dp1x - dp0x, dp1y - dp0y
        dfx, dfy, dgx, dgy = pair_second(nx, ny, d, de, dde, t, inside, wx, wy, sx, sy, dwx, dwy, dsx, dsy)
        dde_p = de / k * dp[C_K] - 1.5 * k * (cut * cut - d2) / d2 * dp[C_CUT]  # δE' from k and c
        dfx, dfy = dfx + dde_p * nx, dfy + dde_p * ny
        dgx, dgy = dgx - t * dde_p * nx, dgy - t * dde_p * ny
        out[iv] -= dfx
        out[n + iv] -= dfy
        out[ie] += dfx
        out[n + ie] += dfy
        # ∂E/∂θ_p = F_w·J p_P, ∂E/∂θ_e = −F_w·J p_0 + F_s·J s  (a·J b = a_y b_x − a_x b_y)
        out[2 * n + iv] -= (dfy * ppx - dfx * ppy) + (fy * dppx - fx * dppy)
        out[2 * n + ie] -= (-(dfy * p0x - dfx * p0y) - (fy * dp0x - fx * dp0y)
                            + (dgy * sx - dgx * sy) + (hy * dsx - hx * dsy))


def pair_geometry(q: np.ndarray, n: int, units: np.ndarray, table: np.ndarray):
    """(p_P, p_0 + t s, δ, d) of every pair at state q, numpy: the vertex's rotated offset, the
    closest point of the edge from the edge unit's centre (each (2, C)), the separation (2, C)
    and its length (C,)."""
    iv, ie = units[:, 0], units[:, 1]
    p = table.T
    x, th = q[: 2 * n].reshape(2, n), q[2 * n : 3 * n]

    def rotated(unit, rx, ry):
        c, s = np.cos(th[unit]), np.sin(th[unit])
        return np.stack([c * rx - s * ry, s * rx + c * ry])

    pp, p0, p1 = rotated(iv, p[C_PX], p[C_PY]), rotated(ie, p[C_0X], p[C_0Y]), rotated(ie, p[C_1X], p[C_1Y])
    s = p1 - p0
    w = p[[C_DX, C_DY]] + x[:, iv] - x[:, ie] + pp - p0
    t = np.clip(np.sum(w * s, 0) / np.sum(s * s, 0), 0.0, 1.0)
    sep = w - t * s
    return pp, p0 + t * s, sep, np.hypot(sep[0], sep[1])


def pair_distances(q: np.ndarray, n: int, units: np.ndarray, table: np.ndarray) -> np.ndarray:
    """Vertex–edge distances (C,) of the pairs at state q (units of the table)."""
    return pair_geometry(q, n, units, table)[3]


def contacts_reference(q: np.ndarray, n: int, units: np.ndarray, table: np.ndarray) -> tuple[float, np.ndarray]:
    """Readable numpy version of the contacts' energy and forces (vectorised over pairs)."""
    f = np.zeros(3 * n)
    if units.shape[0] == 0:
        return 0.0, f
    iv, ie = units[:, 0], units[:, 1]
    pp, closest, sep, d = pair_geometry(q, n, units, table)
    k, c = table[:, C_K], table[:, C_CUT]
    gap = np.where(d < c, c - d, 0.0)
    energy = float(np.sum(0.5 * k * gap**3 / d))
    force = -0.5 * k * gap**2 * (c + 2 * d) / d**2 * sep / d  # E'(d) δ/d, (2, C)

    def cross(v, u):  # v·J u = v_y u_x − v_x u_y
        return v[1] * u[0] - v[0] * u[1]

    for dim in range(2):
        np.add.at(f, dim * n + iv, -force[dim])
        np.add.at(f, dim * n + ie, force[dim])
    np.add.at(f, 2 * n + iv, -cross(force, pp))
    np.add.at(f, 2 * n + ie, cross(force, closest))
    return energy, f


def contact_pairs(vertices: np.ndarray, centres: np.ndarray, links, k: float, cutoff: float,
                  image: np.ndarray | float = 0.0):
    """The contact pairs (units (C, 2) int64 [vertex's unit, edge's unit], table (C, N_CONTACT_PARAMS))
    of a network with counter-clockwise polygons ``vertices`` (N, V, 2), their ``centres`` (N, 2)
    and ligaments ``links`` (units a, units b, vertex of a, vertex of b, ...): on each side of
    each ligament, each facing edge's far vertex against the other edge (module docstring). A link
    of a periodic network that joins the copy of b at X_b + ``image`` (L, 2) (a wrap: the lattice
    shift of its ligament) gives pairs with that copy: their rest separation D is taken to it, so
    the pair acts between a and b across the cell's boundary. Raises ContactError if a pair is
    already within the cutoff in the reference geometry."""
    a, b, va, vb = (np.asarray(x, np.int64) for x in links[:4])
    shift = np.broadcast_to(np.asarray(image, float), (a.size, 2))
    nv = vertices.shape[1]
    seen, units, rows = set(), [], []

    def add(pu, pv, eu, e0, e1, dx, dy):
        key = (pu, pv, eu, e0, e1, dx, dy)
        if key in seen or (pu == eu and dx == dy == 0.0):
            return
        seen.add(key)
        row = np.zeros(N_CONTACT_PARAMS)
        row[[C_PX, C_PY]] = vertices[pu, pv] - centres[pu]
        row[[C_0X, C_0Y]] = vertices[eu, e0] - centres[eu]
        row[[C_1X, C_1Y]] = vertices[eu, e1] - centres[eu]
        row[[C_DX, C_DY]] = centres[pu] - centres[eu] + (dx, dy)
        row[[C_K, C_CUT]] = k, cutoff
        units.append((pu, eu))
        rows.append(row)

    for ua, ub, i, j, (sx, sy) in zip(a.tolist(), b.tolist(), va.tolist(), vb.tolist(), shift.tolist()):
        ip, im, jp, jm = (i + 1) % nv, (i - 1) % nv, (j + 1) % nv, (j - 1) % nv
        add(ua, ip, ub, jm, j, -sx, -sy)  # one side: A's edge i→i+1 faces B's edge j−1→j
        add(ub, jm, ua, i, ip, sx, sy)
        add(ua, im, ub, j, jp, -sx, -sy)  # the other side: A's edge i−1→i faces B's edge j→j+1
        add(ub, jp, ua, im, i, sx, sy)
    if not rows:
        return NO_PAIRS, NO_CONTACTS
    table = np.array(rows)
    pairs = np.array(units, np.int64)
    dist = rest_distances(pairs, table)
    if np.any(dist <= cutoff):
        worst = int(np.argmin(dist))
        raise ContactError(
            f"lattice.contact.cutoff_m: vertex–edge pairs are closer than the cutoff in the reference geometry "
            f"(the closest at {dist[worst]:.4g} a, units {pairs[worst, 0]} and {pairs[worst, 1]}, cutoff "
            f"{cutoff:.4g} a): choose a cutoff below the open pores' gaps")
    return pairs, table


def rest_distances(units: np.ndarray, table: np.ndarray) -> np.ndarray:
    """Vertex–edge distances (C,) of the pairs in the reference geometry (units of the table)."""
    n = int(units.max()) + 1 if units.size else 0
    return pair_distances(np.zeros(3 * n), n, units, table)
