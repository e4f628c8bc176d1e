"""``flexmm export RUN --format svg``: a run's reference geometry as an SVG drawing for fabrication.

Read from the units' shapes the dataset stores (``io.run_dataset.shape_variables``: centres,
polygons, ligaments and their attachment points), as ``render.structure.ShapeStructure`` reads them
for every rigid-unit model, so no kind is named. One ``<polygon>`` per unit (its distinct vertices, in order)
in a group ``units``, one ``<line>`` per ligament between its two attachment points in a group
``ligaments`` (a zero-length ligament is a line of zero length), each carrying its ``data-site`` /
``data-sites``. Coordinates are millimetres with y pointing up (the SVG's y is flipped by the
group ``transform``), so ``x_mm = 1000 x``, ``y_mm = 1000 y`` inside it; the page (``width``,
``height`` in mm) and ``viewBox`` frame the geometry with a margin.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from flexmm.errors import OutputError, UsageError
from flexmm.io.atomic import write_text_atomic
from flexmm.models.geometry import distinct_vertices
from flexmm.render.api import load_lattice
from flexmm.render.source import RunSource
from flexmm.render.structure import ShapeStructure, make_structure


def _num(x: float) -> str:
    return repr(round(float(x), 9))


def svg_text(polygons: list[np.ndarray], segments: np.ndarray, sites: np.ndarray, link_sites: np.ndarray,
             stroke_mm: float = 0.1) -> str:
    """The SVG of ``polygons`` (each (V, 2), mm) and ligament ``segments`` (L, 2, 2) (mm), y up."""
    pts = np.concatenate([np.concatenate(polygons), segments.reshape(-1, 2)])
    lo, hi = pts.min(0), pts.max(0)
    margin = 0.05 * float(np.max(hi - lo)) + stroke_mm
    x0, y0 = lo[0] - margin, -(hi[1] + margin)
    w, h = float(hi[0] - lo[0]) + 2 * margin, float(hi[1] - lo[1]) + 2 * margin
    rows = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{_num(w)}mm" height="{_num(h)}mm" '
            f'viewBox="{_num(x0)} {_num(y0)} {_num(w)} {_num(h)}">',
            '<g transform="scale(1,-1)">',
            f'<g id="units" fill="none" stroke="black" stroke-width="{_num(stroke_mm)}">']
    for site, p in zip(sites.tolist(), polygons):
        coords = " ".join(f"{_num(x)},{_num(y)}" for x, y in p)
        rows.append(f'<polygon data-site="{site}" points="{coords}"/>')
    rows += ["</g>", f'<g id="ligaments" stroke="red" stroke-width="{_num(stroke_mm)}">']
    for (a, b), ((xa, ya), (xb, yb)) in zip(link_sites.tolist(), segments):
        rows.append(f'<line data-sites="{a} {b}" x1="{_num(xa)}" y1="{_num(ya)}" x2="{_num(xb)}" y2="{_num(yb)}"/>')
    rows += ["</g>", "</g>", "</svg>", ""]
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + "\n".join(rows)


def export_svg(run, out: str | Path | None = None, log: Callable[[str], None] | None = None) -> Path:
    """Write the reference geometry of ``run`` as SVG (default ``RUN/<name>.svg``); the path written."""
    with RunSource(run) as src:
        sites = src.sites
        structure = make_structure(src, load_lattice(src), "polygon", 1.0)
        if not isinstance(structure, ShapeStructure):
            raise UsageError(f"{src.path}: model {src.model!r} stores no unit shapes; --format svg draws the "
                             "rigid units of the models that store them")
        if not np.array_equal(sites, np.arange(sites.size)):
            raise UsageError(f"{src.path}: the run saved every {int(sites[1] - sites[0])}-th unit only "
                             "(output.site_stride); the drawing would miss units: run it with site_stride 1")
        target = Path(out) if out is not None else src.path.parent / f"{src.name}.svg"
        centre, links = structure.rest_xy * 1e3, structure.links
        polygons = [distinct_vertices(centre[k] + 1e3 * structure.vertices[k]) for k in range(sites.size)]
        segments = centre[links] + 1e3 * structure.link_points if links.size else np.zeros((0, 2, 2))
        text = svg_text(polygons, segments, sites, links)
    try:
        write_text_atomic(target, text)
    except OSError as exc:
        raise OutputError(f"cannot write {target}: {exc.strerror or exc}") from None
    if log:
        log(f"wrote {target}: {len(polygons)} units, {links.shape[0]} ligaments (mm, y up)")
    return target


__all__ = ["export_svg", "svg_text"]
