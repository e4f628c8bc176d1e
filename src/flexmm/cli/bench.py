"""``flexmm bench CONFIG``: work–precision of every integrator and of scipy's solve_ivp.

Writes ``workprecision.nc`` (one entry per run), ``workprecision.csv`` and
``workprecision.png`` (error against wall time and against force evaluations), and prints the
speed-up over the best solve_ivp method at equal error.
"""

from __future__ import annotations

import csv
from pathlib import Path

import typer

from flexmm.cli.common import OverrideOption, check_output_dir, error, load_or_exit, output_dir, planned, writing

FILES = ("workprecision.nc", "workprecision.csv", "workprecision.png")


def bench(
    config: str = typer.Argument(..., help="Scene YAML file."),
    overrides: list[str] = OverrideOption,
    methods: str = typer.Option(None, "--methods", "-m", help="Comma-separated integrators (default: all)."),
    ivp: str = typer.Option("RK45,DOP853,LSODA", "--ivp", help="solve_ivp methods ('' for none)."),
    frames: int = typer.Option(None, "--frames", min=2,
                               help="Saved frames, errors checked on all (default: the scene's output.n_frames)."),
    repeats: int = typer.Option(3, "--repeats", help="Timed runs per setting (the minimum is kept)."),
    budget_s: float = typer.Option(30.0, "--budget", help="Stop a method's ladder past this wall time per run."),
    out: str = typer.Option(None, "--out", "-o", help="Output directory (default runs/<name>/bench)."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Only print the paths of the files written."),
    force: bool = typer.Option(False, "--force", help="Bench a chaotic scene anyway (its errors measure the chaos)."),
) -> None:
    """Chart error against cost for each integrator and for solve_ivp on the same equations.

    The equations are those `flexmm run` would integrate (its plan, printed first: trimmed domain,
    pruned output, frames); the plan's method and step are one point of the chart's ladders. A
    scene whose reported quantities are chaotic (a reference at 1000x its tolerance reports other
    wave amplitudes and speeds) is refused unless --force. The chart's error is that of those
    quantities (the run's error estimate's), the final state's is in the dataset."""
    from flexmm.diagnostics import baseline
    from flexmm.diagnostics import workprecision as wp
    from flexmm.integrators import INTEGRATORS
    from flexmm.io.cf import write_netcdf
    from flexmm.io.provenance import provenance_attrs

    names = [m.strip() for m in (methods or ",".join(INTEGRATORS)).split(",") if m.strip()]
    ivps = [m.strip() for m in ivp.split(",") if m.strip()]
    bad = [m for m in names if m not in INTEGRATORS] + [m for m in ivps if m not in baseline.METHODS]
    if bad:
        raise error(f"unknown method(s) {bad}; integrators: {', '.join(INTEGRATORS)}; "
                    f"solve_ivp: {', '.join(baseline.METHODS)}")
    scene = load_or_exit(config, list(overrides or []))
    problem = planned(scene, quiet)  # the run's plan: its domain, method, step and frames
    folder = check_output_dir(Path(out) if out else Path(scene.output.directory) / scene.name / "bench")
    n_frames = frames or scene.output.n_frames  # a frame interval also caps the largest step (the plan's frames)
    say = (lambda m: None) if quiet else (lambda m: typer.echo(m, err=True))
    try:
        rows, ref = wp.benchmark(problem, names, ivps, n_frames=n_frames, repeats=repeats, budget_s=budget_s,
                                 log=say, force=force)
    except wp.ChaoticReference as exc:
        raise error(str(exc)) from None
    attrs = {**provenance_attrs(scene), "reference": f"dopri5 rtol {ref.rtol:g}",
             "reference_pulse_speed_m_s": ref.speed, "reference_pulse_amplitude": ref.amplitude}
    output_dir(folder)
    with writing(folder):
        write_netcdf(wp.to_dataset(rows, attrs), folder / "workprecision.nc")
        with open(folder / "workprecision.csv", "w", newline="") as fh:
            writer = csv.DictWriter(fh, fieldnames=list(rows[0].as_dict()))
            writer.writeheader()
            writer.writerows(r.as_dict() for r in rows)
        wp.chart(rows, folder / "workprecision.png", f"{scene.name}: work-precision")
    if quiet:
        for name in FILES:
            typer.echo(folder / name)
        return
    for key, what in (("wall_s", "wall"), ("cpu_s", "CPU")):
        for s in wp.speedups(rows, key=key):
            typer.echo(f"error ≤ {s['error']:.0e} ({what} time): {s['flexmm_method']} {s['flexmm_s']:.4g} s vs "
                       f"solve_ivp {s['solve_ivp_method']} {s['solve_ivp_s']:.4g} s: {s['speedup']:.1f}x faster")
    typer.echo(f"written: {folder}/workprecision.{{nc,csv,png}}")
