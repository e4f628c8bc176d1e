"""Build the rotating-triangles chain and kagome sheet (docs/physics.md §1.6) from their configs.

Nondimensionalisation: length a (the side of a triangle), time sqrt(m/k_l), mass m, so k_l = 1,
K_s = k_s/k_l, K_θ = k_θ/(k_l a²), α² = J/(m a²); speeds in c0 = a sqrt(k_l/m). Centroid to
vertex h = 1/√3; a hinge's rest length (centroid to centroid) 2h cos θ0.

Geometry (θ0 = 0 is the straight kagome; the twist θ0 contracts every centroid distance by
cos θ0 and leaves the hinge axes where they are). Row r, column c, σ = (−1)^(r+c): an up
triangle (σ = +1) has its vertices at 90°, 210°, 330° from its centroid, a down one at 270°, 30°,
150°. The centroid sits at x = c s, y = r H + σ d/4, with s = cos θ0 (x spacing), d = 2h cos θ0
and H = 3d/2 = √3 cos θ0 (row spacing). The hinge c → c+1 of a row has its axis at β = −σ_A·30°,
the hinge of an up triangle to the triangle above it at β = 90°.
"""

from __future__ import annotations

import math

import numpy as np

from flexmm.config.triangles import RotatingTrianglesChain, RotatingTrianglesSheet
from flexmm.models.base import FieldSpec, System, UnitShapes
from flexmm.models.rotating_sheet import checkerboard as sublattice_sign  # σ = +1: the triangle points up
from flexmm.models.rotating_sheet import edge_sites, hold_fixed_ends
from flexmm.models import ligaments as lg
from flexmm.models.triangle_kernels import TriangleArgs
from flexmm.models.variation import parameter_arrays
from flexmm.units import Scales

FIELDS = (
    FieldSpec("u", "length", "displacement along x", "x"),
    FieldSpec("v", "length", "displacement along y", "y"),
    FieldSpec("theta", "angle", "staggered rotation"),
)
COORD_ATTRS = {"row": ("1", "row index of the triangle"), "col": ("1", "column index of the triangle")}
#: centroid-to-vertex distance in units of the side a
HALF = 1.0 / math.sqrt(3.0)


def nondimensional(cfg) -> dict[str, float]:
    """K_s, K_θ, α² of docs/physics.md §1.6 from the SI config."""
    return {
        "Ks": cfg.k_shear_n_per_m / cfg.k_long_n_per_m,
        "Ktheta": cfg.k_rot_n_m_per_rad / (cfg.k_long_n_per_m * cfg.a_m**2),
        "alpha2": cfg.unit_inertia_kg_m2 / (cfg.mass_kg * cfg.a_m**2),
    }


def kagome_hinges(n_rows: int, n_cols: int, periodic_x: bool, periodic_y: bool):
    """Hinges of an n_rows × n_cols kagome sheet: (a (H,), b (H,), β (H,) the axis angle in rad).

    Row hinges (r, c) → (r, c+1) (and the wraps (r, n_cols−1) → (r, 0)); vertical hinges from
    every up triangle (r, c) to (r+1, c) (the top row's to row 0 if periodic in y).
    """
    site = np.arange(n_rows * n_cols).reshape(n_rows, n_cols)
    sigma = sublattice_sign(n_rows, n_cols).reshape(n_rows, n_cols)
    a_h, b_h = site[:, :-1].ravel(), site[:, 1:].ravel()
    if periodic_x:
        a_h, b_h = np.concatenate([a_h, site[:, -1]]), np.concatenate([b_h, site[:, 0]])
    up = sigma > 0
    below = site if periodic_y else site[:-1]
    a_v = below[up[: below.shape[0]]]
    b_v = np.roll(site, -1, axis=0)[: below.shape[0]][up[: below.shape[0]]]
    a = np.concatenate([a_h, a_v]).astype(np.int64)
    b = np.concatenate([b_h, b_v]).astype(np.int64)
    beta = np.concatenate([-sigma.ravel()[a_h] * math.pi / 6, np.full(a_v.size, math.pi / 2)])
    return a, b, beta


