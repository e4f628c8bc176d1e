"""``render_run``: one frame of a run as PNG/SVG, or a range of frames as an animated GIF or MP4.

Everything comes from the dataset (fields, coordinates, status) and the lattice parameters of its
stored config; no model is rebuilt. Frames are streamed from the file, a block at a time.
"""

from __future__ import annotations

import math
import time as _time
from collections.abc import Callable
from dataclasses import dataclass, field as dataclass_field
from pathlib import Path

import numpy as np

from flexmm.errors import FlexmmError, OutputError, UsageError
from flexmm.io.atomic import atomic_target
from flexmm.render.colour import Colouring, make_colouring
from flexmm.render.figure import Frame
from flexmm.render.movie import MOVIE_SUFFIXES, ffmpeg_or_error, open_movie
from flexmm.render.source import RunSource
from flexmm.render.structure import SHAPE_NAMES, make_structure
from flexmm.render.view import columns, describe, make_spacetime, palette_colours, view_extent

STILL_SUFFIXES = (".png", ".svg")
#: frames sampled to fix colour limits, the view and the wells
N_SAMPLES = 24


@dataclass
class RenderOptions:
    """What ``flexmm render`` asks for (SI times; None: the default)."""

    out: Path | None = None
    time_s: float | None = None
    start_s: float | None = None
    stop_s: float | None = None
    every: int | None = None
    max_frames: int = 400
    fps: float = 20.0
    color: str | None = None
    clim: tuple[float, float] | None = None
    exaggerate: float = 1.0
    shape: str | None = None
    sites: tuple[int, int] | None = None
    spacetime: bool = False
    row: int | None = None
    width: int = 960
    movie_format: str = "gif"  # the default movie's format when ``out`` is None: 'gif' or 'mp4'


def output_kind(opts: RenderOptions, run_dir: Path) -> tuple[Path, bool]:
    """(output path, still?) from --out and --time; UsageError for an unknown suffix or a conflict."""
    still_default = opts.time_s is not None
    if opts.movie_format == "mp4":
        if opts.out is not None and opts.out.suffix.lower() != ".mp4":
            raise UsageError(f"--mp4 writes an MP4 movie: give --out NAME.mp4, not --out {opts.out}, or drop --mp4")
        if still_default:
            raise UsageError("--mp4 writes a movie: --time picks one frame (write it as .png or .svg), "
                             "--start/--stop choose a movie's frames")
    default = "render.png" if still_default else f"render.{opts.movie_format}"
    out = opts.out if opts.out is not None else run_dir / default
    suffix = out.suffix.lower()
    if suffix not in STILL_SUFFIXES + MOVIE_SUFFIXES:
        raise UsageError(f"--out {out}: unknown output suffix {suffix or '(none)'!r}; use .png or .svg for "
                         "one frame, .gif or .mp4 for a movie")
    still = suffix in STILL_SUFFIXES
    if not still and opts.time_s is not None:
        raise UsageError(f"--time picks one frame: write it as .png or .svg (a movie takes --start/--stop), "
                         f"not {suffix}")
    if still and (opts.start_s is not None or opts.stop_s is not None or opts.every is not None):
        raise UsageError("--start, --stop and --every choose a movie's frames: write .gif or .mp4, "
                         "or pick one frame with --time")
    return out, still


def check_options(opts: RenderOptions) -> None:
    """UsageError for option values out of range."""
    if not (math.isfinite(opts.exaggerate) and opts.exaggerate > 0):
        raise UsageError(f"--exaggerate must be a positive number, got {opts.exaggerate:g}")
    if not (math.isfinite(opts.fps) and 0 < opts.fps <= 100):
        raise UsageError(f"--fps must be in (0, 100], got {opts.fps:g}")
    if opts.every is not None and opts.every < 1:
        raise UsageError(f"--every must be ≥ 1, got {opts.every}")
    if opts.max_frames < 1:
        raise UsageError(f"--max-frames must be ≥ 1, got {opts.max_frames}")
    if not 320 <= opts.width <= 4000:
        raise UsageError(f"--width must be between 320 and 4000 pixels, got {opts.width}")
    if opts.clim is not None and not opts.clim[1] > opts.clim[0]:
        raise UsageError(f"--clim needs LOW < HIGH, got {opts.clim[0]:g}:{opts.clim[1]:g}")
    if opts.shape is not None and opts.shape not in SHAPE_NAMES:
        raise UsageError(f"--shape must be one of {', '.join(SHAPE_NAMES)}, got {opts.shape!r}")


