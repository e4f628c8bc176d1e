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
from dataclasses import dataclass

import numpy as np

from flexmm.config.network import RigidNetwork
from flexmm.models import geometry as geo
from flexmm.models import ligaments as lg
from flexmm.models import unit_contact as uc
from flexmm.models.base import FieldSpec, PeriodicCell, System, UnitShapes
from flexmm.models.rotating_sheet import edge_sites, hold_fixed_ends
from flexmm.units import Scales

FIELDS = (
    FieldSpec("u", "length", "displacement along x", "x"),
    FieldSpec("v", "length", "displacement along y", "y"),
    FieldSpec("theta", "angle", "rotation"),
)
COORD_ATTRS = {"row": ("1", "row index of the unit"), "col": ("1", "column index of the unit")}
#: the vertices a ligament joins: (vertex of A, vertex of B, axis) for x and y neighbours
X_LINK, Y_LINK = (0, 2, (1.0, 0.0)), (1, 3, (0.0, 1.0))


def square_centres(cfg: RigidNetwork) -> np.ndarray:
    """(N, 2) centres of the rotating squares (grid of pitch cos θ0 + ℓ/a), in units of a."""
    r, c = np.divmod(np.arange(cfg.n_rows * cfg.n_cols), cfg.n_cols)
    pitch = math.cos(cfg.theta0_rad) + cfg.ligament_length_m / cfg.a_m
    return np.stack([c * pitch, r * pitch], 1)


def unit_theta0(cfg: RigidNetwork) -> np.ndarray:
    """(N,) the rest rotation magnitude of each square: the lattice's θ0, or its region's."""
    theta = np.full(cfg.n_rows * cfg.n_cols, cfg.theta0_rad)
    tilted = [r for r in cfg.regions if r.theta0_rad is not None]
    if tilted:
        groups = named_sets({r.units: cfg.unit_sets[r.units] for r in tilted}, square_centres(cfg) * cfg.a_m)
        for region in tilted:
            theta[groups[region.units]] = region.theta0_rad
    return theta


def square_vertices(cfg: RigidNetwork) -> np.ndarray:
    """(N, 4, 2) vertices of the units in the reference geometry, in units of a (each square at
    its ``unit_theta0``)."""
    nr, nc = cfg.n_rows, cfg.n_cols
    r, c = np.divmod(np.arange(nr * nc), nc)
    phi = np.where((r + c) % 2 == 0, 1.0, -1.0) * unit_theta0(cfg)
    cp, sp = 0.5 * np.cos(phi), 0.5 * np.sin(phi)
    corners = np.stack([np.stack([cp, sp], 1), np.stack([-sp, cp], 1), np.stack([-cp, -sp], 1),
                        np.stack([sp, -cp], 1)], 1)
    centres = square_centres(cfg)
    vertices = centres[:, None, :] + corners
    if cfg.pattern == "random_quads":
        rng = np.random.default_rng(cfg.seed)
        vertices = vertices + rng.uniform(-cfg.vertex_jitter, cfg.vertex_jitter, vertices.shape)
    return vertices


def square_links(n_rows: int, n_cols: int, periodic_x: bool = False, periodic_y: bool = False):
    """(units a, units b, vertex of a, vertex of b, axis (L, 2)): x neighbours, then y neighbours,
    then the wraps of a periodic sheet (last column to first, top row to bottom)."""
    site = np.arange(n_rows * n_cols).reshape(n_rows, n_cols)
    parts = [(site[:, :-1].ravel(), site[:, 1:].ravel(), X_LINK), (site[:-1, :].ravel(), site[1:, :].ravel(), Y_LINK)]
    if periodic_x:
        parts.append((site[:, -1], site[:, 0], X_LINK))
    if periodic_y:
        parts.append((site[-1, :], site[0, :], Y_LINK))
    a = np.concatenate([p[0] for p in parts])
    b = np.concatenate([p[1] for p in parts])
    va = np.concatenate([np.full(p[0].size, p[2][0]) for p in parts])
    vb = np.concatenate([np.full(p[0].size, p[2][1]) for p in parts])
    axis = np.concatenate([np.tile(p[2][2], (p[0].size, 1)) for p in parts])
    return a, b, va, vb, axis