def centroids(n_rows: int, n_cols: int, theta0: float) -> tuple[np.ndarray, np.ndarray]:
    """Rest centroid positions (x, y) (N,) in units of a."""
    r, c = np.divmod(np.arange(n_rows * n_cols), n_cols)
    d = 2.0 * HALF * math.cos(theta0)
    return c * math.cos(theta0), r * 1.5 * d + sublattice_sign(n_rows, n_cols) * d / 4


def triangle_args(n_rows: int, n_cols: int, theta0: float, Ks: float, Ktheta: float,
                  periodic_x: bool, periodic_y: bool) -> TriangleArgs:
    """Connectivity and ligament table (nondimensional, a = 1, k_l = 1): hinge h joins the vertex
    r_A = h R(σ_A θ0) e of triangle A to r_B = −h R(σ_B θ0) e of B (e its axis, σ_B = −σ_A), rest
    offset D e with D = 2h cos θ0 the centroids' distance (``triangle_kernels``)."""
    a, b, beta = kagome_hinges(n_rows, n_cols, periodic_x, periodic_y)
    n = n_rows * n_cols
    sigma = sublattice_sign(n_rows, n_cols)
    e = np.stack([np.cos(beta), np.sin(beta)], 1)
    rest = 2.0 * HALF * math.cos(theta0)
    lig = np.zeros((a.size, lg.N_LIGAMENT_PARAMS))
    lig[:, [lg.L_AX, lg.L_AY]] = turned(HALF * e, sigma[a] * theta0)
    lig[:, [lg.L_BX, lg.L_BY]] = turned(-HALF * e, sigma[b] * theta0)
    lig[:, [lg.L_OX, lg.L_OY]] = rest * e
    lig[:, [lg.L_EX, lg.L_EY]] = e
    lig[:, lg.L_KL], lig[:, lg.L_KS], lig[:, lg.L_KT], lig[:, lg.L_LEN] = 1.0, Ks, Ktheta, rest
    return TriangleArgs(lg.NetworkArgs(a, b, lig, np.zeros(n), np.zeros(n)), sigma)


def turned(vec: np.ndarray, phi) -> np.ndarray:
    """R(φ) v for rows v of ``vec`` (k, 2), φ (k,) or a scalar."""
    c, s = np.cos(phi), np.sin(phi)
    return np.stack([c * vec[:, 0] - s * vec[:, 1], s * vec[:, 0] + c * vec[:, 1]], 1)


