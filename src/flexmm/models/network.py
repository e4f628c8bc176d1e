"""Build a rigid-unit network (docs/physics.md §1.9) from its config: a geometry generator, then
the units' inertia from their polygons and the ligament table of ``flexmm.models.ligaments``.

Nondimensionalisation: length a, time sqrt(m/k_l) with m = ρa²/2 the mass of the nominal square of
diagonal a, mass m, so k_l = 1 (scales that no geometry parameter moves: a design may vary them).

Geometry. Unit (row r, col c), σ = (−1)^(r+c), rest orientation φ = σθ0, centre at
(c, r)·(a cos θ0 + ℓ); its vertices, counter-clockwise from the right one, are
(a/2)(cos φ, sin φ), (a/2)(−sin φ, cos φ), −(a/2)(cos φ, sin φ), (a/2)(sin φ, −cos φ). A ligament
joins the right vertex (0) of a unit to the left vertex (2) of its right neighbour, with axis x̂,
and the top vertex (1) to the bottom vertex (3) of the unit above, with axis ŷ; its rest gap is
the two vertices' separation in the reference geometry, so the reference is stress-free.
``random_quads`` moves every vertex by a uniform random vector of up to ``vertex_jitter`` · a in
each coordinate (``numpy.random.default_rng(seed)``); centres are then the polygons' centroids.
``rotating_triangles`` is the kagome of §1.6 (a the side, twist θ0 alternating in sign): each
hinge joins the two vertices that point along its axis at rest.
"""

from __future__ import annotations

import math

import numpy as np

from flexmm.config.network import RigidNetwork
from flexmm.models import ligaments as lg
from flexmm.models import unit_contact as uc
from flexmm.models.base import FieldSpec, System, UnitShapes
from flexmm.models.rotating_sheet import edge_sites, hold_fixed_ends
from flexmm.units import Scales

FIELDS = (
    FieldSpec("u", "length", "displacement along x"),
    FieldSpec("v", "length", "displacement along y"),
    FieldSpec("theta", "angle", "rotation"),
)
COORD_ATTRS = {"row": ("1", "row index of the unit"), "col": ("1", "column index of the unit")}
#: the vertices a ligament joins: (vertex of A, vertex of B, axis) for x and y neighbours
X_LINK, Y_LINK = (0, 2, (1.0, 0.0)), (1, 3, (0.0, 1.0))


def square_vertices(cfg: RigidNetwork) -> np.ndarray:
    """(N, 4, 2) vertices of the units in the reference geometry, in units of a."""
    nr, nc = cfg.n_rows, cfg.n_cols
    r, c = np.divmod(np.arange(nr * nc), nc)
    phi = np.where((r + c) % 2 == 0, 1.0, -1.0) * cfg.theta0_rad
    pitch = math.cos(cfg.theta0_rad) + cfg.ligament_length_m / cfg.a_m
    cp, sp = 0.5 * np.cos(phi), 0.5 * np.sin(phi)
    corners = np.stack([np.stack([cp, sp], 1), np.stack([-sp, cp], 1), np.stack([-cp, -sp], 1),
                        np.stack([sp, -cp], 1)], 1)
    centres = np.stack([c * pitch, r * pitch], 1)
    vertices = centres[:, None, :] + corners
    if cfg.pattern == "random_quads":
        rng = np.random.default_rng(cfg.seed)
        vertices = vertices + rng.uniform(-cfg.vertex_jitter, cfg.vertex_jitter, vertices.shape)
    return vertices


