"""What to draw of a run at one frame: unit polygons, hinge and spring lines, bodies.

``make_structure(source, lattice, shape, exaggeration)``: rigid units of any model, drawn from the
shapes its dataset stores (``ShapeStructure``), or masses (chain, network, grid). Given one frame of
the dataset's fields, ``Structure.draw(frame)`` returns a ``Drawing`` in metres. Exaggeration
scales every field's departure from rest (the predeformed state, if any): displacements and
rotations alike, so a small-amplitude picture is the linear mode shape magnified.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from flexmm.config.lattice import MODELS
from flexmm.errors import UsageError
from flexmm.io.run_dataset import OUTLINES, shape_variables
from flexmm.render.masses import MassParams, mass_params
from flexmm.render.params import rigid_params

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


#: arm half-width of the ``cross`` and ``bars`` outlines, as a fraction of the centre-to-vertex distance
ARM_WIDTH = {"cross": 0.28, "bars": 0.07}
#: ``--shape`` names of the outlines (``square``: a unit's own polygon)
SHAPE_NAMES = {"square": "polygon", "polygon": "polygon", "cross": "cross", "bars": "bars"}


def outlines(centres: np.ndarray, points: np.ndarray, outline: str) -> np.ndarray:
    """Polygons (N, V', 2) of units at ``centres`` (N, 2) whose vertices are ``points`` (N, V, 2):
    the polygon itself (V' = V), or arms from the centre to each vertex (V' = 3V: the end of arm k
    is a segment through vertex k, along arm k + 1, and the corner between arms k and k + 1)."""
    if outline == "polygon":
        return points
    c = centres[:, None, :]
    e = points - c  # arm k, from the centre to vertex k
    w = ARM_WIDTH[outline] * e  # along arm k: the arms' half-width
    w_next = np.roll(w, -1, axis=1)  # along arm k + 1 (across arm k, for squares)
    tip_lo, tip_hi = c + e - w_next, c + e + w_next
    inner = c + w + w_next
    return np.stack([tip_lo, tip_hi, inner], axis=2).reshape(len(centres), 3 * e.shape[1], 2)


def _pair(shapes: dict, stem: str, shape: tuple) -> np.ndarray:
    """(…, 2) of the stored ``stem_x``, ``stem_y`` (zeros of ``shape`` if absent)."""
    if f"{stem}_x" not in shapes:
        return np.zeros(shape + (2,))
    return np.stack([np.asarray(shapes[f"{stem}_x"], float), np.asarray(shapes[f"{stem}_y"], float)], -1)


class ShapeStructure:
    """Rigid units drawn from the shapes their dataset stores (``io.run_dataset.shape_variables``):
    each unit's polygon placed by (u, v) and turned by rotation_sign · θ, outlined as the model
    says (or ``outline``), each joint a line between its two attachment points, points fixed to
    the units (magnets) or the joints as dots, and mirror images across the row (a chain's lateral
    hinges) as ghosts. ``params``: the lattice's ``render.params.RigidParams`` where it has them
    (the energy and well colourings), else None."""

    def __init__(self, shapes: dict, sites: np.ndarray, coords: dict, rest: dict, scale: float,
                 fields: list[str], outline: str | None = None, params=None):
        self.sites, self.rest, self.scale, self.p = sites, rest, scale, params
        n = sites.size
        self.vertices = _pair(shapes, "unit_vertex", (n, 0))  # (n, V, 2)
        self.sign = np.asarray(shapes.get("rotation_sign", np.ones(n)), float)
        self.angle = np.asarray(shapes.get("unit_angle", np.zeros(n)), float)
        self.links = np.asarray(shapes.get("link_site", np.zeros((0, 2), np.int64)), np.int64)
        self.link_points = _pair(shapes, "link_point", (0, 2))  # (L, 2, 2)
        self.markers = _pair(shapes, "unit_marker", (n, 0))  # (n, M, 2)
        self.joints = bool(shapes.get("link_joint", 0))
        self.images = np.asarray(shapes.get("unit_image_offset", np.zeros((n, 0))), float)
        self.image_vertex = np.asarray(shapes.get("image_vertex", np.zeros(0, np.int64)), np.int64)
        self.outline = outline or OUTLINES[int(shapes.get("unit_outline", 0))]
        self.rest_xy = _pair(shapes, "unit_centre", (n,))
        self.col = np.asarray(coords.get("col", sites), np.int64)
        self.row = np.asarray(coords.get("row", np.zeros(n)), np.int64)
        self.fields = [name for name in ("u", "v", "theta") if name in fields]
        gaps = np.hypot(*(self.rest_xy[self.links[:, 1]] - self.rest_xy[self.links[:, 0]]).T)
        self.spacing_m = float(np.median(gaps)) if gaps.size else float(np.ptp(self.vertices[..., 0]))

    def state(self, frame: dict) -> tuple[np.ndarray, np.ndarray]:
        """Drawn centres (n, 2) and rotations from the reference configuration (n,) of the units."""
        n = self.sites.size
        centres = self.rest_xy.copy()
        centres[:, 0] += _scaled(frame, self.rest, "u", self.scale, n)
        centres[:, 1] += _scaled(frame, self.rest, "v", self.scale, n)
        return centres, self.sign * _scaled(frame, self.rest, "theta", self.scale, n)

    def orientation(self, phi: np.ndarray) -> np.ndarray:
        """The units' orientations: their reference angle plus the rotation ``phi`` (``state``)."""
        return self.angle + phi

    def draw(self, frame: dict) -> Drawing:
        """The units' outlines, their joints' lines and dots, and their mirror images at one frame."""
        centres, phi = self.state(frame)
        c, s = np.cos(phi), np.sin(phi)

        def placed(unit, body):  # centre + R(φ) body, body (..., 2) for each unit
            cu, su = c[unit], s[unit]
            x = cu * body[..., 0] - su * body[..., 1]
            y = su * body[..., 0] + cu * body[..., 1]
            return centres[unit] + np.stack([x, y], -1)

        units = np.arange(self.sites.size)
        points = placed(units[:, None], self.vertices)
        segs = [np.stack([placed(self.links[:, k], self.link_points[:, k]) for k in range(2)], 1)]
        ghosts = []
        nv = self.vertices.shape[1]
        order = -np.arange(nv) % nv  # a reflection's vertices in reverse order: counter-clockwise again
        for k, vertex in enumerate(self.image_vertex):  # the unit reflected about its row, shifted
            image = centres + np.stack([np.zeros(units.size), self.images[:, k]], 1)
            mirrored = image[:, None, :] + (points[:, order] - centres[:, None, :]) * [1.0, -1.0]
            ghosts.append(outlines(image, mirrored, self.outline))
            segs.append(np.stack([points[:, vertex], mirrored[:, order[vertex]]], 1))
        lines = np.concatenate(segs)
        dots = None
        if self.markers.shape[1]:
            dots = placed(units[:, None], self.markers).reshape(-1, 2)
        elif self.joints and segs[0].size:
            dots = 0.5 * (segs[0][:, 0] + segs[0][:, 1])
        return Drawing(polygons=outlines(centres, points, self.outline),
                       ghosts=np.concatenate(ghosts) if ghosts else None,
                       lines=lines if lines.size else None, dots=dots,
                       edge="face" if self.outline == "bars" else "#222222")

    def colour_repeats(self) -> int:
        """Ghost rows repeat the units' colours this many times."""
        return self.image_vertex.size


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
    """The Structure of a run: its units drawn from the shapes its dataset stores (a dataset
    written before they were stored: from its model built again), or its masses."""
    if "x" not in source.coords:
        raise UsageError(f"{source.path} has no site positions (coordinate 'x'): cannot draw its structure")
    if MODELS[lattice.kind].topology is not None:  # a lattice of masses
        stored = source.coords.get("u_rest")  # u is measured from it (no relaxation needed)
        rest = None if stored is None else (source.sites, np.asarray(stored, float))
        return MassStructure(mass_params(lattice, rest), source.sites, scale)
    shapes = source.shapes or _built_shapes(source, lattice)
    return ShapeStructure(shapes, source.sites, source.coords, source.rest, scale, source.fields,
                          SHAPE_NAMES[shape] if shape else None, rigid_params(lattice))


def _built_shapes(source, lattice) -> dict:
    """The shape variables of a dataset that does not store them, from its model built again."""
    from flexmm.models import MODELS

    builder = MODELS.get(lattice.kind)
    system = builder.build(lattice) if builder is not None else None
    if system is None or system.unit_shapes() is None:
        raise UsageError(f"cannot draw model {lattice.kind!r}")
    length = system.scales.length_m
    return {name: values for name, (_, values, *_) in shape_variables(system.unit_shapes(), source.sites, length).items()}


__all__ = ["Drawing", "MassStructure", "ShapeStructure", "make_structure", "outlines", "springs"]
