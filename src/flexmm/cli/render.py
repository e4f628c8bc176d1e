"""``flexmm render RUN``: draw the deformed structure of a run, one frame or a movie.

Only typer and the standard library are imported here; the drawing code (matplotlib, numpy)
is loaded inside the command.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import typer

from flexmm.cli.common import error

_TIME = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(s|ms|us|µs)?\s*$")
_SCALE = {None: 1.0, "s": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6}


def parse_time(text: str | None, option: str) -> float | None:
    """Seconds from '0.25', '250ms', '12 us'; UsageError otherwise."""
    if text is None:
        return None
    m = _TIME.match(text)
    if not m:
        raise error(f"{option} {text!r}: expected a time such as 0.25, 250ms or 40us")
    return float(m.group(1)) * _SCALE[m.group(2)]


def parse_pair(text: str | None, option: str, kind=float):
    """'A:B' -> (A, B); UsageError otherwise."""
    if text is None:
        return None
    parts = text.split(":")
    try:
        if len(parts) != 2:
            raise ValueError
        a, b = kind(parts[0]), kind(parts[1])
    except ValueError:
        raise error(f"{option} {text!r}: expected two numbers as LOW:HIGH") from None
    if kind is float and not (math.isfinite(a) and math.isfinite(b)):
        raise error(f"{option} {text!r}: expected finite numbers")
    return a, b


def render(
    run: str = typer.Argument(..., help="Run directory (or its dataset.nc)."),
    out: str = typer.Option(None, "--out", "-o", help="Output file: .png or .svg (one frame), .gif or .mp4 "
                            "(movie). Default RUN/render.gif (RUN/render.mp4 with --mp4), or RUN/render.png "
                            "with --time."),
    time: str = typer.Option(None, "--time", "-t", help="Draw the frame nearest this time (s; or 250ms, 40us)."),
    start: str = typer.Option(None, "--start", help="Movie: first time (default the run's start)."),
    stop: str = typer.Option(None, "--stop", help="Movie: last time (default the run's end)."),
    every: int = typer.Option(None, "--every", help="Movie: draw every N-th frame (default: enough for --max-frames)."),
    max_frames: int = typer.Option(400, "--max-frames", help="Movie: at most this many frames."),
    fps: float = typer.Option(20.0, "--fps", help="Movie: frames per second."),
    color: str = typer.Option(None, "--color", "-c", help="Colour by a site field of the run (theta, u, u_dot, ...), "
                              "energy (per unit), well (multistable lattices) or none. Default: theta for "
                              "rotating units, the well for bistable lattices, else the velocity."),
    clim: str = typer.Option(None, "--clim", help="Colour limits LOW:HIGH (default from the frames drawn)."),
    exaggerate: float = typer.Option(1.0, "--exaggerate", "-x", help="Scale displacements and rotations "
                                     "from rest by this factor (stated on the picture)."),
    shape: str = typer.Option(None, "--shape", help="Units as their polygon (square), a cross of arms to their "
                              "vertices, or bars (default: as the model draws them: crosses for the LEGO chain, "
                              "polygons for sheets and networks, bars for the linkage)."),
    sites: str = typer.Option(None, "--sites", help="Show only columns (chain: units) A:B (B excluded)."),
    spacetime: bool = typer.Option(False, "--spacetime", help="Add the space–time diagram of the colour "
                                   "quantity with a marker at the current time."),
    row: int = typer.Option(None, "--row", help="Row of a sheet or grid for the space–time diagram (default middle)."),
    width: int = typer.Option(960, "--width", help="Picture width in pixels."),
    mp4: bool = typer.Option(False, "--mp4", help="Write the movie as H.264 MP4 (default RUN/render.mp4). "
                             "Uses ffmpeg from PATH, else the static ffmpeg of flexmm's mp4 extra "
                             "(pip install 'flexmm[mp4]')."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Print only the path written."),
) -> None:
    """Draw the deformed structure of a run: one frame (PNG, SVG) or a movie (GIF, MP4)."""
    from flexmm.render import RenderOptions, render_run

    span = parse_pair(sites, "--sites", int)
    if span is not None and not 0 <= span[0] < span[1]:
        raise error(f"--sites {sites!r}: expected 0 ≤ A < B")
    opts = RenderOptions(
        out=Path(out) if out else None, time_s=parse_time(time, "--time"), start_s=parse_time(start, "--start"),
        stop_s=parse_time(stop, "--stop"), every=every, max_frames=max_frames, fps=fps, color=color,
        clim=parse_pair(clim, "--clim"), exaggerate=exaggerate, shape=shape, sites=span, spacetime=spacetime,
        row=row, width=width, movie_format="mp4" if mp4 else "gif")
    log = None if quiet else (lambda m: typer.echo(m, err=True))
    path = render_run(run, opts, log=log, warn=lambda m: typer.echo(m, err=True))  # warnings even with -q
    typer.echo(str(path))
