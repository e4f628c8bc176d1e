"""2D lattice of rotating squares (docs/physics.md §1.2): u, v, θ per unit, the hinge law of hinge.py.

Site s = row · n_cols + col, rest position (col h, row h), h = a cos θ0 + ℓ (ℓ: ligament
length, 0 for zero-length springs). State (nondimensional, length a, time sqrt(m/k_l), mass m):
q = [u (N), v (N), θ (N)]. A horizontal hinge joins the right corner of A = (r, c) to the left
corner of B = (r, c+1): d_l = u_B − u_A, d_s = v_B − v_A, sign σ_A. A vertical hinge joins the top
corner of A = (r, c) to the bottom corner of B = (r+1, c): d_l = v_B − v_A, d_s = u_B − u_A, sign
−σ_A (the bottom corner of B is −(a/2)(−sin φ_B, cos φ_B), so the across-axis offset
(a/2)(sin φ_A + sin φ_B) = −σ_A (a/2)[sin(θ0+θ_B) − sin(θ0+θ_A)]). Periodic edges add wrap hinges.

The kernel also carries the extra terms of the rigid-unit family, each over its own arrays:
point dipoles (``magnets``), bistable joints (``linkage``) and constant loads (``predeform``).
``args`` = (ha (H,), hb (H,), axis (H,), hinge_prm (H, 7), theta0 (N,), cos (N,), sin (N,),
dipoles, joints, loads).
"""

from __future__ import annotations

import math
from functools import partial

import numpy as np

from flexmm.config.rigid import HINGE_TARGETS, SITE_TARGETS, RotatingSquaresSheet
from flexmm.models import predeform, variation
from flexmm.models.base import BOTTOM, LEFT, RIGHT, TOP, FieldSpec, System, UnitShapes, square_units
from flexmm.models.hinge import (H_HALF_A, H_HALF_B, H_KL, H_KS, H_KT, H_REST, H_SIGN,
                                 N_HINGE_PARAMS)
from flexmm.models.joints import empty_joints
from flexmm.models.magnets import MU0_OVER_4PI, empty_dipoles, face_magnets
from flexmm.models.loads import empty_loads
from flexmm.models.sheet_kernels import SheetArgs
from flexmm.units import Scales

FIELDS = (
    FieldSpec("u", "length", "displacement along x", "x"),
    FieldSpec("v", "length", "displacement along y", "y"),
    FieldSpec("theta", "angle", "staggered rotation"),
)
COORD_ATTRS = {"row": ("1", "row index of the unit"), "col": ("1", "column index of the unit")}


def checkerboard(n_rows: int, n_cols: int) -> np.ndarray:
    """σ = (−1)^(row+col) per site, shape (n_rows·n_cols,)."""
    r, c = np.divmod(np.arange(n_rows * n_cols), n_cols)
    return np.where((r + c) % 2 == 0, 1.0, -1.0)


def hinge_pairs(n_rows: int, n_cols: int, periodic_x: bool, periodic_y: bool, skew: int = 0):
    """Hinges of the sheet: (a (H,), b (H,), axis (H,)), axis 0 horizontal (A left of B), 1 vertical.

    ``skew``: the top row's upper neighbours are the bottom row's units ``skew`` columns to the right
    (wrapped if periodic in x, dropped past the ends otherwise).
    """
    site = np.arange(n_rows * n_cols).reshape(n_rows, n_cols)
    a_h, b_h = site[:, :-1].ravel(), site[:, 1:].ravel()
    a_v, b_v = site[:-1, :].ravel(), site[1:, :].ravel()
    if periodic_x:
        a_h, b_h = np.concatenate([a_h, site[:, -1]]), np.concatenate([b_h, site[:, 0]])
    if periodic_y:
        cols = np.arange(n_cols) + skew
        keep = slice(None) if periodic_x else (cols >= 0) & (cols < n_cols)
        top, bottom = site[-1, :][keep], site[0, cols % n_cols][keep]
        a_v, b_v = np.concatenate([a_v, top]), np.concatenate([b_v, bottom])
    a = np.concatenate([a_h, a_v]).astype(np.int64)
    b = np.concatenate([b_h, b_v]).astype(np.int64)
    axis = np.concatenate([np.zeros(a_h.size), np.ones(a_v.size)]).astype(np.int64)
    return a, b, axis


