"""``flexmm run CONFIG``: integrate a scene, write its dataset, print what it measured."""

from __future__ import annotations

import signal

import typer

from flexmm.cli.common import (
    EXIT_FAILED_RUN, OverrideOption, analysis_request, check_output_dir, load_or_exit, stderr_is_tty, writing,
)
from flexmm.cli.plan import AnalysisOption, FidelityOption


def run(
    config: str = typer.Argument(..., help="Scene YAML file."),
    overrides: list[str] = OverrideOption,
    out: str = typer.Option(None, "--out", "-o", help="Run directory (default output.directory/name)."),
    force: bool = typer.Option(False, "--force", help="Run even if dt exceeds the stable limit or the run "
                                                       "exceeds the memory, output, disk or step limits."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Only print the dataset path (no label)."),
    strict: bool = typer.Option(False, "--strict", help="Exit with status 3 when the run's error estimate "
                                                         "exceeds its target (solver.accuracy)."),
    fidelity: str = FidelityOption,
    analysis: str = AnalysisOption,
) -> None:
    """Run a scene and write runs/<name>/dataset.nc (netCDF4, SI units).

    Outputs are committed together when the run ends: a finished run replaces runs/<name>; a
    failed or interrupted one (Ctrl-C: exit 130, SIGTERM: exit 143) is kept in
    runs/<name>.failed or runs/<name>.interrupted.
    """
    from flexmm._signals import exit_status, signal_of, stop_on_signals
    from flexmm.api import run_dir_for, run_scene

    ov = list(overrides or [])
    if force:
        ov.append("solver.allow_unstable=true")
    analysis_request(analysis)  # an unknown --analysis is a usage error before anything runs
    scene = load_or_exit(config, ov)
    run_dir = check_output_dir(run_dir_for(scene, out))
    log = None if quiet else (lambda m: typer.echo(m, err=True))
    from flexmm.plan.cost import EXACT_SITES, enforce

    # memory, output and disk before anything is built (steps too for a large lattice, from a small
    # copy; a small scene's steps are checked once planning has built it)
    big = scene.lattice.n_sites > EXACT_SITES
    for line in enforce(scene, run_dir, force, step=big).lines():  # ResourceError unless --force
        if log and big:
            log(line)
    with writing(run_dir), stop_on_signals():
        try:
            result = run_scene(scene, run_dir=out, progress=stderr_is_tty() and not quiet, log=log,
                               fidelity=fidelity, analysis=analysis, force_limits=force)
        except KeyboardInterrupt as exc:  # before the time loop started: nothing was written
            sig = signal_of(exc)
            typer.echo(f"interrupted by {signal.Signals(sig).name} before the run started: nothing written",
                       err=True)
            raise typer.Exit(exit_status(sig)) from None
    typer.echo(result.path if quiet else f"dataset: {result.path}")
    if not result.ok:
        typer.echo(f"status: {result.status}: {result.reason}", err=True)
        raise typer.Exit(exit_status(result.signal) if result.signal else EXIT_FAILED_RUN)
    _print_error_estimate(result.accuracy, quiet)
    if strict and result.accuracy_missed:
        raise typer.Exit(EXIT_INACCURATE)
    if quiet:
        return
    _print_leading_pulse(result.path)


#: exit status of ``--strict`` when the error estimate exceeds the target
EXIT_INACCURATE = 3


def _print_error_estimate(acc: dict, quiet: bool) -> None:
    """One line with the run's error estimate (stdout), a warning on stderr when it misses the target."""
    if not acc:
        return
    est, target = acc["accuracy_estimate"], acc.get("accuracy_requested")
    line = f"error estimate: {est:.3g} (target {target:g}, {acc.get('accuracy_check', '')})"
    if not quiet:
        typer.echo(line)
    if not acc.get("accuracy_met", 1):
        typer.echo(f"warning: the estimated error {est:.3g} exceeds the target {target:g}", err=True)


def _print_leading_pulse(path) -> None:
    """The quick single-pulse measurement of a finished run, with the continuum's prediction."""
    from flexmm.analysis import PulseNotFound, leading_pulse
    from flexmm.analysis.context import RunContext
    from flexmm.analysis.rest import from_rest, rest_fields
    from flexmm.io.dataset import open_run
    from flexmm.plan.continuum import alongside

    ds = open_run(path)
    ds = from_rest(ds, rest_fields(RunContext.from_dataset(ds)))  # a predeformed run: from its rest state
    field = "theta" if "theta" in ds else next(v for v in ds.data_vars if ds[v].dims == ("time", "site"))
    try:
        p = leading_pulse(ds, field)
    except PulseNotFound as exc:
        typer.echo(f"no pulse measured: {exc}")
        return
    typer.echo(
        f"leading {field} pulse: speed {p.speed_m_s:.4g} ± {p.speed_stderr_m_s:.2g} m/s, "
        f"amplitude {p.amplitude:.4g} {p.amplitude_units}, width (FWHM) {p.fwhm_m * 1e3:.4g} mm "
        f"({p.fwhm_sites:.2f} sites), fitted over sites {p.first_site}-{p.last_site}"
    )
    line = alongside(ds, field, p.amplitude, p.fwhm_sites, p.speed_m_s)
    if line:
        typer.echo(line)