def rectangle_vertices(cfg: RigidNetwork) -> np.ndarray:
    """(N, 4, 2) vertices of rotating rectangles of diagonal a and side ratio ρ = aspect_ratio (units
    of a; docs/physics.md §1.9): β = atan ρ, a + unit's vertices at σ-angles φ0 + (0, 2β, π, π + 2β)
    with φ0 = θ0 + π/4 − β, a − unit the + unit mirrored in x; the squares' links (ρ = 1: the squares)."""
    nr, nc = cfg.n_rows, cfg.n_cols
    r, c = np.divmod(np.arange(nr * nc), nc)
    beta = math.atan(cfg.aspect_ratio)
    phi0 = cfg.theta0_rad + math.pi / 4 - beta
    up = (r + c) % 2 == 0
    offsets = np.where(up[:, None], [0.0, 2 * beta, math.pi, math.pi + 2 * beta],
                       [0.0, math.pi - 2 * beta, math.pi, 2 * math.pi - 2 * beta])
    ang = np.where(up, phi0, -phi0)[:, None] + offsets
    ell = cfg.ligament_length_m / cfg.a_m
    centres = np.stack([c * (math.cos(phi0) + ell), r * (math.sin(phi0 + 2 * beta) + ell)], 1)
    return centres[:, None, :] + 0.5 * np.stack([np.cos(ang), np.sin(ang)], -1)


def kagome_geometry(cfg: RigidNetwork):
    """The kagome of rotating triangles (docs/physics.md §1.6; ``models.rotating_triangles``'s
    centroids and hinges), or of regular hexagons of side a on the same sites whose alternate
    vertices are those triangles' (side √3 a): (N, 3 or 6, 2) vertices in units of a, and the links —
    each hinge joins the linked vertex of A and that of B that point along its axis at rest."""
    from flexmm.models.rotating_triangles import HALF, centroids, kagome_hinges, sublattice_sign, vertex_directions

    nr, nc, t0 = cfg.n_rows, cfg.n_cols, cfg.theta0_rad
    hexagons = cfg.pattern == "rotating_hexagons"
    side = math.sqrt(3.0) if hexagons else 1.0  # the triangle of linked vertices, in units of a
    step = [0.0, 60.0] if hexagons else [0.0]  # a hexagon's vertex between two linked ones
    sigma = sublattice_sign(nr, nc)
    x, y = centroids(nr, nc, t0)
    centres = side * np.stack([x, y], 1)
    vertices = centres[:, None, :] + side * HALF * vertex_directions(sigma, t0, step)
    a, b, beta = kagome_hinges(nr, nc, cfg.left == "periodic", cfg.bottom == "periodic")
    axis = np.stack([np.cos(beta), np.sin(beta)], 1)

    def towards(unit, direction):  # the linked vertex of each unit pointing closest to ``direction`` (L,)
        d = vertices[unit, :: len(step)] - centres[unit][:, None, :]
        return len(step) * np.argmax(np.einsum("lvk,lk->lv", d, direction), axis=1)

    return vertices, (a, b, towards(a, axis), towards(b, -axis), axis)


def column_pitch(cfg: RigidNetwork) -> float:
    """Distance between neighbouring columns of a generated sheet (m)."""
    if cfg.pattern == "rotating_hexagons":
        return math.sqrt(3.0) * cfg.a_m * math.cos(cfg.theta0_rad)
    if cfg.pattern == "rectangles":
        return cfg.a_m * math.cos(cfg.theta0_rad + math.pi / 4 - math.atan(cfg.aspect_ratio)) + cfg.ligament_length_m
    return cfg.a_m * math.cos(cfg.theta0_rad) + cfg.ligament_length_m


def geometry(cfg: RigidNetwork):
    """(vertices (N, V, 2) in units of a, links (units a, units b, vertex of a, vertex of b, axis)),
    with the wrapping links of the periodic edges (``periods``)."""
    if cfg.pattern in ("rotating_triangles", "rotating_hexagons"):
        return kagome_geometry(cfg)
    links = square_links(cfg.n_rows, cfg.n_cols, cfg.left == "periodic", cfg.bottom == "periodic")
    if cfg.pattern == "rectangles":
        return rectangle_vertices(cfg), links
    return square_vertices(cfg), links


