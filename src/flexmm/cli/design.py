"""``flexmm design SPEC``: optimise design variables of a scene with exact gradients.

Only typer and the standard library are imported here; the optimiser (numpy, scipy, numba) is
loaded inside the command.
"""

from __future__ import annotations

import typer


def design(
    spec: str = typer.Argument(..., help="Design spec YAML (scene, variables with bounds, objective, constraints)."),
    out: str = typer.Option(None, "--out", "-o", help="Output directory (default runs/<name>)."),
    resume: bool = typer.Option(False, "--resume", help="Continue from the best design in DIR/history.nc."),
    check_gradient: bool = typer.Option(False, "--check-gradient", help="Compare the adjoint gradient with "
                                        "central differences at the start point and stop; the last line is the "
                                        "worst relative error (exit 1 above 1e-6)."),
) -> None:
    """Optimise a scene's design variables for an objective of its run (L-BFGS-B, SLSQP or trust-constr).

    Writes DIR/history.nc after every evaluation (variables, objective, terms, gradient norm),
    then DIR/best_scene.yaml (runnable) and DIR/before_after.png.
    """
    from pathlib import Path

    import numpy as np
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    from flexmm.cli.fit import report_check
    from flexmm.design.optimize import History, check_gradient as check, load_design, optimise
    from flexmm.design.outputs import design_figure, write_dataset, write_scene
    from flexmm.errors import UsageError

    console = Console()
    dp = load_design(spec)
    if check_gradient:
        report_check(*check(dp))
        return
    directory = Path(out) if out else Path("runs") / dp.spec.name
    directory.mkdir(parents=True, exist_ok=True)
    history_path = directory / "history.nc"
    history = None
    if resume:
        if not history_path.exists():
            raise UsageError(f"--resume: no {history_path} to resume from")
        import xarray as xr

        with xr.open_dataset(history_path, engine="h5netcdf") as ds:
            history = History.from_dataset(ds.load())
        if history.labels != dp.design.labels:
            raise UsageError(f"--resume: {history_path} has variables {history.labels}, the spec {dp.design.labels}")
    scene0 = dp.design.scene(dp.design.x0)

    def save(h: History) -> None:
        write_dataset(h.dataset(), history_path, scene0)

    with Progress(TextColumn("{task.description}"), BarColumn(), TextColumn("{task.completed}/{task.total}"),
                  TimeElapsedColumn(), console=console, transient=True) as progress:
        task = progress.add_task("designing", total=dp.spec.optimizer.max_iterations)

        def on_eval(n, x, value, terms):
            progress.update(task, advance=1, description=f"evaluation {n}: objective {value:.5g}")

        result = optimise(dp, history, on_eval, save)
    hist = result.history
    best = result.best
    write_scene(dp.design.scene_data(result.x), directory / "best_scene.yaml",
                f"Best design of flexmm design {spec} (objective {hist.objective[best]:.6g} of the start's 1)")
    design_figure(dp, dp.design.x0, result.x, directory / "before_after.png")
    console.print(f"{result.message}; {len(hist.objective)} evaluations")
    for name, t0, t1 in zip(dp.term_names, hist.terms[0], hist.terms[best]):
        console.print(f"  {name}: start {t0:.6g} → best {t1:.6g} (× {t1 / t0 if t0 else np.nan:.3g})")
    console.print(f"wrote {directory}/history.nc, best_scene.yaml, before_after.png")