def square_links(n_rows: int, n_cols: int):
    """(units a, units b, vertex of a, vertex of b, axis (L, 2)): x neighbours, then y neighbours."""
    site = np.arange(n_rows * n_cols).reshape(n_rows, n_cols)
    parts = [(site[:, :-1].ravel(), site[:, 1:].ravel(), X_LINK), (site[:-1, :].ravel(), site[1:, :].ravel(), Y_LINK)]
    a = np.concatenate([p[0] for p in parts])
    b = np.concatenate([p[1] for p in parts])
    va = np.concatenate([np.full(p[0].size, p[2][0]) for p in parts])
    vb = np.concatenate([np.full(p[0].size, p[2][1]) for p in parts])
    axis = np.concatenate([np.tile(p[2][2], (p[0].size, 1)) for p in parts])
    return a, b, va, vb, axis


def triangle_geometry(cfg: RigidNetwork):
    """The kagome of rotating triangles (docs/physics.md §1.6; ``models.rotating_triangles``'s
    centroids and hinges): (N, 3, 2) vertices in units of the side a, and the links — each hinge
    joins the vertex of A and the vertex of B that point along its axis at rest."""
    from flexmm.models.rotating_triangles import HALF, centroids, kagome_hinges, sublattice_sign

    nr, nc, t0 = cfg.n_rows, cfg.n_cols, cfg.theta0_rad
    sigma = sublattice_sign(nr, nc)
    x, y = centroids(nr, nc, t0)
    ang = (np.where(sigma[:, None] > 0, 0.0, math.pi) + np.deg2rad([90.0, 210.0, 330.0])[None, :]
           + (sigma * t0)[:, None])
    vertices = np.stack([x, y], 1)[:, None, :] + HALF * np.stack([np.cos(ang), np.sin(ang)], -1)
    a, b, beta = kagome_hinges(nr, nc, False, False)
    axis = np.stack([np.cos(beta), np.sin(beta)], 1)

    def towards(unit, direction):  # the vertex of each unit pointing closest to ``direction`` (L, 2)
        d = vertices[unit] - np.stack([x, y], 1)[unit][:, None, :]
        return np.argmax(np.einsum("lvk,lk->lv", d, direction), axis=1)

    return vertices, (a, b, towards(a, axis), towards(b, -axis), axis)


def geometry(cfg: RigidNetwork):
    """(vertices (N, V, 2) in units of a, links (units a, units b, vertex of a, vertex of b, axis))."""
    if cfg.pattern == "rotating_triangles":
        return triangle_geometry(cfg)
    return square_vertices(cfg), square_links(cfg.n_rows, cfg.n_cols)