def pitches(cfg: RigidNetwork) -> tuple[float, float]:
    """Distances between neighbouring columns and between neighbouring rows of a generated sheet
    (units of a)."""
    across = column_pitch(cfg) / cfg.a_m
    if cfg.pattern in ("rotating_triangles", "rotating_hexagons"):
        return across, math.sqrt(3.0) * across  # rows 3/2 of a hinge (2 cos θ0/√3) apart
    if cfg.pattern == "rectangles":
        beta = math.atan(cfg.aspect_ratio)
        return across, math.sin(cfg.theta0_rad + math.pi / 4 + beta) + cfg.ligament_length_m / cfg.a_m
    return across, across


def periods(cfg: RigidNetwork, links) -> tuple[np.ndarray, np.ndarray] | None:
    """(lattice vectors (P, 2) in units of a, link shifts (L, P)) of a generated sheet with periodic
    edges: the whole sheet is the cell, and a link from a unit to one in a lower column (row) is a
    wrap to the next cell along x (y); None without periodic edges."""
    axes = cfg.periodic_axes
    if not axes:
        return None
    px, py = pitches(cfg)
    row, col = np.divmod(np.arange(cfg.n_rows * cfg.n_cols), cfg.n_cols)
    a, b = links[0], links[1]
    vectors = {"x": (cfg.n_cols * px, 0.0), "y": (0.0, cfg.n_rows * py)}
    wraps = {"x": col[b] < col[a], "y": row[b] < row[a]}
    return (np.array([vectors[ax] for ax in axes], float),
            np.stack([wraps[ax].astype(np.int64) for ax in axes], 1))


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
                   law: int = lg.LAW_PAPER, image: np.ndarray | float = 0.0) -> np.ndarray:
    """The ligament table (L, N_LIGAMENT_PARAMS) of ``links`` with k_l = 1 (nondimensional): the
    joined vertices relative to their centres, the rest offset that makes the reference
    stress-free (the centres' separation less the vertices' gap), the link's axis, and the rest
    length ℓ = |gap|. DifFlexMM's laws read the bond along the rest gap: their axis is gap/ℓ (the
    link's axis where ℓ = 0). ``image`` (L, 2): where the copy of b a link joins lies relative to b
    (a periodic network's wrapping links; 0 inside the cell)."""
    a, b, va, vb, axis = links
    ar = np.arange(a.size)
    lig = np.zeros((a.size, lg.N_LIGAMENT_PARAMS))
    pa, pb = vertices[a, va[ar]], vertices[b, vb[ar]] + image
    gap = pb - pa
    length = np.hypot(gap[:, 0], gap[:, 1])
    lig[:, [lg.L_AX, lg.L_AY]] = pa - centres[a]
    lig[:, [lg.L_BX, lg.L_BY]] = pb - centres[b] - image
    lig[:, [lg.L_OX, lg.L_OY]] = centres[b] + image - centres[a] - gap
    lig[:, [lg.L_EX, lg.L_EY]] = axis
    if law != lg.LAW_PAPER:
        along = length > 1e-12
        lig[along, lg.L_EX], lig[along, lg.L_EY] = gap[along, 0] / length[along], gap[along, 1] / length[along]
    lig[:, lg.L_LEN] = length
    lig[:, [lg.L_KL, lg.L_KS, lg.L_KT]] = (1.0, ks, kt)
    return lig


@dataclass
class Network:
    """A network's geometry before assembly, in units of a: polygons (N, V, 2), links, optional SI
    masses and inertias (N,) (NaN: from the polygon), per-link SI stiffnesses (L, 3) (NaN: the
    lattice's), rest gaps (L, 2) (NaN: the vertices' separation), and the grid it lies on (None:
    no full grid)."""

    vertices: np.ndarray
    links: tuple
    mass_kg: np.ndarray | None = None
    inertia_kg_m2: np.ndarray | None = None
    stiffness: np.ndarray | None = None
    rest_gap: np.ndarray | None = None
    grid: tuple[np.ndarray, np.ndarray] | None = None  # (row, col) of every unit
    full_grid: bool = True
    sets: dict | None = None  # a geometry file's named unit sets (config.geometry.UnitSet)
    cell: np.ndarray | None = None  # periodic: lattice vectors (P, 2), units of a
    shifts: np.ndarray | None = None  # periodic: (L, P) the cell of each link's b relative to a's

    def images(self) -> np.ndarray | float:
        """(L, 2) where the copy of b each link joins lies relative to b (0 without periods)."""
        return 0.0 if self.cell is None else self.shifts @ self.cell


