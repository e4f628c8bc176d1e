"""``flexmm export RUN --format vtk|svg``: a run's units as files other viewers (or a cutter) open.

Only typer and the standard library are imported here; the writer is loaded inside the command.
"""

from __future__ import annotations

import typer

from flexmm.cli.common import error
from flexmm.cli.render import parse_time

FORMATS = ("vtk", "svg")


def export(
    run: str = typer.Argument(..., help="Run directory (or its dataset.nc)."),
    format: str = typer.Option("vtk", "--format", help="vtk: a ParaView collection (.pvd) of one .vtu per "
                               "frame, the units as points with the run's site fields; svg: the reference "
                               "geometry (unit polygons and ligaments, mm, y up) for fabrication."),
    svg: bool = typer.Option(False, "--svg", help="Same as --format svg."),
    out: str = typer.Option(None, "--out", "-o", help="Output directory (default RUN/vtk); with svg the file "
                            "(default RUN/<name>.svg)."),
    start: str = typer.Option(None, "--start", help="First time (default the run's start; 0.25, 250ms, 40us)."),
    stop: str = typer.Option(None, "--stop", help="Last time (default the run's end)."),
    every: int = typer.Option(1, "--every", help="Write every N-th frame."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Print only the path written."),
) -> None:
    """Export a run's units per frame for ParaView (VTK: .pvd + .vtu), or its reference geometry as SVG."""
    if format not in FORMATS:
        raise error(f"--format {format!r}: expected one of {', '.join(FORMATS)}")
    if svg or format == "svg":
        from flexmm.render.svg import export_svg

        typer.echo(export_svg(run, out, log=None if quiet else (lambda m: typer.echo(m, err=True))))
        return
    from flexmm.render.vtk import export_vtk

    pvd = export_vtk(run, out, start_s=parse_time(start, "--start"), stop_s=parse_time(stop, "--stop"),
                     every=every, log=None if quiet else (lambda m: typer.echo(m, err=True)))
    typer.echo(pvd)