def load_lattice(src: RunSource):
    """The validated lattice config stored in the dataset; UsageError if there is none."""
    import yaml

    from flexmm.config import scene_from_dict

    text = src.config_text
    if not text:
        raise UsageError(f"{src.path} has no stored config (attribute 'config'): cannot draw its structure")
    try:
        return scene_from_dict(yaml.safe_load(text), source=f"{src.path} (stored config)").lattice
    except FlexmmError as exc:
        raise UsageError(f"the config stored in {src.path} does not validate any more: {exc}") from None


def frame_indices(src: RunSource, opts: RenderOptions, still: bool) -> np.ndarray:
    """The frames to draw: one (--time, default the last) or a window thinned to --every/--max-frames."""
    if still:
        return np.array([src.index_at(opts.time_s) if opts.time_s is not None else src.time.size - 1])
    idx = src.window(opts.start_s, opts.stop_s)
    every = opts.every or max(1, math.ceil(idx.size / opts.max_frames))
    return idx[::every]


@dataclass
class Picture:
    """A prepared render: the open run, its structure and colouring, the figure, the frames to draw."""

    src: RunSource
    structure: object
    colouring: Colouring
    fig: Frame
    indices: np.ndarray
    needed: list[str]
    #: fields holding NaN or infinite values in the frames sampled for the limits (drawn as they are)
    nonfinite: list[str] = dataclass_field(default_factory=list)

    def warnings(self) -> list[str]:
        if not self.nonfinite:
            return []
        return [f"warning: {self.src.path}: {', '.join(self.nonfinite)} {'holds' if len(self.nonfinite) == 1 else 'hold'} NaN or infinite values (in the frames "
                f"sampled for the colour limits): a damaged dataset or a run that blew up; drawn as they are"]

    def draw(self, t_s: float, frame: dict) -> None:
        """Move the figure to one frame of the run."""
        s = self.structure
        self.fig.update(t_s, s.draw(frame), _colours(self.colouring, frame), s.colour_repeats())


def prepare(src: RunSource, opts: RenderOptions, still: bool) -> Picture:
    """Structure, colouring (limits from sampled frames), view and figure of a render."""
    lattice = load_lattice(src)
    structure = make_structure(src, lattice, opts.shape, opts.exaggerate)
    src.require(structure.fields)
    indices = frame_indices(src, opts, still)
    take = np.unique(np.linspace(0, indices.size - 1, min(N_SAMPLES, indices.size)).round().astype(int))
    names = list(dict.fromkeys(structure.fields + [f for f in ("u_dot", "v_dot", "theta_dot") if f in src.fields]))
    samples = [f for _, _, f in src.frames(indices[take], names)]
    colouring = make_colouring(opts.color, src, structure, [f["u"] for f in samples])
    needed = list(dict.fromkeys(structure.fields + colouring.fields))
    src.require(needed)
    if colouring.values is not None:
        colouring.set_limits(_shown([colouring.values(f) for f in samples], structure, opts.sites), opts.clim)
    extent = view_extent(structure, [structure.draw(f) for f in samples], opts.sites)
    spacetime = None
    if opts.spacetime:
        st_idx = indices if not still else np.arange(src.time.size)
        spacetime = make_spacetime(src, structure, colouring, st_idx, opts.row, needed)
    title, subtitle = describe(src, lattice, structure, opts.exaggerate)
    fig = Frame(drawing=structure.draw(samples[0]), extent=extent, colouring=colouring, title=title,
                subtitle=subtitle, status=src.status_line(), t_max_s=float(src.time[-1]), width=opts.width,
                frame_step_s=_step(src.time[indices] if indices.size > 1 else src.time),
                spacetime=spacetime, animated=not still)
    nonfinite = [n for n in names if any(not np.all(np.isfinite(f[n])) for f in samples if n in f)]
    return Picture(src, structure, colouring, fig, indices, needed, nonfinite)


def _shown(values: list[np.ndarray], structure, sites: tuple[int, int] | None) -> list[np.ndarray]:
    """The colour values of the units ``--sites`` shows (all without it): the colour limits come
    from what is on the picture, not from a long chain's quiet rest."""
    if sites is None:
        return values
    col = columns(structure)
    pick = (col >= sites[0]) & (col < sites[1])
    return [v[pick] if np.shape(v)[:1] == pick.shape else v for v in values]


