"""What to draw of a run at one frame: unit polygons, hinge and spring lines, bodies.

``make_structure(source, lattice, shape, exaggeration)`` picks the kind: rigid units (rotating-
squares chain and sheet, bistable linkage) or masses (chain, network, grid). Given one frame of
the dataset's fields, ``Structure.draw(frame)`` returns a ``Drawing`` in metres. Exaggeration
scales every field's departure from rest (the predeformed state, if any): displacements and
rotations alike, so a small-amplitude picture is the linear mode shape magnified.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from flexmm.errors import UsageError
from flexmm.render import rigid
from flexmm.render.masses import MassParams, mass_params
from flexmm.render.params import RigidParams, rigid_params

RIGID_KINDS = ("rotating_squares_chain", "rotating_squares_sheet", "bistable_linkage")
MASS_KINDS = ("mass_chain", "mass_network", "mass_grid")
DEFAULT_SHAPE = {"rotating_squares_chain": "cross", "rotating_squares_sheet": "square", "bistable_linkage": "bars"}
#: draw springs as zigzags up to this many bonds (straight lines beyond)
ZIGZAG_MAX_BONDS = 400


@dataclass
class Drawing:
    """One frame's geometry (metres): coloured polygons (units) and ghosts (mirror rows) of shape
    (M, V, 2), line segments (K, P, 2), body centres (B, 2) with one radius, marker points (D, 2)."""

    polygons: np.ndarray | None = None
    ghosts: np.ndarray | None = None
    lines: np.ndarray | None = None
    bodies: np.ndarray | None = None
    body_radius_m: float = 0.0
    dots: np.ndarray | None = None
    #: outline colour of the units ("face": none, thin bars)
    edge: str = "#222222"


def _scaled(frame: dict, rest: dict, name: str, scale: float, n: int) -> np.ndarray:
    """rest + scale · (field − rest) of one field (zeros if the field is absent from the model)."""
    value = frame.get(name)
    if value is None:
        return np.zeros(n)
    base = rest.get(name)
    if base is None:
        return scale * value
    return base + scale * (value - base)


class RigidStructure:
    """Rotating units: each drawn unit is a saved site, placed and turned by u, v, θ."""

    def __init__(self, p: RigidParams, sites: np.ndarray, coords: dict, rest: dict, shape: str, scale: float):
        self.p, self.sites, self.rest, self.shape, self.scale = p, sites, rest, shape, scale
        if sites.size and sites.max() >= p.n_units:
            raise UsageError(f"the dataset has site {sites.max()} but its config has {p.n_units} units")
        self.index = np.full(p.n_units, -1, np.int64)
        self.index[sites] = np.arange(sites.size)
        y = coords.get("y", np.zeros(sites.size))
        self.rest_xy = np.stack([np.asarray(coords["x"], float), np.asarray(y, float)], 1)
        self.fields = ["u", "theta"] + (["v"] if p.kind != "rotating_squares_chain" else [])
        self.spacing_m = 2 * p.half_m * float(np.cos(np.mean(p.theta0_rad)))

    def state(self, frame: dict) -> tuple[np.ndarray, np.ndarray]:
        """Drawn centres (n, 2) and orientations φ (n,) of the saved units."""
        n = self.sites.size
        centres = self.rest_xy.copy()
        centres[:, 0] += _scaled(frame, self.rest, "u", self.scale, n)
        centres[:, 1] += _scaled(frame, self.rest, "v", self.scale, n)
        theta = _scaled(frame, self.rest, "theta", self.scale, n)
        return centres, rigid.orientation(self.p, self.sites, theta)

    def draw(self, frame: dict) -> Drawing:
        """Units, their mirror rows, hinge lines and markers (pins, magnets) at one frame."""
        centres, phi = self.state(frame)
        pts = rigid.hinge_points(centres, phi, self.p.half_m)
        segs = [rigid.hinge_segments(self.p, self.index, pts)]
        ghosts = []
        for k, (gc, gphi) in enumerate(rigid.mirror_units(self.p, self.sites, centres, phi)):
            gpts = rigid.hinge_points(gc, gphi, self.p.half_m)
            ghosts.append(rigid.outlines(gc, gpts, self.shape))
            below = k == 0  # lateral hinge: bottom of the unit to top of the image below (or vice versa)
            segs.append(np.stack([pts[:, rigid.BOTTOM if below else rigid.TOP],
                                  gpts[:, rigid.TOP if below else rigid.BOTTOM]], 1))
        dots = None
        if self.p.magnets is not None:
            dots = self._magnets(centres, phi)
        elif self.p.joint is not None:
            seg = segs[0]
            dots = 0.5 * (seg[:, 0] + seg[:, 1])
        return Drawing(polygons=rigid.outlines(centres, pts, self.shape),
                       ghosts=np.concatenate(ghosts) if ghosts else None,
                       lines=np.concatenate(segs), dots=dots, edge="face" if self.shape == "bars" else "#222222")

    def _magnets(self, centres, phi) -> np.ndarray:
        """Face magnets: body-frame (±a/4, ±a/4) − recess along the face normal, turned by φ."""
        a, recess = 2 * self.p.half_m, self.p.magnets[0]
        r2 = 1 / np.sqrt(2)
        dirs = np.array([[r2, r2], [-r2, r2], [-r2, -r2], [r2, -r2]])
        body = 0.25 * a * np.sign(dirs) - recess * dirs  # (4, 2)
        c, s = np.cos(phi)[:, None], np.sin(phi)[:, None]
        x = centres[:, None, 0] + c * body[None, :, 0] - s * body[None, :, 1]
        y = centres[:, None, 1] + s * body[None, :, 0] + c * body[None, :, 1]
        return np.stack([x, y], -1).reshape(-1, 2)

    def colour_repeats(self) -> int:
        """Ghost rows repeat the units' colours this many times."""
        return self.p.n_lateral


