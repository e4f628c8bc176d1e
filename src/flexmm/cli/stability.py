"""``flexmm stability CONFIG``: raise dt for each integrator until the scene blows up.

Prints predicted (from ω_max at rest and along a pilot run) against measured limits and
writes ``stability.txt``, ``stability.json`` and ``stability.png`` to the output directory. On
the scene a trial is unstable when it blows up; with ``--linear`` the scene's fastest linear mode
alone is excited and a trial is unstable when its amplitude grows faster than
``--growth-threshold`` per step (``flexmm.diagnostics.stability_scan``: the criterion is printed with the table).
"""

from __future__ import annotations

import json
from pathlib import Path

import typer

from flexmm.cli.common import OverrideOption, check_output_dir, error, load_or_exit, output_dir, planned, writing

FILES = ("stability.txt", "stability.json", "stability.png")


def stability(
    config: str = typer.Argument(..., help="Scene YAML file."),
    overrides: list[str] = OverrideOption,
    methods: str = typer.Option(None, "--methods", "-m", help="Comma-separated integrators (default: all)."),
    duration_s: float = typer.Option(None, "--duration", help="Length of each trial run (default: the scene's)."),
    linear: bool = typer.Option(False, "--linear", help="Excite only the fastest linear mode (the linear limit); "
                                "unstable = amplitude growth above --growth-threshold per step."),
    growth_threshold: float = typer.Option(
        None, "--growth-threshold", min=1e-8, max=1e-2,
        help="With --linear: amplitude growth per step counted as unstable (default 1e-5)."),
    out: str = typer.Option(None, "--out", "-o", help="Output directory (default runs/<name>/stability)."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Only print the paths of the files written."),
) -> None:
    """Measure each integrator's largest stable dt on a scene and compare with the prediction.

    The scene is the one `flexmm run` would integrate (its plan, printed first: domain, method,
    step, stable limit, frames)."""
    from flexmm.diagnostics import stability_scan
    from flexmm.integrators import INTEGRATORS

    names = [m.strip() for m in (methods or ",".join(INTEGRATORS)).split(",") if m.strip()]
    unknown = [m for m in names if m not in INTEGRATORS]
    if unknown:
        raise error(f"unknown integrator(s) {unknown}; valid: {', '.join(INTEGRATORS)}")
    if growth_threshold is not None and not linear:
        raise error("--growth-threshold applies only with --linear")
    scene = load_or_exit(config, list(overrides or []) + ["solver.allow_unstable=true"])
    problem = planned(scene, quiet)  # the run's plan: its domain, method, step and frames
    folder = check_output_dir(Path(out) if out else Path(scene.output.directory) / scene.name / "stability")
    ts = problem.system.scales.time_s
    t_end = duration_s / ts if duration_s else problem.duration
    q0 = v0 = threshold = None
    if linear:
        q0, v0 = stability_scan.mode_state(problem)
        threshold = growth_threshold or stability_scan.GROWTH_THRESHOLD
    say = (lambda m: None) if quiet else (lambda m: typer.echo(m, err=True))
    rows = stability_scan.scan(problem, names, t_end=t_end, peak=not linear, growth_threshold=threshold,
                               q0=q0, v0=v0, log=say)
    table = stability_scan.table(rows)
    if not quiet:
        typer.echo(table)
    output_dir(folder)
    with writing(folder):
        (folder / "stability.txt").write_text(table + "\n")
        (folder / "stability.json").write_text(json.dumps([r.as_dict() for r in rows], indent=1, default=str))
        stability_scan.figure(rows, folder / "stability.png", f"{scene.name}: measured vs predicted stable dt")
    if quiet:
        for name in FILES:
            typer.echo(folder / name)
    else:
        typer.echo(f"written: {folder}/stability.{{txt,json,png}}")