def generated(cfg: RigidNetwork) -> Network:
    """The generator's network, cut by the mask if there is one (a cut into pieces is refused);
    units that overlap (their pores closed: a rest rotation too large for the shape) are refused."""
    if cfg.pattern != "random_quads":
        refuse_overlap(cfg)
    vertices, links = geometry(cfg)
    n = vertices.shape[0]
    row, col = np.divmod(np.arange(n), cfg.n_cols)
    cell, shifts = periods(cfg, links) or (None, None)
    net = Network(vertices, links, grid=(row, col), cell=cell, shifts=shifts)
    if cfg.mask is None:
        return net
    _, centres, _ = polygon_inertia(vertices, 1.0)
    keep = geo.mask_keep(cfg.mask, centres * cfg.a_m)
    if not keep.any():
        raise geo.GeometryError("lattice.mask keeps no unit: the outline holds no unit centre, or the holes cover it")
    return cut(net, keep)


def refuse_overlap(cfg: RigidNetwork) -> None:
    """GeometryError if the units of a periodic pattern overlap (checked on a 3 × 3 patch, which
    holds every pair of neighbours of the whole sheet)."""
    for region in cfg.regions:  # a region of its own rest rotation is its own pattern
        if region.theta0_rad is not None:
            refuse_overlap(cfg.region_lattice(region))
    vertices, _ = geometry(cfg.model_copy(update={"n_rows": min(cfg.n_rows, 3), "n_cols": min(cfg.n_cols, 3),
                                                  "regions": []}))
    pairs = geo.overlapping_pairs(list(vertices), 1e-9)
    if pairs:
        p, q = pairs[0]
        raise geo.GeometryError(f"lattice: {cfg.pattern} at theta0_rad = {cfg.theta0_rad:g} overlap (units {p} and {q} "
                                f"by {geo.overlap_depth(vertices[p], vertices[q]) * cfg.a_m:.3g} m): the pores have "
                                "closed; use a smaller |theta0_rad| or longer ligaments")


def cut(net: Network, keep: np.ndarray) -> Network:
    """``net`` with only the units ``keep`` (N,) bool and the links between them; refused if the
    units kept fall into disconnected pieces."""
    new = np.cumsum(keep) - 1
    a, b, va, vb, axis = net.links
    both = keep[a] & keep[b]
    links = (new[a[both]], new[b[both]], va[both], vb[both], axis[both])
    groups = geo.pieces(int(keep.sum()), links[0], links[1])
    if len(groups) > 1:
        raise geo.GeometryError(f"lattice.mask: {geo.describe_pieces(groups)}; change the outline or holes")
    grid = None if net.grid is None else (net.grid[0][keep], net.grid[1][keep])
    return Network(net.vertices[keep], links, grid=grid, full_grid=False)


def read_geometry(path: str):
    """(the validated ``config.geometry.GeometryFile``, its key-path -> line map); ConfigError
    naming file:line otherwise."""
    from flexmm.config.geometry import GeometryFile
    from flexmm.config.loader import read_yaml, validate

    data, lines = read_yaml(path)
    return validate(GeometryFile, data, lines=lines, source=str(path)), lines


