"""``flexmm export RUN --format vtk``: a run's units as files other viewers open.

Only typer and the standard library are imported here; the writer is loaded inside the command.
"""

from __future__ import annotations

import typer

from flexmm.cli.common import error
from flexmm.cli.render import parse_time

FORMATS = ("vtk",)


def export(
    run: str = typer.Argument(..., help="Run directory (or its dataset.nc)."),
    format: str = typer.Option("vtk", "--format", help="vtk: a ParaView collection (.pvd) of one .vtu per "
                               "frame, the units as points with the run's site fields."),
    out: str = typer.Option(None, "--out", "-o", help="Output directory (default RUN/vtk)."),
    start: str = typer.Option(None, "--start", help="First time (default the run's start; 0.25, 250ms, 40us)."),
    stop: str = typer.Option(None, "--stop", help="Last time (default the run's end)."),
    every: int = typer.Option(1, "--every", help="Write every N-th frame."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Print only the path written."),
) -> None:
    """Export a run's units per frame for ParaView (VTK: .pvd + .vtu)."""
    if format not in FORMATS:
        raise error(f"--format {format!r}: expected one of {', '.join(FORMATS)}")
    from flexmm.render.vtk import export_vtk

    pvd = export_vtk(run, out, start_s=parse_time(start, "--start"), stop_s=parse_time(stop, "--stop"),
                     every=every, log=None if quiet else (lambda m: typer.echo(m, err=True)))
    typer.echo(pvd)