def polygon_inertia(vertices: np.ndarray, density: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mass (N,), centroid (N, 2) and polar moment of inertia about the centroid (N,) of simple
    polygons (N, V, 2) (vertices in order) of uniform areal density (shoelace sums about each
    polygon's vertex mean, so that no parallel-axis shift from far away cancels digits)."""
    mean = vertices.mean(1)
    x, y = vertices[..., 0] - mean[:, :1], vertices[..., 1] - mean[:, 1:]
    x1, y1 = np.roll(x, -1, 1), np.roll(y, -1, 1)
    cross = x * y1 - x1 * y
    area = 0.5 * cross.sum(1)
    cx = ((x + x1) * cross).sum(1) / (6 * area)
    cy = ((y + y1) * cross).sum(1) / (6 * area)
    j_origin = ((x * x + x * x1 + x1 * x1 + y * y + y * y1 + y1 * y1) * cross).sum(1) / 12
    mass = density * np.abs(area)
    inertia = density * np.abs(j_origin) - mass * (cx * cx + cy * cy)
    return mass, np.stack([cx, cy], 1) + mean, inertia


def ligament_table(vertices: np.ndarray, centres: np.ndarray, links, ks: float, kt: float,
                   law: int = lg.LAW_PAPER) -> np.ndarray:
    """The ligament table (L, N_LIGAMENT_PARAMS) of ``links`` with k_l = 1 (nondimensional): the
    joined vertices relative to their centres, the rest offset that makes the reference
    stress-free (the centres' separation less the vertices' gap), the link's axis, and the rest
    length ℓ = |gap|. DifFlexMM's laws read the bond along the rest gap: their axis is gap/ℓ (the
    link's axis where ℓ = 0)."""
    a, b, va, vb, axis = links
    ar = np.arange(a.size)
    lig = np.zeros((a.size, lg.N_LIGAMENT_PARAMS))
    pa, pb = vertices[a, va[ar]], vertices[b, vb[ar]]
    gap = pb - pa
    length = np.hypot(gap[:, 0], gap[:, 1])
    lig[:, [lg.L_AX, lg.L_AY]] = pa - centres[a]
    lig[:, [lg.L_BX, lg.L_BY]] = pb - centres[b]
    lig[:, [lg.L_OX, lg.L_OY]] = centres[b] - centres[a] - gap
    lig[:, [lg.L_EX, lg.L_EY]] = axis
    if law != lg.LAW_PAPER:
        along = length > 1e-12
        lig[along, lg.L_EX], lig[along, lg.L_EY] = gap[along, 0] / length[along], gap[along, 1] / length[along]
    lig[:, lg.L_LEN] = length
    lig[:, [lg.L_KL, lg.L_KS, lg.L_KT]] = (1.0, ks, kt)
    return lig


def build(cfg: RigidNetwork) -> System:
    """The network as a System: state (u, v, θ) of its units; edges free or fixed (all DOFs held)."""
    nr, nc, n, a = cfg.n_rows, cfg.n_cols, cfg.n_units, cfg.a_m
    vertices, links = geometry(cfg)
    mass_si, centres, inertia_si = polygon_inertia(vertices * a, cfg.areal_density_kg_m2)
    centres = centres / a
    m = cfg.areal_density_kg_m2 * a * a / 2  # the nominal square's mass: scales that the geometry does not move
    kl = cfg.k_long_n_per_m
    ua, ub = links[0].astype(np.int64), links[1].astype(np.int64)
    law = lg.LAWS[cfg.ligament_law]
    lig = ligament_table(vertices, centres, links, cfg.k_shear_n_per_m / kl, cfg.k_rot_n_m_per_rad / (kl * a * a), law)
    contact = () if cfg.contact is None else uc.contact_pairs(
        vertices, centres, links, cfg.contact.stiffness_n_per_m / kl, cfg.contact.cutoff_m / a)
    args = lg.NetworkArgs(ua, ub, lig, np.zeros(n), np.zeros(n), law, *contact)
    mass = np.concatenate([mass_si / m, mass_si / m, inertia_si / (m * a * a)])
    inv_mass = 1.0 / mass
    ends = edge_sites(nr, nc)
    hold_fixed_ends(cfg, inv_mass, ends, n)
    row, col = np.divmod(np.arange(n), nc)
    x_links = np.arange(nr * (nc - 1))  # the links along the rows come first (both generators)
    return System(
        model=cfg.kind, fields=FIELDS, n_sites=n, scales=Scales(a, math.sqrt(m / kl), m),
        mass=mass, inv_mass=inv_mass, args=args, q0=np.zeros(3 * n), v0=np.zeros(3 * n),
        spacing_m=a * math.cos(cfg.theta0_rad) + cfg.ligament_length_m,
        site_coords={"x": centres[:, 0] * a} | ({"y": centres[:, 1] * a, "row": row, "col": col} if nr > 1 else {}),
        ends=ends, rotation_field="theta", axis_fields={"x": "u", "y": "v"},
        end_fields={"left": "u", "right": "u", "bottom": "v", "top": "v"},
        grid_shape=(nr, nc) if nr > 1 else None, site_coord_attrs=COORD_ATTRS if nr > 1 else {},
        neighbour_pairs=np.stack([ua[x_links], ub[x_links]], 1),
        shapes=UnitShapes(centres, vertices - centres[:, None, :], np.ones(n), np.stack([ua, ub], 1),
                          np.stack([lig[:, [lg.L_AX, lg.L_AY]], lig[:, [lg.L_BX, lg.L_BY]]], 1)),
    )
