"""1D bistable linkage: rigid bars pinned tip to tip, every pin a bistable rotational spring.

Each unit is a rigid cross (two bars of length L welded at their middles, the rigid unit of the
rotating-squares family with its four tips as hinge points, docs/physics.md §1.2); units form a strip
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
from functools import partial

import numpy as np

from flexmm.models.base import System
from flexmm.models.rotating_sheet import FIELDS  # a two-row sheet: u, v, θ per cross


def joint_stiffness(released_energy: float, switch: float, beta: float) -> float:
    """k of the double well from the released energy ΔE = k ψ*⁴ (1 − 2β)/12."""
    return 12.0 * released_energy / (switch**4 * (1.0 - 2.0 * beta))


def lattice_hinges(cfg) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(a, b, axis) of the linkage's hinges: a two-row sheet's (its ``ModelSpec.hinges``)."""
    from flexmm.models.rotating_sheet import hinge_pairs

    return hinge_pairs(2, cfg.n_cols, False, False)


def build(cfg) -> System:
    """The linkage as a System (a two-row rotating_sheet with pins and bistable joints)."""
    from flexmm.models.sheet_kernels import SheetArgs
    from flexmm.models.rotating_sheet import (COORD_ATTRS, checkerboard, edge_sites, hold_fixed_ends,
                                              hinge_table, sheet_shapes)
    from flexmm.models.magnets import empty_dipoles
    from flexmm.models.loads import empty_loads
    from flexmm.units import Scales

    nc, L, m = cfg.n_cols, cfg.bar_length_m, cfg.mass_kg
    n = 2 * nc
    J = cfg.inertia_kg_m2 if cfg.inertia_kg_m2 is not None else m * L * L / 12
    scales = Scales(L, math.sqrt(m / cfg.k_pin_n_per_m), m)
    ha, hb, hax = lattice_hinges(cfg)
    sigma = checkerboard(2, nc)
    theta0 = np.full(n, cfg.theta0_rad)
    hprm = hinge_table(ha, hb, hax, sigma, theta0, 0.5, 0.5, 0.0, 1.0, 1.0, 0.0)
    switch = 2.0 * (cfg.theta_deployed_rad - cfg.theta0_rad)
    k = joint_stiffness(cfg.released_energy_j, switch, cfg.barrier_fraction) / (cfg.k_pin_n_per_m * L * L)
    jprm = np.tile([k, cfg.barrier_fraction, switch], (ha.size, 1))
    args = SheetArgs(ha, hb, hax, hprm, theta0, np.zeros(n), np.zeros(n), empty_dipoles(n),
                     (ha.copy(), hb.copy(), jprm), empty_loads())
    mass = np.concatenate([np.ones(2 * n), np.full(n, J / (m * L * L))])
    inv_mass = 1.0 / mass
    ends = {k: v for k, v in edge_sites(2, nc).items() if k in ("left", "right")}
    hold_fixed_ends(cfg, inv_mass, ends, n)
    spacing = L * math.cos(cfg.theta0_rad)
    row, col = np.divmod(np.arange(n), nc)
    return System(
        model=cfg.kind, fields=FIELDS, n_sites=n, scales=scales, mass=mass, inv_mass=inv_mass,
        args=args, q0=np.zeros(3 * n), v0=np.zeros(3 * n),
        spacing_m=spacing,
        site_coords={"x": col * spacing, "y": row * spacing, "row": row, "col": col},
        ends=ends, grid_shape=(2, nc),
        site_coord_attrs=COORD_ATTRS, neighbour_pairs=np.stack([ha[hax == 0], hb[hax == 0]], 1),
        shapes=partial(sheet_shapes, 2, nc, ha, hb, hax, sigma, theta0, math.cos(cfg.theta0_rad), outline="bars",
                       link_joints=True),
    )