def from_file(cfg: RigidNetwork) -> Network:
    """The network of a geometry file (``config.geometry``), its geometry checked: ConfigError at
    the file's line of the first unit or ligament at fault."""
    from flexmm.config.loader import ConfigError, ConfigIssue

    f, lines = read_geometry(cfg.geometry)
    polys = [np.asarray(u.vertices_m, float) for u in f.units]
    ligs = f.ligaments
    a, i, b, j = (np.array([getattr(g, k) for g in ligs], np.int64) for k in "aibj")
    issues = geo.geometry_issues(polys, a, i, b, j)
    if issues:
        def line(path):
            return next((lines[path[:k]] for k in range(len(path), 0, -1) if path[:k] in lines), None)
        raise ConfigError([ConfigIssue(cfg.geometry, line(path), ".".join(map(str, path)), msg)
                           for path, msg in issues])
    vertices = geo.padded(polys) / cfg.a_m
    nan = float("nan")

    def column(values):
        return np.array([nan if v is None else v for v in values], float)

    mass = column([u.mass_kg for u in f.units])
    inertia = column([u.inertia_kg_m2 for u in f.units])
    stiffness = np.stack([column([g.k_long_n_per_m for g in ligs]), column([g.k_shear_n_per_m for g in ligs]),
                          column([g.k_rot_n_m_per_rad for g in ligs])], 1)
    rest_gap = np.array([[nan, nan] if g.rest_gap_m is None else g.rest_gap_m for g in ligs], float) / cfg.a_m
    _, centres, _ = polygon_inertia(vertices, 1.0)
    cell = shifts = None
    image = 0.0
    if f.lattice_vectors_m is not None:
        cell = np.asarray(f.lattice_vectors_m, float) / cfg.a_m
        shifts = np.array([g.shift or [0] * len(cell) for g in ligs], np.int64).reshape(len(ligs), len(cell))
        image = shifts @ cell
    gap = np.where(np.isnan(rest_gap), vertices[b, j] + image - vertices[a, i], rest_gap)
    along = gap / np.maximum(np.hypot(gap[:, 0], gap[:, 1]), 1e-300)[:, None]
    towards = centres[b] + image - centres[a]
    towards /= np.hypot(towards[:, 0], towards[:, 1])[:, None]
    axis = np.where((np.hypot(gap[:, 0], gap[:, 1]) > 1e-9 * float(np.median(np.ptp(vertices, 1).max(1))))[:, None],
                    along, towards)
    for k, g in enumerate(ligs):
        if g.axis is not None:
            axis[k] = np.asarray(g.axis) / math.hypot(*g.axis)
    return Network(vertices, (a, b, i, j, axis), mass, inertia, stiffness, rest_gap, grid=None, full_grid=False,
                   sets=f.sets, cell=cell, shifts=shifts)


def bounding_ends(centres: np.ndarray, sizes: np.ndarray) -> dict[str, list[int]]:
    """The units of each side of a network that is not a full grid: those whose centre lies within
    half the median unit size of the extreme centre on that side (units of a)."""
    h = 0.5 * float(np.median(sizes))
    x, y = centres[:, 0], centres[:, 1]
    return {"left": np.flatnonzero(x <= x.min() + h).tolist(), "right": np.flatnonzero(x >= x.max() - h).tolist(),
            "bottom": np.flatnonzero(y <= y.min() + h).tolist(), "top": np.flatnonzero(y >= y.max() - h).tolist()}


def named_sets(specs: dict, centres_m: np.ndarray) -> dict[str, list[int]]:
    """Named unit sets (``config.geometry.UnitSet``: the lattice's ``unit_sets``, a geometry file's
    ``sets``) as unit indices, given the units' centres (N, 2) in m."""
    n, out = centres_m.shape[0], {}
    for name, spec in specs.items():
        units = geo.unit_set(spec, centres_m)
        if units.size == 0:
            raise geo.GeometryError(f"unit set {name!r} holds no unit (unit centres span x {centres_m[:, 0].min():.4g}.."
                             f"{centres_m[:, 0].max():.4g} m, y {centres_m[:, 1].min():.4g}..{centres_m[:, 1].max():.4g} m)")
        if units.max() >= n:
            raise geo.GeometryError(f"unit set {name!r}: units {[int(u) for u in units if u >= n]} outside 0..{n - 1}")
        out[name] = sorted(set(units.tolist()))
    return out


