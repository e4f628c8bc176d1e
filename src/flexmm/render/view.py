"""What part of a run to show and how to label it: the view, the space–time diagram, titles."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from flexmm.config.lattice import MODELS
from flexmm.errors import UsageError
from flexmm.render.colour import Colouring
from flexmm.render.figure import bounds
from flexmm.render.source import RunSource
from flexmm.render.structure import Drawing, MassStructure, ShapeStructure

#: rows of the space–time diagram at most
SPACETIME_ROWS = 600


@dataclass
class SpaceTime:
    """The space–time diagram: values (n_t, n_x) at positions x (m) and times t (s)."""

    x: np.ndarray
    t: np.ndarray
    values: np.ndarray
    title: str
    xlabel: str = "x (m)"
    shares_x: bool = True


def columns(structure) -> np.ndarray:
    """Column (chain: unit) index of each drawn site, for --sites and the space–time diagram."""
    sites = structure.sites
    if isinstance(structure, ShapeStructure):
        return structure.col
    if structure.p.grid_shape is not None:
        return sites % structure.p.grid_shape[0]
    return sites


def rows(structure) -> np.ndarray:
    """Row index of each drawn site (0 for chains and networks)."""
    sites = structure.sites
    if isinstance(structure, ShapeStructure):
        return structure.row
    if structure.p.grid_shape is not None:
        return sites // structure.p.grid_shape[0]
    return np.zeros(sites.size, np.int64)


def view_extent(structure, drawings, sites: tuple[int, int] | None) -> tuple[float, float, float, float]:
    """The region to show: everything drawn in the sampled frames (or the --sites columns), padded."""
    if sites is not None:
        col = columns(structure)
        pick = (col >= sites[0]) & (col < sites[1])
        if not pick.any():
            raise UsageError(f"--sites {sites[0]}:{sites[1]}: no drawn unit in that range "
                             f"(columns 0 to {int(col.max())})")
        drawings = [_only(d, pick) for d in drawings]
    b = np.array([bounds(d) for d in drawings])
    x0, x1, y0, y1 = b[:, 0].min(), b[:, 1].max(), b[:, 2].min(), b[:, 3].max()
    if sites is not None and not _branched(structure):
        yb = np.array([bounds(d)[2:] for d in drawings])  # rows: keep the whole height in view
        y0, y1 = min(y0, yb[:, 0].min()), max(y1, yb[:, 1].max())
    pad = 0.25 * structure.spacing_m
    return x0 - pad, x1 + pad, y0 - pad, y1 + pad


def _branched(structure) -> bool:
    """A lattice of masses on branches (a network): its sites are not along x."""
    return isinstance(structure, MassStructure) and MODELS[structure.p.kind].branched


def _only(d: Drawing, pick: np.ndarray) -> Drawing:
    """The units (bodies) of a drawing selected by ``pick`` (ghost rows follow their units)."""
    if d.polygons is not None:
        reps = 1 if d.ghosts is None else 1 + d.ghosts.shape[0] // d.polygons.shape[0]
        polys = d.polygons[pick] if d.ghosts is None else np.concatenate(
            [d.polygons[pick]] + [g[pick] for g in np.split(d.ghosts, reps - 1)])
        return Drawing(polygons=polys)
    return Drawing(bodies=d.bodies[pick], body_radius_m=d.body_radius_m)


def make_spacetime(src: RunSource, structure, colouring: Colouring, indices: np.ndarray, row: int | None,
                   needed: list[str]) -> SpaceTime:
    """Colour values along one row of sites (sheets, grids: --row, default the middle) over time."""
    if colouring.values is None:
        raise UsageError("--spacetime shows the colour quantity: choose one (not --color none)")
    r = rows(structure)
    n_rows = int(r.max()) + 1
    pick_row = (n_rows // 2 if row is None else row)
    if not 0 <= pick_row < n_rows:
        raise UsageError(f"--row {pick_row}: the lattice has rows 0 to {n_rows - 1}")
    network = _branched(structure)
    sel = np.flatnonzero(r == pick_row)
    x = structure.rest_xy[sel, 0] if not network else structure.sites[sel].astype(float)
    order = np.argsort(x, kind="stable")
    sel, x = sel[order], x[order]
    stride = max(1, math.ceil(indices.size / SPACETIME_ROWS))
    idx = indices[::stride]
    values = np.empty((idx.size, sel.size))
    for k, (_, _, frame) in enumerate(src.frames(idx, needed)):
        values[k] = colouring.values(frame)[sel]
    where = f", row {pick_row}" if n_rows > 1 else ""
    return SpaceTime(x, src.time[idx], values, f"space–time: {colouring.label}{where}",
                     xlabel="site" if network else "x (m)", shares_x=not network)


def describe(src: RunSource, lattice, structure, scale: float) -> tuple[str, str]:
    """(title, subtitle): the run's name and status; model, size, exaggeration."""
    title = src.name + ("" if src.status == "finished" else f" — {src.status.upper()} RUN")
    kind = lattice.kind
    n = structure.sites.size
    size = {"rotating_squares_sheet": lambda: f"{lattice.n_cols} columns × {lattice.n_rows} rows of units",
            "bistable_linkage": lambda: f"{lattice.n_cols} columns × 2 rows of crosses",
            "mass_grid": lambda: f"{lattice.nx} columns × {lattice.ny} rows of masses",
            "mass_network": lambda: f"{len(lattice.branches)} branches, {n} masses",
            "mass_chain": lambda: f"{n} masses"}.get(kind, lambda: f"{n} units")()
    images = structure.colour_repeats()
    if images:
        size += f", n_lateral = {images} (mirror row{'s' if images > 1 else ''} shaded)"
    if n != getattr(lattice, "n_units", n) and getattr(lattice, "mask", None) is None:  # a mask removes units
        size += f" ({n} saved: output.site_stride > 1)"
    what = "displacements and rotations" if isinstance(structure, ShapeStructure) else "displacements"
    scale_txt = "drawn to scale" if scale == 1 else f"{what} ×{scale:g} (exaggerated)"
    planned = str(src.attrs.get("plan_dimension", "kept"))
    reduced = "" if planned in ("kept", "") else f" ({planned})"
    return title, f"{MODELS[kind].label or kind} · {size}{reduced} · {scale_txt}"


def palette_colours(colouring: Colouring) -> np.ndarray | None:
    """Colours a movie's palette must hold: the colour map, plain and shaded (ghost units)."""
    from matplotlib import colormaps

    from flexmm.render.figure import WELL_COLOURS

    if colouring.values is None:
        return None
    if colouring.categories is not None:
        from matplotlib.colors import to_rgb

        rgb = np.array([to_rgb(c) for c in WELL_COLOURS[: len(colouring.categories)]])
    else:
        rgb = colormaps[colouring.cmap](np.linspace(0, 1, 64))[:, :3]
    shaded = 0.4 * rgb + 0.6
    return (255 * np.concatenate([rgb, shaded])).astype(np.uint8)


__all__ = ["SpaceTime", "columns", "describe", "make_spacetime", "palette_colours", "rows",
           "view_extent"]