def lattice_hinges(cfg) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(a, b, axis) of the sheet's hinges, in the builder's order (its ``ModelSpec.hinges``)."""
    return hinge_pairs(cfg.n_rows, cfg.n_cols, cfg.left == "periodic", cfg.bottom == "periodic", cfg.skew_cols)


def element_counts(cfg) -> dict[str, int]:
    """Target -> number of elements, of each per-unit and per-hinge target of a rotating-squares
    chain or sheet (its ``ModelSpec.elements``)."""
    from flexmm.models import MODELS

    n_hinges = MODELS[cfg.kind].hook("hinges")(cfg)[0].size
    return {t: cfg.n_units for t in SITE_TARGETS} | {t: n_hinges for t in HINGE_TARGETS}


def magnet_pairs(n_rows: int, n_cols: int, periodic_x: bool, periodic_y: bool, h: float):
    """Neighbour pairs for magnets (hinged and across a void) with rest offsets (P, 2) in units of a."""
    pairs, offs = [], []
    for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
        for r in range(n_rows):
            for c in range(n_cols):
                r2, c2 = r + dr, c + dc
                if periodic_y:
                    r2 %= n_rows
                if periodic_x:
                    c2 %= n_cols
                if 0 <= r2 < n_rows and 0 <= c2 < n_cols and (r2, c2) != (r, c):
                    pairs.append((r * n_cols + c, r2 * n_cols + c2))
                    offs.append((dc * h, dr * h))
    return np.array(pairs, np.int64).reshape(-1, 2), np.array(offs, float).reshape(-1, 2)


def hinge_table(a, b, axis, sigma, theta0, half_a, half_b, ligament, kl, ks, kt) -> np.ndarray:
    """Per-hinge parameter rows of hinge.hinge_law (nondimensional), shape (H, 7)."""
    hprm = np.empty((a.size, N_HINGE_PARAMS))
    # d_l is the change of the centre distance h = cos θ0 + ℓ; the springs measure the hinge
    # points' separation minus the ligament ℓ, so ℓ cancels and the rest state is stress-free
    hprm[:, H_REST] = half_a * np.cos(theta0[a]) + half_b * np.cos(theta0[b])
    hprm[:, H_HALF_A] = half_a
    hprm[:, H_HALF_B] = half_b
    hprm[:, H_SIGN] = np.where(axis == 0, sigma[a], -sigma[a])
    hprm[:, H_KL] = kl
    hprm[:, H_KS] = ks
    hprm[:, H_KT] = kt
    return hprm


def hold_fixed_ends(cfg, inv_mass: np.ndarray, ends: dict[str, list[int]], n: int, n_fields: int = 3) -> None:
    """Zero the inverse masses of every field of the units of each end ``cfg`` declares fixed
    (``cfg.left`` etc.), in place: a fixed end holds all DOFs of its units."""
    for end, sites in ends.items():
        if getattr(cfg, end) == "fixed":
            inv_mass[np.concatenate([np.asarray(sites) + f * n for f in range(n_fields)])] = 0.0


def edge_sites(n_rows: int, n_cols: int) -> dict[str, list[int]]:
    """Site lists of the four edges (left/right: columns; bottom/top: rows)."""
    site = np.arange(n_rows * n_cols).reshape(n_rows, n_cols)
    return {"left": site[:, 0].tolist(), "right": site[:, -1].tolist(),
            "bottom": site[0, :].tolist(), "top": site[-1, :].tolist()}


# ---------------------------------------------------------------- builder
def build(cfg: RotatingSquaresSheet) -> System:
    """The sheet as a System; edges free, fixed (all DOFs of the edge units held) or periodic."""
    nr, nc, n = cfg.n_rows, cfg.n_cols, cfg.n_units
    m, J, kl, a = cfg.unit_mass_kg, cfg.unit_inertia_kg_m2, cfg.k_long_n_per_m, cfg.a_m
    scales = Scales(a, math.sqrt(m / kl), m)
    px, py = cfg.left == "periodic", cfg.bottom == "periodic"
    ha, hb, hax = lattice_hinges(cfg)
    row, col = np.divmod(np.arange(n), nc)
    base = {"theta0_rad": cfg.theta0_rad, "mass_kg": m, "inertia_kg_m2": J, "k_long_n_per_m": kl,
            "k_shear_n_per_m": cfg.k_shear_n_per_m, "k_rot_n_m_per_rad": cfg.k_rot_n_m_per_rad}
    site_v, hinge_v = variation.parameter_arrays(base, cfg.variation, col, row, ha, hb)
    sigma = checkerboard(nr, nc)
    theta0 = site_v["theta0_rad"]
    ell = cfg.ligament_length_m / a
    hprm = hinge_table(ha, hb, hax, sigma, theta0, 0.5, 0.5, ell, hinge_v["k_long_n_per_m"] / kl,
                       hinge_v["k_shear_n_per_m"] / kl, hinge_v["k_rot_n_m_per_rad"] / (kl * a * a))
    h = math.cos(cfg.theta0_rad) + ell
    dip = empty_dipoles(n)
    if cfg.magnets is not None:
        mg = cfg.magnets
        pos, dirs = face_magnets(mg.recess_m / a)
        pab, off = magnet_pairs(nr, nc, px, py, h)
        strength = mg.moment_a_m2 * math.sqrt(MU0_OVER_4PI / (kl * a**5))  # s² = μ0 m²/(4π k_l a⁵)
        s = strength * (sigma if mg.polarity == "attract" else np.ones(n))
        kc = 10.0 if mg.contact_stiffness_n_per_m is None else mg.contact_stiffness_n_per_m / kl
        dip = (pab, off, pos, dirs, theta0, sigma, s, np.array([2.0 * mg.recess_m / a, kc]))
    args = SheetArgs(ha, hb, hax, hprm, theta0, np.zeros(n), np.zeros(n), dip, empty_joints(), empty_loads())
    mass = np.concatenate([site_v["mass_kg"], site_v["mass_kg"], site_v["inertia_kg_m2"] / a**2]) / m
    inv_mass = 1.0 / mass
    ends = edge_sites(nr, nc)
    hold_fixed_ends(cfg, inv_mass, ends, n)
    horiz = hax == 0
    spacing = h * a
    system = System(
        model=cfg.kind, fields=FIELDS, n_sites=n, scales=scales, mass=mass, inv_mass=inv_mass,
        args=args, q0=np.zeros(3 * n), v0=np.zeros(3 * n),
        spacing_m=spacing,
        site_coords={"x": col * spacing, "y": row * spacing, "row": row, "col": col},
        ends=ends,
        grid_shape=(nr, nc),
        site_coord_attrs=COORD_ATTRS,
        neighbour_pairs=np.stack([ha[horiz], hb[horiz]], 1),
        shapes=partial(sheet_shapes, nr, nc, ha, hb, hax, sigma, theta0, h,
                       markers=None if cfg.magnets is None else dip[2]),
    )
    if cfg.predeform is not None:
        predeform.relax(system, cfg.predeform)
    return system


def sheet_shapes(nr: int, nc: int, ha, hb, hax, sigma, theta0, spacing: float, outline: str = "polygon",
                 markers: np.ndarray | None = None, link_joints: bool = False) -> UnitShapes:
    """The squares of a sheet (diagonal 1) at (col, row) · ``spacing``, its hinges between the right
    and left corners (horizontal) or the top and bottom corners (vertical) of neighbours (the
    periodic wraps, far apart in the reference configuration, are not drawn); ``markers``: the
    magnets' body-frame positions (M, 2) (``magnets.face_magnets``), turned by each unit's σθ0."""
    row, col = np.divmod(np.arange(nr * nc), nc)
    across = np.where(hax == 0, col[hb] - col[ha], row[hb] - row[ha]) == 1
    along = np.where(hax == 0, row[hb] - row[ha], col[hb] - col[ha]) == 0
    drawn = across & along
    corners = np.where(hax[drawn, None] == 0, [RIGHT, LEFT], [TOP, BOTTOM])
    placed = None
    if markers is not None:
        c, s = np.cos(sigma * theta0)[:, None], np.sin(sigma * theta0)[:, None]
        placed = np.stack([c * markers[None, :, 0] - s * markers[None, :, 1],
                           s * markers[None, :, 0] + c * markers[None, :, 1]], -1)
    return square_units(np.stack([col, row], 1) * spacing, theta0, sigma, 0.5,
                        np.stack([ha[drawn], hb[drawn]], 1), corners, outline=outline, markers=placed,
                        link_joints=link_joints)


def theory_parameters(cfg: RotatingSquaresSheet):
    """The ``theory.rotating.RotatingChainND`` of the sheet's planar waves: the chain with n_v = 2,
    s_v = 1 (docs/physics.md §1.2)."""
    from flexmm.theory.rotating import RotatingChainND

    return RotatingChainND.from_si(cfg.a_m, cfg.theta0_rad, cfg.k_long_n_per_m, cfg.k_shear_n_per_m,
                                   cfg.k_rot_n_m_per_rad, cfg.unit_mass_kg, cfg.unit_inertia_kg_m2, 2, 1)


def launch_soliton(system: System, cfg: RotatingSquaresSheet, amplitude: float, center: int, direction: int) -> None:
    """Add a planar vector soliton (chain theory with n_v = 2, s_v = 1) centred on column ``center``.

    Every row gets the chain profile of docs/physics.md §1.3 (v = 0): exact for a sheet periodic in y,
    the natural launch for a wide sheet.
    """
    from flexmm.theory.rotating import soliton_initial_state

    p = theory_parameters(cfg)
    (nr, nc), n = system.grid_shape, system.n_sites
    U, T, dU, dT = soliton_initial_state(p, amplitude, nc, center, direction)
    for k, (vals, rates) in enumerate(((U, dU), (np.zeros(nc), np.zeros(nc)), (T, dT))):
        system.q0[k * n : (k + 1) * n] += np.tile(vals, nr)
        system.v0[k * n : (k + 1) * n] += np.tile(rates, nr)
