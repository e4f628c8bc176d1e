"""``flexmm fit SPEC``: fit scene parameters to a measured trajectory (least squares, exact Jacobian).

Only typer and the standard library are imported here; the fit (numpy, scipy, numba) is loaded
inside the command.
"""

from __future__ import annotations

import typer

from flexmm.cli.common import EXIT_FAILED_RUN


def fit(
    spec: str = typer.Argument(..., help="Fit spec YAML (scene, measured table, parameters)."),
    out: str = typer.Option(None, "--out", "-o", help="Output directory (default runs/<name>)."),
    check_gradient: bool = typer.Option(False, "--check-gradient", help="Compare the adjoint gradient of the "
                                        "cost with central differences at the start point and stop; the last "
                                        "line is the worst relative error (exit 1 above 1e-6)."),
) -> None:
    """Fit parameters of a scene to a measured table: least squares with the Gauss-Newton covariance.

    Writes DIR/fit.nc (data, start and fitted model, residuals, values, standard errors,
    covariance), DIR/fitted_scene.yaml (runnable) and DIR/fit.png.
    """
    from pathlib import Path

    import numpy as np
    from rich.console import Console

    from flexmm.design.fit import check_gradient as check
    from flexmm.design.fit import load_fit, solve
    from flexmm.design.outputs import fit_dataset, fit_figure, write_dataset, write_scene

    console = Console()
    problem = load_fit(spec)
    if check_gradient:
        report_check(problem.design.labels, *check(problem))
        return
    with console.status("fitting ...") as status:
        result = solve(problem, lambda n, x, c: status.update(f"fitting: evaluation {n}, cost {c:.6g}"))
    directory = Path(out) if out else Path("runs") / problem.spec.name
    directory.mkdir(parents=True, exist_ok=True)
    ds = fit_dataset(problem, result, problem.model(problem.design.x0), problem.model(result.x))
    scene = problem.design.scene(result.x)
    write_dataset(ds, directory / "fit.nc", scene)
    write_scene(problem.design.scene_data(result.x), directory / "fitted_scene.yaml",
                f"Scene with the parameters fitted by flexmm fit {spec}")
    fit_figure(ds, directory / "fit.png")
    console.print(f"{result.status} after {result.evaluations} evaluations; cost {result.cost0:.6g} → "
                  f"{result.cost:.6g}, reduced χ² = {result.reduced_chi2:.4g}")
    for label, x0, x, se in zip(problem.design.labels, problem.design.x0, result.x, result.stderr):
        console.print(f"  {label:>16s} = {x:.6g} ± {se:.2g}   (start {x0:.6g}, {abs(se / x) * 100 if x else np.inf:.2g} %)")
    console.print(f"wrote {directory}/fit.nc, fitted_scene.yaml, fit.png")


#: --check-gradient fails above this worst relative error
CHECK_TOLERANCE = 1e-6


def report_check(labels, adjoint, fd, err) -> None:
    """Print one line per variable, then the worst relative error (last line); exit 1 above tolerance."""
    for label, a, f, e in zip(labels, adjoint, fd, err):
        typer.echo(f"  {label:>16s}  adjoint {a: .10e}  central difference {f: .10e}  relative error {e:.2e}")
    worst = float(max(err)) if len(err) else 0.0
    typer.echo(f"worst relative error: {worst:.3e}")
    if not worst <= CHECK_TOLERANCE:
        raise typer.Exit(EXIT_FAILED_RUN)
