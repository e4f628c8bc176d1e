"""``flexmm stability CONFIG``: raise dt for each integrator until the scene blows up.

Prints predicted (from ω_max at rest and along a pilot run) against measured limits and
writes ``stability.txt``, ``stability.json`` and ``stability.png`` to the output directory. On
the scene a trial is unstable when it blows up; with ``--linear`` the scene's fastest linear mode
alone is excited and a trial is unstable when its amplitude grows faster than
``--growth-threshold`` per step (``flexmm.stability_scan``: the criterion is printed with the table).
"""

from __future__ import annotations

import json
from pathlib import Path

import typer

from flexmm.assemble import SceneError, UnstableStepError, build_problem
from flexmm.cli.common import OverrideOption, error, load_or_exit
from flexmm.integrators import INTEGRATORS


def stability(
    config: str = typer.Argument(..., help="Scene YAML file."),
    overrides: list[str] = OverrideOption,
    methods: str = typer.Option(",".join(INTEGRATORS), "--methods", "-m", help="Comma-separated integrators."),
    duration_s: float = typer.Option(None, "--duration", help="Length of each trial run (default: the scene's)."),
    linear: bool = typer.Option(False, "--linear", help="Excite only the fastest linear mode (the linear limit); "
                                "unstable = amplitude growth above --growth-threshold per step."),
    growth_threshold: float = typer.Option(
        None, "--growth-threshold", min=1e-8, max=1e-2,
        help="With --linear: amplitude growth per step counted as unstable (default 1e-5)."),
    out: str = typer.Option(None, "--out", "-o", help="Output directory (default runs/<name>/stability)."),
) -> None:
    """Measure each integrator's largest stable dt on a scene and compare with the prediction."""
    from flexmm import stability_scan

    names = [m.strip() for m in methods.split(",") if m.strip()]
    unknown = [m for m in names if m not in INTEGRATORS]
    if unknown:
        raise error(f"unknown integrator(s) {unknown}; valid: {', '.join(INTEGRATORS)}")
    scene = load_or_exit(config, list(overrides or []) + ["solver.allow_unstable=true"])
    try:
        problem = build_problem(scene)
    except (UnstableStepError, SceneError) as exc:
        raise error(f"{config}: {exc}") from None
    ts = problem.system.scales.time_s
    t_end = duration_s / ts if duration_s else problem.duration
    q0 = v0 = threshold = None
    if growth_threshold is not None and not linear:
        raise error("--growth-threshold applies only with --linear")
    if linear:
        q0, v0 = stability_scan.mode_state(problem)
        threshold = growth_threshold or stability_scan.GROWTH_THRESHOLD
    rows = stability_scan.scan(problem, names, t_end=t_end, peak=not linear, growth_threshold=threshold,
                               q0=q0, v0=v0, log=lambda m: typer.echo(m, err=True))
    table = stability_scan.table(rows)
    typer.echo(table)
    folder = Path(out) if out else Path(scene.output.directory) / scene.name / "stability"
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "stability.txt").write_text(table + "\n")
    (folder / "stability.json").write_text(json.dumps([r.as_dict() for r in rows], indent=1, default=str))
    stability_scan.figure(rows, folder / "stability.png", f"{scene.name}: measured vs predicted stable dt")
    typer.echo(f"written: {folder}/stability.{{txt,json,png}}")
