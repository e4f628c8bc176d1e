"""Plane geometry of rigid networks: the checks a network's polygons and ligaments must pass, unit
sets and masks (which units a box, circle, outline or hole holds), and cutting a network to the
units kept. Pure numpy on arrays; no config objects beyond reading their fields.

Checks (``geometry_issues``), each reported with the path of what is wrong (``("units", k)``,
``("ligaments", k)``): a polygon with two coincident vertices, with crossing edges (self-
intersecting), that is not convex, or of zero area; two units whose interiors overlap (convex
polygons: no separating axis among their edge normals, by more than ``tol``; units touching at a
vertex or along an edge do not overlap); a ligament naming a unit or vertex that does not exist; a
network that falls into pieces. A polygon is a (V, 2) array of its vertices in order; padded
polygons (the last vertex repeated, for units of fewer vertices than the largest) are given with
their own vertex count.
"""

from __future__ import annotations

import numpy as np

from flexmm.errors import FlexmmError


class GeometryError(FlexmmError, ValueError):
    """A network that cannot be built as configured: a mask that keeps nothing or cuts it into
    pieces, a unit set that holds no unit (geometry files report their faults as ConfigError)."""


def _cross(o, a, b) -> float:
    return float((a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]))


def _segments_cross(p, q, r, s) -> bool:
    """Whether the closed segments pq and rs intersect."""
    d1, d2, d3, d4 = _cross(r, s, p), _cross(r, s, q), _cross(p, q, r), _cross(p, q, s)
    if ((d1 > 0) != (d2 > 0) and d1 * d2 != 0) and ((d3 > 0) != (d4 > 0) and d3 * d4 != 0):
        return True
    def on(a, b, c):  # c on segment ab, given collinear
        return min(a[0], b[0]) <= c[0] <= max(a[0], b[0]) and min(a[1], b[1]) <= c[1] <= max(a[1], b[1])
    return ((d1 == 0 and on(r, s, p)) or (d2 == 0 and on(r, s, q)) or (d3 == 0 and on(p, q, r))
            or (d4 == 0 and on(p, q, s)))


def polygon_issue(poly: np.ndarray, tol: float) -> str | None:
    """What is wrong with one polygon (V, 2), or None: coincident vertices, crossing edges, not
    convex, zero area."""
    v = poly.shape[0]
    for i in range(v):
        for j in range(i + 1, v):
            if np.hypot(*(poly[i] - poly[j])) <= tol:
                return f"vertices {i} and {j} coincide ({poly[i].tolist()}): a duplicate vertex"
    for i in range(v):
        for j in range(i + 2, v):
            if i == 0 and j == v - 1:
                continue  # adjacent through the closing edge
            if _segments_cross(poly[i], poly[(i + 1) % v], poly[j], poly[(j + 1) % v]):
                return f"edges {i}-{(i + 1) % v} and {j}-{(j + 1) % v} cross: the polygon is self-intersecting"
    turns = [_cross(poly[i], poly[(i + 1) % v], poly[(i + 2) % v]) for i in range(v)]
    scale = max(float(np.ptp(poly, 0).max()), tol) ** 2
    if any(t > 1e-12 * scale for t in turns) and any(t < -1e-12 * scale for t in turns):
        bad = [(i + 1) % v for i, t in enumerate(turns) if np.sign(t) != np.sign(sum(turns))]
        return f"not convex (turns the other way at vertex {bad[0]}); a rigid unit is a convex polygon"
    if abs(sum(turns)) <= 1e-12 * scale:
        return "zero area"
    return None