def still_figure(run, opts: RenderOptions) -> Picture:
    """The picture of one frame (--time, default the last), drawn but not saved (tests, notebooks);
    ``run``: a run directory, its dataset.nc or the run's ``xarray.Dataset``."""
    check_options(opts)
    with RunSource(run) as src:
        pic = prepare(src, opts, still=True)
        i = int(pic.indices[0])
        pic.draw(float(src.time[i]), next(src.frames([i], pic.needed))[2])
    return pic


#: the options of ``figure`` (the fields of ``RenderOptions`` that a still uses)
FIGURE_OPTIONS = ("color", "clim", "exaggerate", "shape", "sites", "spacetime", "row", "width")


def figure(run, t: float | None = None, **options):
    """One frame of a run drawn as ``flexmm render --time t`` draws it, as a matplotlib Figure
    (shown inline by Jupyter; ``fig.savefig(...)`` to save it): ``flexmm.render`` (docs/api.md).

    ``run``: the run's ``xarray.Dataset``, a ``flexmm.run`` result, a run directory or its
    dataset.nc; ``t``: the time in s (the nearest frame; default the last). ``options``:
    ``FIGURE_OPTIONS``, the fields of ``RenderOptions`` of those names; a bad value raises
    ``UsageError``.
    """
    unknown = sorted(set(options) - set(FIGURE_OPTIONS))
    if unknown:
        raise UsageError(f"flexmm.render: unknown option {', '.join(unknown)}; expected one of "
                         f"{', '.join(FIGURE_OPTIONS)}")
    run = getattr(run, "dataset", run)  # a flexmm.run result
    return still_figure(run, RenderOptions(time_s=t, **options)).fig.fig


def render_run(run: str | Path, opts: RenderOptions, log: Callable[[str], None] | None = None,
               warn: Callable[[str], None] | None = None) -> Path:
    """Draw a run (one frame or a movie) and return the path written. ``warn`` (default ``log``)
    gets what the picture cannot be trusted for (NaN/inf in the fields drawn)."""
    warn = warn or log
    check_options(opts)
    with RunSource(run) as src:
        out, still = output_kind(opts, src.path.parent)
        if out.suffix.lower() == ".mp4":
            ffmpeg_or_error()
        pic = prepare(src, opts, still)
        for line in pic.warnings() if warn else []:
            warn(line)
        _mkdir(out)
        t0 = _time.perf_counter()
        if still:
            i = int(pic.indices[0])
            pic.draw(float(src.time[i]), next(src.frames([i], pic.needed))[2])
            with atomic_target(out) as tmp:
                try:
                    pic.fig.save(tmp, out.suffix.lower()[1:])
                except OSError as exc:
                    raise OutputError(f"cannot write {out}: {exc.strerror or exc}") from None
            if log:
                log(f"wrote {out} (t = {src.time[i]:.6g} s)")
            return out
        if out.suffix.lower() == ".gif":
            pic.fig.crisp()
        writer = open_movie(out, opts.fps, palette_colours(pic.colouring))
        try:
            for _, t, frame in src.frames(pic.indices, pic.needed):
                pic.draw(t, frame)
                writer.write(pic.fig.rgb())
            path = writer.close()
        except OSError as exc:
            writer.abort()
            raise OutputError(f"cannot write {out}: {exc.strerror or exc}") from None
        except BaseException:
            writer.abort()
            raise
        wall = _time.perf_counter() - t0
        n = pic.indices.size
        if log:
            log(f"wrote {path}: {n} frames of the run, t = {src.time[pic.indices[0]]:.6g} s to "
                f"{src.time[pic.indices[-1]]:.6g} s (a {n / opts.fps:.3g} s movie at {opts.fps:g} frames/s); "
                f"render time {wall:.1f} s")
        return path


def _step(t: np.ndarray) -> float:
    return float(np.median(np.diff(t))) if t.size > 1 else 0.0


def _colours(colouring: Colouring, frame: dict):
    return None if colouring.values is None else colouring.values(frame)


def _mkdir(out: Path) -> None:
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot create {out.parent}: {exc.strerror or exc}") from None


__all__ = ["FIGURE_OPTIONS", "Picture", "RenderOptions", "figure", "prepare", "render_run", "still_figure"]