class ShapeStructure:
    """Rigid units drawn from the shapes their dataset stores (any model that stores them): each
    unit's polygon placed by (u, v) and turned by rotation_sign · θ, each joint a line between its
    two attachment points."""

    def __init__(self, shapes: dict, sites: np.ndarray, coords: dict, rest: dict, scale: float):
        self.sites, self.rest, self.scale = sites, rest, scale
        self.vertices = np.stack([shapes["unit_vertex_x"], shapes["unit_vertex_y"]], -1)  # (n, V, 2)
        self.sign = np.asarray(shapes.get("rotation_sign", np.ones(sites.size)), float)
        self.links = np.asarray(shapes.get("link_site", np.zeros((0, 2), np.int64)), np.int64)
        self.link_points = np.stack([shapes.get("link_point_x", np.zeros((0, 2))),
                                     shapes.get("link_point_y", np.zeros((0, 2)))], -1)  # (L, 2, 2)
        self.rest_xy = np.stack([shapes["unit_centre_x"], shapes["unit_centre_y"]], 1)
        self.col = np.asarray(coords.get("col", sites), np.int64)
        self.row = np.asarray(coords.get("row", np.zeros(sites.size)), np.int64)
        self.fields = ["u", "v", "theta"]
        gaps = np.hypot(*(self.rest_xy[self.links[:, 1]] - self.rest_xy[self.links[:, 0]]).T)
        self.spacing_m = float(np.median(gaps)) if gaps.size else float(np.ptp(self.vertices[..., 0]))

    def draw(self, frame: dict) -> Drawing:
        """The units' polygons and the joints' lines at one frame."""
        n = self.sites.size
        centres = self.rest_xy.copy()
        centres[:, 0] += _scaled(frame, self.rest, "u", self.scale, n)
        centres[:, 1] += _scaled(frame, self.rest, "v", self.scale, n)
        phi = self.sign * _scaled(frame, self.rest, "theta", self.scale, n)
        c, s = np.cos(phi), np.sin(phi)

        def placed(unit, body):  # centre + R(φ) body, body (..., 2) for each unit
            cu, su = c[unit], s[unit]
            x = cu * body[..., 0] - su * body[..., 1]
            y = su * body[..., 0] + cu * body[..., 1]
            return centres[unit] + np.stack([x, y], -1)

        units = np.arange(n)
        polygons = placed(units[:, None], self.vertices)
        lines = np.stack([placed(self.links[:, k], self.link_points[:, k]) for k in range(2)], 1)
        return Drawing(polygons=polygons, lines=lines if lines.size else None)

    def colour_repeats(self) -> int:
        """No ghost rows."""
        return 0