def _build(cfg, n_rows: int, n_cols: int, ends: dict[str, list[int]]) -> System:
    nd = nondimensional(cfg)
    n = n_rows * n_cols
    periodic_y = getattr(cfg, "bottom", "free") == "periodic"
    args = triangle_args(n_rows, n_cols, cfg.theta0_rad, nd["Ks"], nd["Ktheta"], cfg.left == "periodic", periodic_y)
    row, col = np.divmod(np.arange(n), n_cols)
    mass = np.concatenate([np.ones(2 * n), np.full(n, nd["alpha2"])])
    if cfg.variation:  # per-triangle m, J and per-hinge k_l, k_s, k_θ (docs/scenes.md, Parameter variation)
        m, J, kl, a = cfg.mass_kg, cfg.unit_inertia_kg_m2, cfg.k_long_n_per_m, cfg.a_m
        base = {"theta0_rad": cfg.theta0_rad, "mass_kg": m, "inertia_kg_m2": J, "k_long_n_per_m": kl,
                "k_shear_n_per_m": cfg.k_shear_n_per_m, "k_rot_n_m_per_rad": cfg.k_rot_n_m_per_rad}
        net = args.network
        units, hinges = parameter_arrays(base, cfg.variation, col, row, net.unit_a, net.unit_b)
        mass = np.concatenate([units["mass_kg"] / m, units["mass_kg"] / m, units["inertia_kg_m2"] / (m * a**2)])
        net.ligaments[:, lg.L_KL] = hinges["k_long_n_per_m"] / kl
        net.ligaments[:, lg.L_KS] = hinges["k_shear_n_per_m"] / kl
        net.ligaments[:, lg.L_KT] = hinges["k_rot_n_m_per_rad"] / (kl * a**2)
    inv_mass = 1.0 / mass
    hold_fixed_ends(cfg, inv_mass, ends, n)
    a = cfg.a_m
    x, y = centroids(n_rows, n_cols, cfg.theta0_rad)
    net = args.network
    rows = np.flatnonzero(net.ligaments[:, lg.L_EY] < 1.0)  # the hinges along the rows (not the vertical ones)
    return System(
        model=cfg.kind, fields=FIELDS, n_sites=n,
        scales=Scales(a, math.sqrt(cfg.mass_kg / cfg.k_long_n_per_m), cfg.mass_kg),
        mass=mass, inv_mass=inv_mass, args=args, q0=np.zeros(3 * n), v0=np.zeros(3 * n),
        spacing_m=a * math.cos(cfg.theta0_rad),
        # a chain keeps x only: its centroids' zig-zag (y = ±d/4) is no second row of sites
        site_coords={"x": x * a} | ({"y": y * a, "row": row, "col": col} if n_rows > 1 else {}),
        ends=ends,
        grid_shape=(n_rows, n_cols) if n_rows > 1 else None,
        site_coord_attrs=COORD_ATTRS if n_rows > 1 else {},
        neighbour_pairs=np.stack([net.unit_a[rows], net.unit_b[rows]], 1),
        shapes=shapes(args, cfg.theta0_rad, np.stack([x, y], 1)),
    )


def vertex_directions(sigma: np.ndarray, theta0: float, step=(0.0,)) -> np.ndarray:
    """Unit vectors (N, 3·len(step), 2) from each centroid to its triangle's vertices: 90°, 210°, 330°
    (each plus every angle of ``step``, degrees) pointing up (σ = +1), 270°, 30°, 150° pointing down,
    turned by σθ0."""
    deg = (np.array([90.0, 210.0, 330.0])[:, None] + np.array(step)[None, :]).ravel()
    ang = np.where(sigma[:, None] > 0, 0.0, math.pi) + np.deg2rad(deg)[None, :] + (sigma * theta0)[:, None]
    return np.stack([np.cos(ang), np.sin(ang)], -1)


def shapes(args: TriangleArgs, theta0: float, centres: np.ndarray) -> UnitShapes:
    """The triangles (vertices at 90°, 210°, 330° from the centroid pointing up, 270°, 30°, 150°
    pointing down, turned by σθ0) and their hinges' points (the ligament table's r_A, r_B); a
    periodic wrap's hinge (its points far apart in the reference configuration) is left out of
    the drawing."""
    sigma, net = args.sigma, args.network
    vertices = HALF * vertex_directions(sigma, theta0)
    ha, hb, lig = net.unit_a, net.unit_b, net.ligaments
    r_a, r_b = lig[:, [lg.L_AX, lg.L_AY]], lig[:, [lg.L_BX, lg.L_BY]]
    drawn = np.hypot(*(centres[hb] + r_b - centres[ha] - r_a).T) < 1e-9  # the periodic wraps are not drawn
    return UnitShapes(centres, vertices, sigma.copy(), np.stack([ha, hb], 1)[drawn],
                      np.stack([r_a, r_b], 1)[drawn])


def build_chain(cfg: RotatingTrianglesChain) -> System:
    """The strip of triangles as a System: state (u, v, θ) of units 0..N−1, ends free, fixed
    (all three DOFs of the end unit held) or periodic (even N)."""
    return _build(cfg, 1, cfg.n_units, {"left": [0], "right": [cfg.n_units - 1]})


def build_sheet(cfg: RotatingTrianglesSheet) -> System:
    """The kagome sheet as a System; edges free, fixed (all DOFs of the edge units) or periodic."""
    return _build(cfg, cfg.n_rows, cfg.n_cols, edge_sites(cfg.n_rows, cfg.n_cols))
