"""The picture: structure panel, title with the run's status, time, length scale, colour bar and
an optional space–time diagram with a marker at the current time.

One ``Frame`` figure is built per render (matplotlib, Agg canvas, no pyplot) with its layout fixed
in pixels; each frame only updates the collections in place (``set_verts``, ``set_offsets``,
``set_array``) and redraws them over a cached background (blitting), so a movie costs one
collection redraw per frame, not a new figure.
"""

from __future__ import annotations

import math
import textwrap
from dataclasses import dataclass

import numpy as np

from flexmm.render.colour import Colouring
from flexmm.render.structure import Drawing

DPI = 100
WELL_COLOURS = ["#3b6fb6", "#e07b39", "#4e9f50", "#b5493f", "#8a63b8", "#8c6d3f"]


@dataclass
class Layout:
    """Panel heights and margins in pixels."""

    width: int
    title: int
    structure: int
    band: int
    spacetime: int
    bottom: int
    left: int
    right: int = 16

    @property
    def height(self) -> int:
        """Figure height in pixels (even)."""
        h = self.title + self.structure + self.band + self.spacetime + self.bottom
        return h + (h % 2)  # even, for video encoders


def time_unit(t_max: float) -> tuple[float, str]:
    """(factor, unit) to print times of a run lasting ``t_max`` seconds."""
    if t_max < 2e-3:
        return 1e6, "µs"
    if t_max < 2.0:
        return 1e3, "ms"
    return 1.0, "s"


def length_label(length_m: float) -> str:
    """'20 mm', '1.5 m', '200 µm'."""
    for factor, unit in ((1.0, "m"), (1e-3, "mm"), (1e-6, "µm")):
        if length_m >= factor * 0.999:
            return f"{length_m / factor:g} {unit}"
    return f"{length_m:.3g} m"


def nice_length(target_m: float) -> float:
    """The largest 1, 2 or 5 × 10^k not above ``target_m``."""
    k = math.floor(math.log10(target_m))
    for m in (5, 2, 1):
        if m * 10**k <= target_m:
            return m * 10**k
    return 10**k


def bounds(drawing: Drawing) -> tuple[float, float, float, float]:
    """(xmin, xmax, ymin, ymax) of everything in a drawing."""
    pts = [a.reshape(-1, 2) for a in (drawing.polygons, drawing.ghosts, drawing.lines, drawing.dots) if a is not None]
    if drawing.bodies is not None:
        r = drawing.body_radius_m
        pts += [drawing.bodies - r, drawing.bodies + r]
    allp = np.concatenate(pts)
    allp = allp[np.all(np.isfinite(allp), axis=1)]
    if allp.size == 0:
        return -1.0, 1.0, -1.0, 1.0
    return float(allp[:, 0].min()), float(allp[:, 0].max()), float(allp[:, 1].min()), float(allp[:, 1].max())


def layout_for(extent, width: int, status_lines: int, spacetime: bool) -> Layout:
    """Pixel layout: the structure panel keeps the drawing's aspect within sensible limits."""
    left = 70 if spacetime else 16
    xr, yr = extent[1] - extent[0], extent[3] - extent[2]
    inner = width - left - 16
    h = int(np.clip(inner * yr / max(xr, 1e-300), 90, 0.7 * width))
    return Layout(width=width, title=44 + 15 * status_lines, structure=h, band=64,
                  spacetime=int(np.clip(0.3 * width, 150, 300)) if spacetime else 0,
                  bottom=44 if spacetime else 6, left=left)


