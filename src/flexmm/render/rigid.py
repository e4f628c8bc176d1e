"""Energies of rigid rotating units (docs/physics.md §1), for the energy colouring: per hinge and
per unit, from the lattice's ``render.params.RigidParams``. (How units are drawn: the shapes their
dataset stores, ``render.structure.ShapeStructure``.)
"""

from __future__ import annotations

import numpy as np

from flexmm.render.params import RigidParams, joint_energy_j, lateral_energy_j


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


__all__ = ["hinge_energy_j", "unit_energy_j"]
