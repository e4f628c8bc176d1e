"""``flexmm validate CONFIG``: check a scene without running it."""

from __future__ import annotations

import typer

from flexmm.cli.common import OverrideOption, load_or_exit


def validate(
    config: str = typer.Argument(..., help="Scene YAML file, or a sweep spec (every point is validated)."),
    overrides: list[str] = OverrideOption,
    build: bool = typer.Option(True, help="Also find the time step (checked against the stable limit) "
                                          "and estimate the run's cost."),
) -> None:
    """Validate a scene config (schema, cross-field rules and, by default, the step and the cost),
    or a sweep spec (its schema and every point's scene; nothing is built).

    The step comes from the scene built (small scenes) or from a small copy of its lattice, so
    a lattice of any size validates in about a second; a run beyond the limits on memory,
    output size, free disk or steps is reported as an error (flexmm.plan.cost).
    """
    from flexmm.config.loader import read_yaml
    from flexmm.sweep.spec import is_sweep_spec

    if is_sweep_spec(read_yaml(config)[0]):
        _validate_sweep(config, overrides)
        return
    scene = load_or_exit(config, overrides)
    if not build:
        typer.echo(f"{config}: ok")
        return
    from flexmm.api import run_dir_for
    from flexmm.cli.common import check_output_dir
    from flexmm.plan.cost import ResourceError, check, estimate

    check_output_dir(run_dir_for(scene))  # OutputError if the output could not be written there

    cost = estimate(scene)
    dt = "dt unknown" if cost.dt_s is None else f"dt = {cost.dt_s:.4g} s" + (
        "" if cost.stable_dt_s is None else f" (stable limit {cost.stable_dt_s:.4g} s)")
    for line in cost.lines():
        typer.echo(line)
    problems = check(cost, run_dir_for(scene))
    if problems:
        raise ResourceError("a run would be refused: " + "; ".join(problems) + " (flexmm run --force runs it anyway)")
    typer.echo(f"{config}: ok — {scene.lattice.kind}, {cost.ndof:,} DOFs, {dt}")


def _validate_sweep(path: str, overrides: list[str] | None) -> None:
    from flexmm.sweep.spec import load_sweep

    spec = load_sweep(path, overrides=overrides)
    points = spec.points()  # one ConfigError listing every point that does not validate
    typer.echo(f"{path}: ok — sweep {spec.name}: {len(points)} points, {spec.mode} of "
               f"{', '.join(a.path for a in spec.axes)}")