class Frame:
    """The figure of one render; ``update`` then ``rgb`` per frame, or ``save`` for a still."""

    def __init__(self, *, drawing: Drawing, extent, colouring: Colouring, title: str, subtitle: str,
                 status: str, t_max_s: float, width: int, frame_step_s: float = 0.0, spacetime=None, animated: bool = True):
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        status_wrapped = textwrap.wrap(status, width=max(40, width // 7))[:3] if status else []
        self.layout = L = layout_for(extent, width, len(status_wrapped), spacetime is not None)
        self.fig = Figure(figsize=(L.width / DPI, L.height / DPI), dpi=DPI, facecolor="white")
        self.canvas = FigureCanvasAgg(self.fig)
        self.colouring = colouring
        self.t_factor, self.t_unit = time_unit(t_max_s)
        step = (frame_step_s or t_max_s or 1.0) * self.t_factor
        self.t_digits = int(np.clip(-math.floor(math.log10(step)) if step > 0 else 3, 0, 6))
        self.t_width = len(f"{t_max_s * self.t_factor:.{self.t_digits}f}")
        self.dynamic = []
        H, W = L.height, L.width
        fx, fy = (lambda px: px / W), (lambda py: py / H)
        y_struct = L.bottom + L.spacetime + L.band
        self.ax = self.fig.add_axes([fx(L.left), fy(y_struct), fx(W - L.left - L.right), fy(L.structure)])
        self.ax.set_axis_off()
        self._fit(extent, W - L.left - L.right, L.structure)
        self._cmap, self._norm = self._colour_map()
        self._make_artists(drawing, animated)
        top = H - 8
        self.fig.text(fx(12), fy(top), title, ha="left", va="top", fontsize=12, weight="bold")
        self.fig.text(fx(12), fy(top - 19), subtitle, ha="left", va="top", fontsize=9, color="#444444")
        for k, line in enumerate(status_wrapped):
            self.fig.text(fx(12), fy(top - 36 - 14 * k), line, ha="left", va="top", fontsize=9,
                          color="#c0392b", weight="bold")
        self.time_text = self.fig.text(fx(W - 12), fy(top), "", ha="right", va="top", fontsize=12,
                                       family="monospace", animated=animated)
        self.dynamic.append((self.fig, self.time_text))
        self._scale_bar(fx, fy, y_struct)
        self._colour_bar(fx, fy, y_struct)
        self.marker = None
        if spacetime is not None:
            self._spacetime(spacetime, fx, fy, animated)
        self._background = None

    def _fit(self, extent, box_w: int, box_h: int) -> None:
        """Limits that show ``extent`` at equal scales in x and y, centred in the panel."""
        xr, yr = max(extent[1] - extent[0], 1e-300), max(extent[3] - extent[2], 1e-300)
        m_per_px = max(xr / box_w, yr / box_h)
        cx, cy = 0.5 * (extent[0] + extent[1]), 0.5 * (extent[2] + extent[3])
        self.ax.set_xlim(cx - 0.5 * m_per_px * box_w, cx + 0.5 * m_per_px * box_w)
        self.ax.set_ylim(cy - 0.5 * m_per_px * box_h, cy + 0.5 * m_per_px * box_h)

    # ------------------------------------------------------------ artists
    def _colour_map(self):
        from matplotlib import colormaps
        from matplotlib.colors import BoundaryNorm, ListedColormap, Normalize

        c = self.colouring
        if c.categories is not None:
            n = len(c.categories)
            cmap = ListedColormap([WELL_COLOURS[k % len(WELL_COLOURS)] for k in range(n)])
            return cmap, BoundaryNorm(np.arange(n + 1) - 0.5, n)
        return colormaps[c.cmap], Normalize(c.vmin, c.vmax)

    def _make_artists(self, d: Drawing, animated: bool) -> None:
        from matplotlib.collections import EllipseCollection, PolyCollection
        from matplotlib.lines import Line2D

        ax = self.ax
        px_per_m = self.px_per_m()
        self.polys = self.ghosts = self.lines = self.bodies = self.dots = None
        if d.polygons is not None:
            size_px = px_per_m * float(np.ptp(d.polygons[0, :, 0])) if len(d.polygons) else 10.0
            lw = float(np.clip(size_px / 40.0, 0.2, 0.8)) if size_px > 8 else 0.0
            if d.ghosts is not None:
                self.ghosts = PolyCollection(d.ghosts, closed=True, edgecolors="#777777", linewidths=lw,
                                             alpha=0.4, cmap=self._cmap, norm=self._norm, animated=animated)
                ax.add_collection(self.ghosts)
            self.polys = PolyCollection(d.polygons, closed=True, edgecolors=d.edge, linewidths=lw,
                                        cmap=self._cmap, norm=self._norm, animated=animated)
            ax.add_collection(self.polys)
        if d.lines is not None:  # one polyline with NaN breaks: far cheaper to update than a LineCollection
            grid = d.bodies is not None and d.lines.shape[1] == 2
            self.lines = Line2D(*polyline(d.lines), color="#9a9a9a" if grid else "#333333",
                                linewidth=0.5 if grid else 0.9, animated=animated)
            ax.add_line(self.lines)
        if d.bodies is not None:
            r_px = px_per_m * d.body_radius_m
            self.bodies = EllipseCollection(2 * d.body_radius_m, 2 * d.body_radius_m, 0.0, units="xy",
                                            offsets=d.bodies, offset_transform=ax.transData,
                                            edgecolors="#222222", linewidths=0.5 if r_px > 3 else 0.0,
                                            cmap=self._cmap, norm=self._norm, animated=animated)
            ax.add_collection(self.bodies)
        if d.dots is not None:
            self.dots = ax.scatter(d.dots[:, 0], d.dots[:, 1], s=3.0, c="#111111", linewidths=0, animated=animated)
        for artist in (self.ghosts, self.polys, self.lines, self.bodies, self.dots):
            if artist is not None:
                self.dynamic.append((ax, artist))
        if self.colouring.values is None:
            for artist in (self.polys, self.bodies):
                if artist is not None:
                    artist.set_facecolor("#b8c4d6")
            if self.ghosts is not None:
                self.ghosts.set_facecolor("#b8c4d6")

    def crisp(self) -> None:
        """No antialiasing of the units and bodies: a GIF's palette then compresses 2–3× better."""
        for artist in (self.polys, self.ghosts, self.bodies):
            if artist is not None:
                artist.set_antialiased(False)

    def px_per_m(self) -> float:
        """Pixels per metre of the structure panel."""
        pos = self.ax.get_position()
        x0, x1 = self.ax.get_xlim()
        return pos.width * self.layout.width / (x1 - x0)

    def _scale_bar(self, fx, fy, y_struct) -> None:
        """A round length (1, 2 or 5 × 10^k m) of about 110 px, labelled, under the structure."""
        from matplotlib.lines import Line2D

        ppm = self.px_per_m()
        length = nice_length(110.0 / ppm)
        px = length * ppm
        x0, y = 16, y_struct - 30
        self.fig.add_artist(Line2D([fx(x0), fx(x0 + px)], [fy(y), fy(y)], color="black", linewidth=3,
                                   solid_capstyle="butt", transform=self.fig.transFigure))
        self.fig.text(fx(x0 + px / 2), fy(y + 5), length_label(length), ha="center", va="bottom", fontsize=9)

    def _colour_bar(self, fx, fy, y_struct) -> None:
        """Horizontal colour bar with the colouring's label (categories as tick labels)."""
        from matplotlib.cm import ScalarMappable

        c = self.colouring
        if c.values is None:
            return
        W = self.layout.width
        x0 = max(200, int(0.34 * W))
        cax = self.fig.add_axes([fx(x0), fy(y_struct - 30), fx(W - x0 - 24), fy(11)])
        sm = ScalarMappable(norm=self._norm, cmap=self._cmap)
        cb = self.fig.colorbar(sm, cax=cax, orientation="horizontal")
        if c.categories is not None:
            cb.set_ticks(np.arange(len(c.categories)))
            cb.set_ticklabels(c.categories)
        cb.ax.tick_params(labelsize=8, length=2, pad=1)
        cb.set_label(c.label, fontsize=9, labelpad=2)

    def _spacetime(self, st, fx, fy, animated) -> None:
        """The space–time image below the structure, sharing its x range, with the time marker."""
        from matplotlib.lines import Line2D

        L = self.layout
        W = L.width
        ax = self.fig.add_axes([fx(L.left), fy(L.bottom), fx(W - L.left - L.right), fy(L.spacetime - 22)])
        tf = self.t_factor
        ext = [st.x[0], st.x[-1], st.t[0] * tf, st.t[-1] * tf]
        if ext[2] == ext[3]:
            ext[3] = ext[2] + 1.0
        ax.imshow(st.values, origin="lower", aspect="auto", extent=ext, cmap=self._cmap, norm=self._norm,
                  interpolation="nearest")
        if st.shares_x:
            ax.set_xlim(self.ax.get_xlim())
        ax.set_ylim(ext[2], ext[3])
        ax.set_xlabel(st.xlabel, fontsize=9, labelpad=1)
        ax.set_ylabel(f"t ({self.t_unit})", fontsize=9)
        ax.tick_params(labelsize=8)
        ax.set_title(st.title, fontsize=9, loc="left", pad=3)
        if st.shares_x:
            ax.xaxis.set_major_formatter(_length_formatter(ax))
        self.marker = Line2D([0, 1], [ext[2], ext[2]], color="#111111", linewidth=1.2,
                             transform=ax.get_yaxis_transform(), animated=animated)
        ax.add_line(self.marker)
        self.dynamic.append((ax, self.marker))

    # ------------------------------------------------------------ per frame
    def update(self, t_s: float, drawing: Drawing, colours: np.ndarray | None, repeats: int = 0) -> None:
        """Move the artists to one frame's drawing and colours (in place)."""
        if self.polys is not None:
            self.polys.set_verts(drawing.polygons)
            if colours is not None:
                self.polys.set_array(colours)
        if self.ghosts is not None:
            self.ghosts.set_verts(drawing.ghosts)
            if colours is not None:
                self.ghosts.set_array(np.tile(colours, max(repeats, 1)))
        if self.lines is not None:
            self.lines.set_data(*polyline(drawing.lines))
        if self.bodies is not None:
            self.bodies.set_offsets(drawing.bodies)
            if colours is not None:
                self.bodies.set_array(colours)
        if self.dots is not None:
            self.dots.set_offsets(drawing.dots)
        self.time_text.set_text(f"t = {t_s * self.t_factor:{self.t_width}.{self.t_digits}f} {self.t_unit}")
        if self.marker is not None:
            self.marker.set_ydata([t_s * self.t_factor] * 2)

    def rgb(self) -> np.ndarray:
        """The current frame as an (H, W, 3) uint8 array (static parts drawn once, then blitted)."""
        if self._background is None:
            self.canvas.draw()
            self._background = self.canvas.copy_from_bbox(self.fig.bbox)
        else:
            self.canvas.restore_region(self._background)
        for owner, artist in self.dynamic:
            owner.draw_artist(artist)
        return np.asarray(self.canvas.buffer_rgba())[..., :3].copy()

    def save(self, path, fmt: str) -> None:
        """Write the current frame as a PNG or SVG file."""
        self.fig.savefig(path, format=fmt, dpi=DPI, facecolor="white")


def polyline(segments: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """x, y of (K, P, 2) polylines joined into one line broken by NaN points."""
    k, p, _ = segments.shape
    joined = np.full((k, p + 1, 2), np.nan)
    joined[:, :p] = segments
    joined = joined.reshape(-1, 2)
    return joined[:, 0], joined[:, 1]


def _length_formatter(ax):
    """Tick labels of a position axis in mm (or m) according to its span."""
    from matplotlib.ticker import FuncFormatter

    span = abs(np.diff(ax.get_xlim())[0])
    factor, unit = (1e3, "mm") if span < 2.0 else (1.0, "m")
    ax.set_xlabel(ax.get_xlabel().replace("(m)", f"({unit})"))
    return FuncFormatter(lambda v, _: f"{v * factor:g}")


__all__ = ["Frame", "Layout", "bounds", "layout_for", "length_label", "nice_length", "polyline", "time_unit"]