class MassStructure:
    """Masses as bodies at rest + (initial displacement + u) along their branch, bonds as springs."""

    def __init__(self, p: MassParams, sites: np.ndarray, scale: float):
        self.p, self.sites, self.scale = p, sites, scale
        if sites.size and sites.max() >= p.n_sites:
            raise UsageError(f"the dataset has site {sites.max()} but its config has {p.n_sites} sites")
        self.index = np.full(p.n_sites, -1, np.int64)
        self.index[sites] = np.arange(sites.size)
        self.rest_xy, self.dirs = p.rest_xy[sites], p.direction[sites]
        self.x0 = p.x0[sites]
        keep = (self.index[p.bonds[:, 0]] >= 0) & (self.index[p.bonds[:, 1]] >= 0)
        self.bonds = self.index[p.bonds[keep]]
        self.fields = ["u"]
        self.spacing_m = p.spacing_m
        self.radius = (0.5 if p.beads else 0.3 if p.grid_shape is None else 0.22) * p.spacing_m
        self.zigzag = not p.beads and self.bonds.shape[0] <= ZIGZAG_MAX_BONDS

    def positions(self, frame: dict) -> np.ndarray:
        """Drawn body centres (n, 2)."""
        u = self.x0 + self.scale * frame["u"]
        return self.rest_xy + u[:, None] * self.dirs

    def draw(self, frame: dict) -> Drawing:
        """Bodies and springs at one frame."""
        pos = self.positions(frame)
        lines = None
        if not self.p.beads and self.bonds.size:
            a, b = pos[self.bonds[:, 0]], pos[self.bonds[:, 1]]
            lines = springs(a, b, self.radius) if self.zigzag else np.stack([a, b], 1)
        return Drawing(lines=lines, bodies=pos, body_radius_m=self.radius)

    def colour_repeats(self) -> int:
        """No ghost rows."""
        return 0


def springs(a: np.ndarray, b: np.ndarray, radius: float, coils: int = 4) -> np.ndarray:
    """Zigzag polylines (K, 2 coils + 4, 2) from the surface of body a to that of body b."""
    d = b - a
    length = np.hypot(d[:, 0], d[:, 1])
    unit = d / np.where(length > 0, length, 1.0)[:, None]
    normal = np.stack([-unit[:, 1], unit[:, 0]], 1)
    free = np.clip(length - 2 * radius, 0.0, None)
    s = np.concatenate([[0.0, 0.1], 0.1 + 0.8 * (np.arange(2 * coils) + 0.5) / (2 * coils), [0.9, 1.0]])
    side = np.concatenate([[0, 0], np.where(np.arange(2 * coils) % 2 == 0, 1.0, -1.0), [0, 0]])
    width = 0.5 * radius
    start = a + radius * unit
    return (start[:, None, :] + (free[:, None] * s[None, :])[..., None] * unit[:, None, :]
            + (width * side)[None, :, None] * normal[:, None, :])


def make_structure(source, lattice, shape: str | None, scale: float):
    """The Structure of a run (from its dataset's sites and its stored lattice config)."""
    kind = lattice.kind
    if "x" not in source.coords:
        raise UsageError(f"{source.path} has no site positions (coordinate 'x'): cannot draw its structure")
    if source.shapes:
        return ShapeStructure(source.shapes, source.sites, source.coords, source.rest, scale)
    if kind in RIGID_KINDS:
        shape = shape or DEFAULT_SHAPE[kind]
        return RigidStructure(rigid_params(lattice), source.sites, source.coords, source.rest, shape, scale)
    if kind in MASS_KINDS:
        stored = source.coords.get("u_rest")  # u is measured from it (no relaxation needed)
        rest = None if stored is None else (source.sites, np.asarray(stored, float))
        return MassStructure(mass_params(lattice, rest), source.sites, scale)
    raise UsageError(f"cannot draw model {kind!r}")


__all__ = ["Drawing", "MassStructure", "RigidStructure", "ShapeStructure", "make_structure", "springs"]
