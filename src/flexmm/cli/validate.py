"""``flexmm validate CONFIG``: check a scene without running it."""

from __future__ import annotations

import typer

from flexmm.cli.common import OverrideOption, load_or_exit


def validate(
    config: str = typer.Argument(..., help="Scene YAML file."),
    overrides: list[str] = OverrideOption,
    build: bool = typer.Option(True, help="Also build the system and check dt against the stable limit."),
) -> None:
    """Validate a scene config (schema, cross-field rules and, by default, the time step)."""
    scene = load_or_exit(config, overrides)
    if build:
        from flexmm.assemble import build_problem

        problem = build_problem(scene)
        sc = problem.system.scales
        typer.echo(
            f"{config}: ok — {scene.lattice.kind}, {problem.system.ndof} DOFs, "
            f"dt = {problem.dt * sc.time_s:.4g} s (stable limit {problem.stable_dt * sc.time_s:.4g} s), "
            f"{problem.duration / problem.dt:.0f} steps"
        )
    else:
        typer.echo(f"{config}: ok")