def _projections(poly: np.ndarray, axes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    p = poly @ axes.T
    return p.min(0), p.max(0)


def overlap_depth(p1: np.ndarray, p2: np.ndarray) -> float:
    """How far two convex polygons interpenetrate: the smallest overlap of their projections on
    the edge normals of both (≤ 0: a separating axis exists, they at most touch)."""
    axes = []
    for p in (p1, p2):
        e = np.roll(p, -1, 0) - p
        n = np.stack([-e[:, 1], e[:, 0]], 1)
        length = np.hypot(n[:, 0], n[:, 1])
        axes.append(n[length > 0] / length[length > 0, None])
    axes = np.concatenate(axes)
    lo1, hi1 = _projections(p1, axes)
    lo2, hi2 = _projections(p2, axes)
    return float(np.min(np.minimum(hi1, hi2) - np.maximum(lo1, lo2)))


def overlapping_pairs(polys: list[np.ndarray], tol: float) -> list[tuple[int, int]]:
    """Pairs (i < j) of convex polygons that overlap by more than ``tol`` (bounding boxes hashed
    on a grid of the largest box's size, so only near pairs are tested)."""
    lo = np.array([p.min(0) for p in polys])
    hi = np.array([p.max(0) for p in polys])
    cell = max(float(np.max(hi - lo)), tol)
    grid: dict[tuple[int, int], list[int]] = {}
    for k, c in enumerate(np.floor(lo / cell).astype(np.int64)):
        grid.setdefault((int(c[0]), int(c[1])), []).append(k)
    out = set()
    for (cx, cy), members in grid.items():
        near = [j for dx in (-1, 0, 1) for dy in (-1, 0, 1) for j in grid.get((cx + dx, cy + dy), [])]
        for i in members:
            for j in near:
                if j > i and np.all(lo[i] < hi[j] - tol) and np.all(lo[j] < hi[i] - tol):
                    if overlap_depth(polys[i], polys[j]) > tol:
                        out.add((i, j))
    return sorted(out)


def pieces(n: int, a: np.ndarray, b: np.ndarray) -> list[np.ndarray]:
    """The connected pieces of n units joined by links (a, b), largest first (union-find)."""
    parent = np.arange(n)

    def root(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for i, j in zip(a.tolist(), b.tolist()):
        ri, rj = root(i), root(j)
        if ri != rj:
            parent[max(ri, rj)] = min(ri, rj)
    roots = np.array([root(i) for i in range(n)])
    groups = [np.flatnonzero(roots == r) for r in np.unique(roots)]
    return sorted(groups, key=lambda g: (-g.size, g[0]))


def describe_pieces(groups: list[np.ndarray]) -> str:
    """'the network falls into 3 pieces: units 4, 5 and units 9 are not joined to unit 0 ...'."""
    def listed(g):
        head = ", ".join(str(int(k)) for k in g[:8])
        return head + (f", ... ({g.size} units)" if g.size > 8 else "")
    rest = "; ".join(f"units {listed(g)}" for g in groups[1:4]) + ("; ..." if len(groups) > 4 else "")
    return (f"the network falls into {len(groups)} disconnected pieces: {rest} are not joined to the "
            f"{groups[0].size} units of unit {int(groups[0][0])}'s piece; a disconnected piece drifts freely")


def geometry_issues(polys: list[np.ndarray], a, i, b, j) -> list[tuple[tuple, str]]:
    """Every problem of a network of polygons (each (V_k, 2)) and ligaments (vertex i of unit a to
    vertex j of unit b), as (path, message): ``("units", k)`` or ``("ligaments", k)``, ``()`` for
    the whole network. Tolerances are 10⁻⁹ of the median polygon size."""
    n = len(polys)
    size = float(np.median([np.ptp(p, 0).max() for p in polys]))
    tol = 1e-9 * size
    issues = []
    for k, p in enumerate(polys):
        why = polygon_issue(p, tol)
        if why:
            issues.append((("units", k), f"unit {k}: {why}"))
    for k, (ua, va, ub, vb) in enumerate(zip(a, i, b, j)):
        for unit, vertex, name in ((ua, va, "a"), (ub, vb, "b")):
            if unit >= n:
                issues.append((("ligaments", k, name), f"ligament {k}: unit {unit} does not exist (units 0..{n - 1})"))
            elif vertex >= polys[unit].shape[0]:
                issues.append((("ligaments", k, "i" if name == "a" else "j"),
                               f"ligament {k}: unit {unit} has no vertex {vertex} (it has {polys[unit].shape[0]})"))
    if issues:
        return issues  # overlap and connectivity need valid polygons and ligaments
    for p, q in overlapping_pairs(polys, 1e-6 * size):
        issues.append((("units", q), f"units {p} and {q} overlap (by {overlap_depth(polys[p], polys[q]):.3g} m)"))
    groups = pieces(n, np.asarray(a), np.asarray(b))
    if len(groups) > 1:
        issues.append((("units", int(groups[1][0])), describe_pieces(groups)))
    return issues


def inside(points: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """(P,) whether each point (P, 2) lies inside the polygon (V, 2) (even-odd rule)."""
    x, y = points[:, 0][:, None], points[:, 1][:, None]
    x0, y0 = poly[:, 0][None, :], poly[:, 1][None, :]
    x1, y1 = np.roll(poly[:, 0], -1)[None, :], np.roll(poly[:, 1], -1)[None, :]
    crosses = (y0 > y) != (y1 > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        xc = x0 + (y - y0) * (x1 - x0) / (y1 - y0)
    return np.sum(crosses & (x < xc), 1) % 2 == 1


def in_circle(points: np.ndarray, circle) -> np.ndarray:
    return np.hypot(points[:, 0] - circle[0], points[:, 1] - circle[1]) <= circle[2]


def unit_set(spec, centres_m: np.ndarray) -> np.ndarray:
    """The units (indices) of a ``config.geometry.UnitSet`` given the units' centres (N, 2) in m."""
    if spec.units is not None:
        return np.asarray(spec.units, np.int64)
    if spec.box_m is not None:
        x0, y0, x1, y1 = spec.box_m
        x, y = centres_m[:, 0], centres_m[:, 1]
        return np.flatnonzero((x >= x0) & (x <= x1) & (y >= y0) & (y <= y1))
    return np.flatnonzero(in_circle(centres_m, spec.circle_m))


def mask_keep(mask, centres_m: np.ndarray) -> np.ndarray:
    """(N,) which units a ``config.network.Mask`` keeps: centre inside the outline, outside every hole."""
    keep = np.ones(centres_m.shape[0], bool) if mask.outline_m is None else inside(centres_m, np.asarray(mask.outline_m))
    for hole in mask.holes:
        keep &= ~(in_circle(centres_m, hole.circle_m) if hole.circle_m is not None
                  else inside(centres_m, np.asarray(hole.polygon_m)))
    return keep


def padded(polys: list[np.ndarray]) -> np.ndarray:
    """(N, V, 2) of polygons of up to V vertices, each padded by repeating its last vertex (a
    zero-length edge: areas, inertias and drawings are unchanged)."""
    v = max(p.shape[0] for p in polys)
    return np.stack([np.concatenate([p, np.repeat(p[-1:], v - p.shape[0], 0)]) for p in polys])


def distinct_vertices(poly: np.ndarray) -> np.ndarray:
    """A padded polygon (V, 2) without the repeated trailing vertices."""
    keep = [0] + [k for k in range(1, poly.shape[0]) if np.any(poly[k] != poly[k - 1])]
    out = poly[keep]
    return out[:-1] if out.shape[0] > 1 and np.all(out[-1] == out[0]) else out
