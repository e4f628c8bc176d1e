"""1D bistable linkage: rigid bars pinned tip to tip, every pin a bistable rotational spring.

Each unit is a rigid cross (two bars of length L welded at their middles, the rigid unit of the
rotating-squares family with its four tips as hinge points, PHYSICS.md §1.2); units form a strip
of two rows, pinned tip to tip, so the only soft mode is the counter-rotation of the units — a
scissor-like deployable linkage (a single row of pinned bars would fold like a chain instead).
The strip is a two-row ``rotating_sheet`` whose hinges are stiff pins (k_l = k_s = k_pin, k_θ = 0)
plus, at every pin, the double well in ψ = θ_a + θ_b

    V(ψ) = k [ψ⁴/4 − (1+β)ψ*ψ³/3 + βψ*²ψ²/2],   V′(ψ) = k ψ (ψ − βψ*)(ψ − ψ*),

wells at ψ = 0 and ψ* (V(ψ*) = −kψ*⁴(1−2β)/12), barrier at βψ*. A transition wave switches the
joints one after the other: the linkage deploys, its spacing L cos θ changing from the folded to
the deployed value.

Nondimensional: length L (bar length), time sqrt(m/k_pin), mass m.
"""

from __future__ import annotations

import math

import numpy as np

from flexmm._jit import jit
from flexmm.models.base import System


def empty_joints() -> tuple:
    """Joint arguments with no joints: (a (0,), b (0,), prm (0, 3))."""
    return (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3)))


@jit
def joint_law(psi, prm):
    """Energy and dE/dψ of the bistable joint (row ``prm`` = k, β, ψ*)."""
    k, beta, ps = prm[0], prm[1], prm[2]
    e = k * psi * psi * (0.25 * psi * psi - (1.0 + beta) * ps * psi / 3.0 + 0.5 * beta * ps * ps)
    return e, k * psi * (psi - beta * ps) * (psi - ps)


@jit
def joint_terms(q, n, joints, out, want_force):
    """Add the bistable-joint torques to ``out`` (if ``want_force``); return their energy.

    ``joints`` = (a (J,), b (J,), prm (J, 3) = k, β, ψ*); θ of site i is ``q[2n + i]``.
    """
    ja, jb, jp = joints
    e = 0.0
    for j in range(ja.shape[0]):
        a = 2 * n + ja[j]
        b = 2 * n + jb[j]
        ej, dv = joint_law(q[a] + q[b], jp[j])
        e += ej
        if want_force:
            out[a] -= dv
            out[b] -= dv
    return e


def joint_reference(q: np.ndarray, n: int, joints: tuple) -> tuple[float, np.ndarray]:
    """Numpy version of ``joint_terms`` (the law via numpy.polynomial), for the tests."""
    ja, jb, jp = joints
    f = np.zeros_like(q)
    energy = 0.0
    for j in range(ja.size):
        k, beta, ps = jp[j]
        dV = np.polynomial.Polynomial.fromroots([0.0, beta * ps, ps]) * k
        psi = q[2 * n + ja[j]] + q[2 * n + jb[j]]
        energy += float(dV.integ()(psi))
        f[2 * n + ja[j]] -= dV(psi)
        f[2 * n + jb[j]] -= dV(psi)
    return energy, f


def joint_stiffness(released_energy: float, switch: float, beta: float) -> float:
    """k of the double well from the released energy ΔE = k ψ*⁴ (1 − 2β)/12."""
    return 12.0 * released_energy / (switch**4 * (1.0 - 2.0 * beta))


def build(cfg) -> System:
    """The linkage as a System (a two-row rotating_sheet with pins and bistable joints)."""
    from flexmm.models.rotating_sheet import (COORD_ATTRS, FIELDS, checkerboard, edge_sites, hinge_pairs,
                                              hinge_table, sheet_energy, sheet_force, sheet_reference)
    from flexmm.models.magnets import empty_dipoles
    from flexmm.models.predeform import empty_loads
    from flexmm.units import Scales

    nc, L, m = cfg.n_cols, cfg.bar_length_m, cfg.mass_kg
    n = 2 * nc
    J = cfg.inertia_kg_m2 if cfg.inertia_kg_m2 is not None else m * L * L / 12
    scales = Scales(L, math.sqrt(m / cfg.k_pin_n_per_m), m)
    ha, hb, hax = hinge_pairs(2, nc, False, False)
    sigma = checkerboard(2, nc)
    theta0 = np.full(n, cfg.theta0_rad)
    hprm = hinge_table(ha, hb, hax, sigma, theta0, 0.5, 0.5, 0.0, 1.0, 1.0, 0.0)
    switch = 2.0 * (cfg.theta_deployed_rad - cfg.theta0_rad)
    k = joint_stiffness(cfg.released_energy_j, switch, cfg.barrier_fraction) / (cfg.k_pin_n_per_m * L * L)
    jprm = np.tile([k, cfg.barrier_fraction, switch], (ha.size, 1))
    args = (ha, hb, hax, hprm, theta0, np.zeros(n), np.zeros(n), empty_dipoles(n),
            (ha.copy(), hb.copy(), jprm), empty_loads())
    mass = np.concatenate([np.ones(2 * n), np.full(n, J / (m * L * L))])
    inv_mass = 1.0 / mass
    ends = {k: v for k, v in edge_sites(2, nc).items() if k in ("left", "right")}
    for end, sites in ends.items():
        if getattr(cfg, end) == "fixed":
            inv_mass[np.concatenate([np.asarray(sites) + f * n for f in range(3)])] = 0.0
    spacing = L * math.cos(cfg.theta0_rad)
    row, col = np.divmod(np.arange(n), nc)
    return System(
        model=cfg.kind, fields=FIELDS, n_sites=n, scales=scales, mass=mass, inv_mass=inv_mass,
        force=sheet_force, energy=sheet_energy, args=args, q0=np.zeros(3 * n), v0=np.zeros(3 * n),
        spacing_m=spacing, reference=sheet_reference,
        site_coords={"x": col * spacing, "y": row * spacing, "row": row, "col": col},
        meta={
            "theta0": cfg.theta0_rad, "theta_deployed": cfg.theta_deployed_rad, "switch_rad": switch,
            "n_rows": 2, "n_cols": nc, "omega_ref": 1.0, "ends": ends,
            "end_fields": {"left": "u", "right": "u"}, "axis_fields": {"x": "u", "y": "v"},
            "longitudinal_field": "u", "rotation_field": "theta", "load_slot": 9,
            "site_coord_attrs": COORD_ATTRS, "neighbour_pairs": np.stack([ha[hax == 0], hb[hax == 0]], 1),
        },
    )
