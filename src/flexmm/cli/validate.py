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
    """Validate a scene config (schema, cross-field rules and, by default, the plan: the method,
    step, stable limit, frames, domain and cost that `flexmm plan` and `flexmm run` show), or a
    sweep spec (its schema and every point's scene; nothing is built).

    The plan is `flexmm plan`'s (its accuracy pilots run; nothing is written). A lattice of more
    than 200,000 units is not built: its step comes from a small copy of the lattice, so any size
    validates in about a second, and the pilots choose the step when it runs. A run beyond the
    limits on memory, output size, free disk or steps is reported as an error (flexmm.plan.cost).
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
    from flexmm.plan.cost import PLANNED_SITES, ResourceError, check, estimate

    check_output_dir(run_dir_for(scene))  # OutputError if the output could not be written there
    if scene.lattice.n_sites > PLANNED_SITES:
        cost = estimate(scene)
        lines = cost.lines() + ["cost: method and step: chosen when the run starts (flexmm plan builds the "
                                "lattice and runs the accuracy pilots)"]
        dt = "dt unknown" if cost.dt_s is None else f"dt ≈ {cost.dt_s:.4g} s" + (
            "" if cost.stable_dt_s is None else f" (stable limit {cost.stable_dt_s:.4g} s)")
        head = f"{scene.lattice.kind}, {cost.ndof:,} DOFs, {dt}"
    else:
        from flexmm.prepare import resolve

        rp = resolve(scene, "auto")
        cost, lines = rp.cost, rp.lines()
        head = f"{rp.plan.scene.lattice.kind}, plan above" if cost is not None else "continuum, plan above"
    for line in lines:
        typer.echo(line)
    problems = [] if cost is None else check(cost, run_dir_for(scene))
    if problems:
        raise ResourceError("a run would be refused: " + "; ".join(problems) + " (flexmm run --force runs it anyway)")
    typer.echo(f"{config}: ok — {head}")


def _validate_sweep(path: str, overrides: list[str] | None) -> None:
    from flexmm.sweep.spec import load_sweep

    spec = load_sweep(path, overrides=overrides)
    points = spec.points()  # one ConfigError listing every point that does not validate
    typer.echo(f"{path}: ok — sweep {spec.name}: {len(points)} points, {spec.mode} of "
               f"{', '.join(a.path for a in spec.axes)}")
