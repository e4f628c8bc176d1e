"""Energies of rigid rotating units (docs/physics.md §1), for the energy colouring: per hinge and
per unit, from the lattice's ``render.params.RigidParams``. (How units are drawn: the shapes their
dataset stores, ``render.structure.ShapeStructure``.)
"""

from __future__ import annotations

import numpy as np

from flexmm.models.hinge import H_HALF_A, H_HALF_B, H_KL, H_KS, H_KT, H_REST, H_SIGN, N_HINGE_PARAMS
from flexmm.models.energies import hinge_energies
from flexmm.render.params import RigidParams, joint_energy_j, lateral_energy_j


def hinge_energy_j(p: RigidParams, u, v, theta) -> np.ndarray:
    """Energy (J) of every hinge (H,) from full-lattice fields u, v (m; None for a chain), θ (rad).

    The models' hinge law (``models.hinge.hinge_law``, docs/physics.md §1) on rows in SI:
    E = ½ k_l Δl² + ½ k_s Δs² + ½ k_θ (θ_A + θ_B)², Δl, Δs the hinged points' separation along
    and across the hinge axis minus the ligament (wraps included: relative displacements only).
    """
    A, B, ax = p.hinge_a, p.hinge_b, p.hinge_axis
    h = p.half_m
    t0A, t0B = p.theta0_rad[A], p.theta0_rad[B]
    du = u[B] - u[A]
    dv = np.zeros_like(du) if v is None else v[B] - v[A]
    prm = np.empty((A.size, N_HINGE_PARAMS))
    prm[:, H_REST] = h * (np.cos(t0A) + np.cos(t0B))
    prm[:, H_HALF_A] = prm[:, H_HALF_B] = h
    prm[:, H_SIGN] = np.where(ax == 0, p.sigma[A], -p.sigma[A])
    prm[:, H_KL], prm[:, H_KS], prm[:, H_KT] = p.k_long_n_per_m, p.k_shear_n_per_m, p.k_rot_n_m_per_rad
    phi_a, phi_b = t0A + theta[A], t0B + theta[B]
    e = np.empty(A.size)
    hinge_energies(*(np.ascontiguousarray(x, float) for x in (
        np.where(ax == 0, du, dv), np.where(ax == 0, dv, du), theta[A], theta[B], np.cos(phi_a), np.sin(phi_a),
        np.cos(phi_b), np.sin(phi_b))), prm, e)
    if p.joint is not None:
        e = e + joint_energy_j(theta[A] + theta[B], p.joint)
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