def apply_regions(cfg: RigidNetwork, groups: dict[str, list[int]], lig: np.ndarray, ua: np.ndarray, ub: np.ndarray,
                  mass_si: np.ndarray, inertia_si: np.ndarray, given: np.ndarray | None) -> None:
    """The lattice's ``regions`` (``config.network.Region``) in place: each region's density scales
    its units' mass and inertia (not those a geometry file gives: ``given``), and its stiffnesses
    replace the lattice's in the ligament table — between two units of the same region, or, across
    an interface, the series stiffness 2 k₁k₂/(k₁ + k₂) of the two sides. GeometryError if a unit
    lies in two regions."""
    n = mass_si.size
    kl, a = cfg.k_long_n_per_m, cfg.a_m
    scales = {"k_long_n_per_m": kl, "k_shear_n_per_m": kl, "k_rot_n_m_per_rad": kl * a * a}
    k_unit = np.tile([cfg.k_long_n_per_m, cfg.k_shear_n_per_m, cfg.k_rot_n_m_per_rad], (n, 1))
    region = np.full(n, -1)
    for r, spec in enumerate(cfg.regions):
        units = np.asarray(groups[spec.units], np.int64)
        twice = units[region[units] >= 0]
        if twice.size:
            raise geo.GeometryError(f"lattice.regions: units {twice[:5].tolist()} are in two regions "
                                    f"({cfg.regions[region[twice[0]]].units!r} and {spec.units!r})")
        region[units] = r
        for col, name in enumerate(scales):
            if getattr(spec, name) is not None:
                k_unit[units, col] = getattr(spec, name)
        if spec.areal_density_kg_m2 is not None:
            scaled = units if given is None else units[~given[units]]
            mass_si[scaled] *= spec.areal_density_kg_m2 / cfg.areal_density_kg_m2
            inertia_si[scaled] *= spec.areal_density_kg_m2 / cfg.areal_density_kg_m2
    touched = (region[ua] >= 0) | (region[ub] >= 0)
    ka, kb = k_unit[ua[touched]], k_unit[ub[touched]]
    total = ka + kb
    series = np.where(total > 0, 2 * ka * kb / np.where(total > 0, total, 1.0), 0.0)
    k = np.where((region[ua[touched]] == region[ub[touched]])[:, None], ka, series)
    for j, (col, scale) in enumerate(zip((lg.L_KL, lg.L_KS, lg.L_KT), scales.values())):
        lig[touched, col] = k[:, j] / scale


def as_paper(cfg: RigidNetwork, groups: dict[str, list[int]], lig: np.ndarray, ua: np.ndarray, ub: np.ndarray,
             axis: np.ndarray) -> None:
    """In a network that mixes the paper's law with DifFlexMM's linearised one (run as the latter),
    make the ligaments of the paper's law that law, in place: rest length ℓ = 0 and the link's axis
    (docs/physics.md §1.9: at ℓ = 0 the linearised law is the paper's). A ligament between two units
    of a region with a ``ligament_law`` has that law; every other ligament the lattice's."""
    law = np.full(ua.size, cfg.ligament_law, dtype=object)
    region = np.full(int(max(ua.max(), ub.max())) + 1, -1)
    for r, spec in enumerate(cfg.regions):
        region[np.asarray(groups[spec.units], np.int64)] = r
    for r, spec in enumerate(cfg.regions):
        if spec.ligament_law is not None:
            law[(region[ua] == r) & (region[ub] == r)] = spec.ligament_law
    paper = law == "paper"
    lig[paper, lg.L_LEN] = 0.0
    lig[np.ix_(paper, [lg.L_EX, lg.L_EY])] = axis[paper]


