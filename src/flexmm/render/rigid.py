"""Kinematics of rigid rotating units (docs/physics.md §1): hinge points, outlines, energies.

A unit with centre c and orientation φ = σ(θ0 + θ) (σ the checkerboard sign) has its four hinge
points at c + (a/2)(cos(φ + kπ/2), sin(φ + kπ/2)), k = 0..3: right, top, left, bottom. A
horizontal hinge joins the right point of A to the left point of B, a vertical one the top of A
to the bottom of B. Outlines: a square is the polygon through the hinge points (its diagonal is
a); a cross has arms of half-width w reaching the hinge points (mid-points of the arms' ends);
``bars`` is a cross of thin bars (the linkage). A chain's lateral hinges (n_v, §1.1) join each
unit to its mirror image across the row, drawn as ghost units below (and above for n_v = 2).
"""

from __future__ import annotations

import numpy as np

from flexmm.render.params import RigidParams, joint_energy_j, lateral_energy_j

#: arm half-width of each outline, as a fraction of the hinge-to-hinge size a
SHAPES = {"square": None, "cross": 0.14, "bars": 0.035}
RIGHT, TOP, LEFT, BOTTOM = range(4)


def hinge_points(centres: np.ndarray, phi: np.ndarray, half: np.ndarray | float) -> np.ndarray:
    """(N, 4, 2) hinge points (right, top, left, bottom) of units at ``centres`` turned by ``phi``."""
    ang = phi[:, None] + 0.5 * np.pi * np.arange(4)
    half = np.broadcast_to(np.asarray(half, float), phi.shape)[:, None]
    return centres[:, None, :] + half[..., None] * np.stack([np.cos(ang), np.sin(ang)], -1)


def outlines(centres: np.ndarray, points: np.ndarray, shape: str) -> np.ndarray:
    """Polygons (N, V, 2) of the units: the hinge points (square, V = 4) or a cross (V = 12)."""
    width = SHAPES[shape]
    if width is None:
        return points
    c = centres[:, None, :]
    e = points - c  # arm k, from the centre to hinge point k (length a/2)
    w = 2.0 * width * e  # along arm k, length width · a: the arms' half-width
    w_next = np.roll(w, -1, axis=1)  # arm k + 1 is arm k turned by 90°
    tip_lo, tip_hi = c + e - w_next, c + e + w_next  # the end of arm k; its mid-point is the hinge point
    inner = c + w + w_next  # the corner between arms k and k + 1
    return np.stack([tip_lo, tip_hi, inner], axis=2).reshape(len(centres), 12, 2)


def orientation(p: RigidParams, sites: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """φ = σ(θ0 + θ) of the given units."""
    return p.sigma[sites] * (p.theta0_rad[sites] + theta)


def mirror_units(p: RigidParams, sites: np.ndarray, centres: np.ndarray, phi: np.ndarray) -> list:
    """Ghost rows of a chain's lateral hinges: [(centres, phi), ...], one per lateral hinge.

    The mirror image of unit i across the row sits a cos θ0_i below (above) it with orientation
    −φ_i and the same u: each lateral hinge (bottom point of i to top point of its image) then
    stretches by a[cos θ0 − cos(θ0 + θ_i)] and carries no shear (§1.1).
    """
    gap = 2 * p.half_m * np.cos(p.theta0_rad[sites])
    out = []
    for side in (-1.0, 1.0)[: p.n_lateral]:
        c = centres.copy()
        c[:, 1] += side * gap
        out.append((c, -phi))
    return out


def hinge_segments(p: RigidParams, index: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(H', 2, 2) segments between the hinged points of the drawn hinges (wraps left out).

    ``index`` maps a lattice site to its row in ``points`` (−1: not saved).
    """
    keep = ~p.hinge_wrap & (index[p.hinge_a] >= 0) & (index[p.hinge_b] >= 0)
    a, b, ax = index[p.hinge_a[keep]], index[p.hinge_b[keep]], p.hinge_axis[keep]
    ca = np.where(ax == 0, RIGHT, TOP)
    cb = np.where(ax == 0, LEFT, BOTTOM)
    return np.stack([points[a, ca], points[b, cb]], axis=1)


def hinge_energy_j(p: RigidParams, u, v, theta) -> np.ndarray:
    """Energy (J) of every hinge (H,) from full-lattice fields u, v (m; None for a chain), θ (rad).

    E = ½ k_l Δl² + ½ k_s Δs² + ½ k_θ (θ_A + θ_B)², Δl, Δs the hinged points' separation along
    and across the hinge axis minus the ligament (wraps included: relative displacements only).
    """
    A, B, ax = p.hinge_a, p.hinge_b, p.hinge_axis
    h = p.half_m
    t0A, t0B = p.theta0_rad[A], p.theta0_rad[B]
    du = u[B] - u[A]
    dv = np.zeros_like(du) if v is None else v[B] - v[A]
    dl = np.where(ax == 0, du, dv)
    ds = np.where(ax == 0, dv, du)
    sign = np.where(ax == 0, p.sigma[A], -p.sigma[A])
    el = dl + h * (np.cos(t0A) + np.cos(t0B)) - h * (np.cos(t0A + theta[A]) + np.cos(t0B + theta[B]))
    es = ds + sign * h * (np.sin(t0B + theta[B]) - np.sin(t0A + theta[A]))
    ep = theta[A] + theta[B]
    e = 0.5 * (p.k_long_n_per_m * el * el + p.k_shear_n_per_m * es * es + p.k_rot_n_m_per_rad * ep * ep)
    if p.joint is not None:
        e = e + joint_energy_j(ep, p.joint)
    return e


def unit_energy_j(p: RigidParams, u, v, theta, rates: dict | None) -> np.ndarray:
    """Energy per unit (J): half of each of its hinges, its lateral hinges and its kinetic energy.

    ``rates``: {'u_dot', 'v_dot', 'theta_dot'} per unit, or None (potential only). Magnets are
    not included.
    """
    n = p.n_units
    eh = hinge_energy_j(p, u, v, theta)
    e = 0.5 * (np.bincount(p.hinge_a, eh, n) + np.bincount(p.hinge_b, eh, n)) + lateral_energy_j(p, theta)
    if rates:
        for name, inertia in (("u_dot", p.mass_kg), ("v_dot", p.mass_kg), ("theta_dot", p.inertia_kg_m2)):
            if rates.get(name) is not None:
                e = e + 0.5 * inertia * rates[name] ** 2
    return e


__all__ = ["SHAPES", "hinge_energy_j", "hinge_points", "hinge_segments", "mirror_units", "orientation",
           "outlines", "unit_energy_j"]