def build(cfg: RigidNetwork) -> System:
    """The network as a System: state (u, v, θ) of its units; edges free or fixed (all DOFs held),
    named unit sets held by ``fixed_units``."""
    a = cfg.a_m
    net = from_file(cfg) if cfg.geometry is not None else generated(cfg)
    vertices, links = net.vertices, net.links
    n = vertices.shape[0]
    mass_si, centres, inertia_si = polygon_inertia(vertices * a, cfg.areal_density_kg_m2)
    if net.mass_kg is not None:
        mass_si = np.where(np.isnan(net.mass_kg), mass_si, net.mass_kg)
        inertia_si = np.where(np.isnan(net.inertia_kg_m2), inertia_si, net.inertia_kg_m2)
    centres = centres / a
    groups = named_sets(dict(cfg.unit_sets) | (net.sets or {}), centres * a)
    m = cfg.areal_density_kg_m2 * a * a / 2  # the nominal square's mass: scales that the geometry does not move
    kl = cfg.k_long_n_per_m
    ua, ub = links[0].astype(np.int64), links[1].astype(np.int64)
    laws = {cfg.ligament_law} | {r.ligament_law for r in cfg.regions if r.ligament_law is not None}
    law = lg.LAWS["difflexmm_linear" if len(laws) > 1 else cfg.ligament_law]
    image = net.images()
    lig = ligament_table(vertices, centres, links, cfg.k_shear_n_per_m / kl, cfg.k_rot_n_m_per_rad / (kl * a * a), law,
                         image)
    if cfg.regions:
        given = None if net.mass_kg is None else ~np.isnan(net.mass_kg)
        apply_regions(cfg, groups, lig, ua, ub, mass_si, inertia_si, given)
    if len(laws) > 1:
        as_paper(cfg, groups, lig, ua, ub, links[4])
    if net.stiffness is not None:  # per-ligament springs and rest gaps of a geometry file
        for col, scale, k in ((lg.L_KL, kl, 0), (lg.L_KS, kl, 1), (lg.L_KT, kl * a * a, 2)):
            lig[:, col] = np.where(np.isnan(net.stiffness[:, k]), lig[:, col], net.stiffness[:, k] / scale)
        gap = net.rest_gap
        rows = ~np.isnan(gap[:, 0])
        lig[np.ix_(rows, [lg.L_OX, lg.L_OY])] = (centres[ub] + image - centres[ua] - gap)[rows]
    contact = () if cfg.contact is None else uc.contact_pairs(
        vertices, centres, links, cfg.contact.stiffness_n_per_m / kl, cfg.contact.cutoff_m / a, image)
    args = lg.NetworkArgs(ua, ub, lig, np.zeros(n), np.zeros(n), law, *contact)
    mass = np.concatenate([mass_si / m, mass_si / m, inertia_si / (m * a * a)])
    inv_mass = 1.0 / mass
    if net.full_grid:
        ends = edge_sites(cfg.n_rows, cfg.n_cols)
    else:
        ends = bounding_ends(centres, np.ptp(vertices, 1).max(1))
    hold_fixed_ends(cfg, inv_mass, ends, n)
    for name in cfg.fixed_units:
        inv_mass[np.concatenate([np.asarray(groups[name]) + f * n for f in range(3)])] = 0.0
    if net.full_grid:  # the links along the rows (first in both generators, and the wraps of a periodic x)
        pairs = np.flatnonzero(net.grid[0][ua] == net.grid[0][ub])
    else:
        pairs = np.arange(ua.size)
    two_d = cfg.n_rows > 1 or not net.full_grid
    coords = {"x": centres[:, 0] * a}
    if two_d:
        coords["y"] = centres[:, 1] * a
    attrs = {}
    if net.grid is not None and cfg.n_rows > 1:
        coords |= {"row": net.grid[0], "col": net.grid[1]}
        attrs = COORD_ATTRS
    joined = np.hypot(*(centres[ub] + image - centres[ua]).T)
    inside = np.ones(ua.size, bool) if net.cell is None else ~np.any(net.shifts, 1)  # wraps are not drawn
    spacing = column_pitch(cfg) if net.full_grid else a * float(np.median(joined))
    return System(
        model=cfg.kind, fields=FIELDS, n_sites=n, scales=Scales(a, math.sqrt(m / kl), m),
        mass=mass, inv_mass=inv_mass, args=args, q0=np.zeros(3 * n), v0=np.zeros(3 * n),
        spacing_m=spacing, site_coords=coords,
        ends=ends,
        grid_shape=(cfg.n_rows, cfg.n_cols) if cfg.n_rows > 1 and net.full_grid else None,
        site_coord_attrs=attrs, site_groups=groups,
        neighbour_pairs=np.stack([ua[pairs], ub[pairs]], 1),
        shapes=UnitShapes(centres, vertices - centres[:, None, :], np.ones(n), np.stack([ua[inside], ub[inside]], 1),
                          np.stack([lig[inside][:, [lg.L_AX, lg.L_AY]], lig[inside][:, [lg.L_BX, lg.L_BY]]], 1)),
        periodic=None if net.cell is None else PeriodicCell(net.cell.copy(), net.shifts.copy()),
    )
