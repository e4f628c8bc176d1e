"""``flexmm run CONFIG``: integrate a scene, write its dataset, print what it measured."""

from __future__ import annotations

import math
import signal

import typer

from flexmm.errors import UsageError

from flexmm.cli.common import (
    EXIT_FAILED_RUN, OverrideOption, analysis_request, check_output_dir, load_or_exit, print_plan, stderr_is_tty,
    writing,
)
from flexmm.cli.plan import AnalysisOption, FidelityOption, check_fidelity


def run(
    config: str = typer.Argument(None, help="Scene YAML file (with --resume: optional, checked against the "
                                            "run's; with --extend: default RUN_DIR/config.yaml)."),
    overrides: list[str] = OverrideOption,
    out: str = typer.Option(None, "--out", "-o", help="Run directory (default output.directory/name)."),
    force: bool = typer.Option(False, "--force", help="Run even if dt exceeds the stable limit or the run "
                                                       "exceeds the memory, output, disk or step limits."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Only print the dataset path (no label)."),
    strict: bool = typer.Option(False, "--strict", help="Exit with status 3 when the run's error estimate "
                                                         "exceeds its target (solver.accuracy); without it, "
                                                         "only a miss by over 10x (status inaccurate)."),
    fidelity: str = FidelityOption,
    analysis: str = AnalysisOption,
    from_run: str = typer.Option(None, "--from", help="Continue RUN: start from its last frame "
                                                      "(sets initial.from_run; the config records it)."),
    resume: str = typer.Option(None, "--resume", metavar="RUN_DIR",
                               help="Continue the interrupted, failed or killed run RUN_DIR from its last "
                                    "checkpoint; publishes what an uninterrupted run would have."),
    extend: str = typer.Option(None, "--extend", metavar="RUN_DIR",
                               help="Continue the finished run RUN_DIR to the longer duration given by "
                                    "--set solver.duration_s=... (same step and frame interval)."),
    checkpoint_s: float = typer.Option(None, "--checkpoint-s", metavar="SECONDS", show_default=False,
                                       help="Wall time between checkpoints (default 60; 0: only when the run "
                                            "ends or a signal stops it)."),
) -> None:
    """Run a scene and write runs/<name>/dataset.nc (netCDF4, SI units).

    The plan (`flexmm plan`'s lines: method, step, stable limit, frames, domain, cost and any change
    made to what the scene asked) is printed first. Outputs are committed together when the run ends: a finished run replaces runs/<name>; a
    failed or interrupted one (Ctrl-C: exit 130, SIGTERM: exit 143) is kept in
    runs/<name>.failed or runs/<name>.interrupted. A run writes checkpoints (every --checkpoint-s
    of wall time, when it ends, on Ctrl-C/SIGTERM); --resume continues one, --extend a finished run.
    """
    from flexmm._signals import exit_status, signal_of, stop_on_signals
    from flexmm.api import run_dir_for, run_scene
    from flexmm.io.rundir import refuse_inputs_inside

    ended: list = []  # the run's result once it is published
    with stop_on_signals():  # SIGTERM like Ctrl-C from here on: reading, planning, the run, the summary
        try:
            ov = list(overrides or [])
            if force:
                ov.append("solver.allow_unstable=true")
            check_fidelity(fidelity)
            analysis_request(analysis)  # an unknown --analysis is a usage error before anything runs
            from flexmm.checkpoint import DEFAULT_EVERY_S  # numpy: not at start-up (--help)

            seconds = DEFAULT_EVERY_S if checkpoint_s is None else checkpoint_s
            every = seconds if seconds > 0 else math.inf
            if resume or extend:
                result = _continue(config, ov, resume, extend, every, quiet, force)
                ended.append(result)
                _report(result, quiet, strict, analysis)
                return
            if config is None:
                raise UsageError("missing the scene: flexmm run CONFIG (or --resume/--extend RUN_DIR)")
            scene = load_or_exit(config, ov, {"initial.from_run": ("--from", from_run)} if from_run else None)
            run_dir = check_output_dir(run_dir_for(scene, out))
            refuse_inputs_inside(run_dir, [config])  # a finished run replaces its directory: never the user's input
            log = None if quiet else (lambda m: typer.echo(m, err=True))
            from flexmm.plan.cost import EXACT_SITES, enforce

            # memory, output and disk before anything is built (steps too for a large lattice, from a small
            # copy; a small scene's steps are checked once planning has built it)
            big = scene.lattice.n_sites > EXACT_SITES
            for line in enforce(scene, run_dir, force, step=big).lines():  # ResourceError unless --force
                if log and big:
                    log(line)
            with writing(run_dir):
                result = run_scene(scene, run_dir=out, progress=stderr_is_tty() and not quiet, log=log,
                                   fidelity=fidelity, analysis=analysis, force_limits=force, checkpoint_s=every,
                                   announce=lambda lines: print_plan(lines, quiet))
            ended.append(result)
            _report(result, quiet, strict, analysis)
        except KeyboardInterrupt as exc:  # outside the time loop (which keeps its frames itself)
            sig = signal_of(exc)
            name = signal.Signals(sig).name
            typer.echo(f"interrupted by {name} after the run ended: its outputs are kept ({ended[0].path})"
                       if ended else f"interrupted by {name} before the run started: nothing written", err=True)
            raise typer.Exit(exit_status(sig)) from None


def _continue(config: str | None, overrides: list[str], resume: str | None, extend: str | None, every: float,
              quiet: bool, force: bool):
    """``--resume`` / ``--extend``: the scene to check or extend with, then ``api.continue_run``."""
    from pathlib import Path

    from flexmm.api import continue_run
    from flexmm.cli.common import writing

    if resume and extend:
        raise UsageError("--resume and --extend: give one")
    target = Path(resume or extend)
    if extend:
        config = config or str(target / "config.yaml")  # the scene that ran: step and method fixed
    elif overrides and config is None:
        raise UsageError("--set with --resume needs CONFIG (the scene the run was started with)")
    scene = load_or_exit(config, overrides) if config else None
    log = None if quiet else (lambda m: typer.echo(m, err=True))
    with writing(target):
        return continue_run(target, scene, extend=bool(extend), progress=stderr_is_tty() and not quiet, log=log,
                            allow_version=force, checkpoint_s=every)


def _report(result, quiet: bool, strict: bool, analysis: str | None) -> None:
    """The dataset's path, the status and exit code, the error estimate and the summary of a run."""
    from flexmm._signals import exit_status

    if result.path is not None:
        typer.echo(result.path if quiet else f"dataset: {result.path}")
    if not result.ok:
        typer.echo(f"status: {result.status}: {result.reason}", err=True)
        if result.status == "inaccurate":  # went to its end, published as <name>.inaccurate
            _print_error_estimate(result.accuracy, quiet)
            raise typer.Exit(EXIT_INACCURATE)
        raise typer.Exit(exit_status(result.signal) if result.signal else EXIT_FAILED_RUN)
    _print_error_estimate(result.accuracy, quiet)
    if strict and result.accuracy_missed:
        raise typer.Exit(EXIT_INACCURATE)
    if quiet:
        return
    _print_summary(result.path, analysis)


#: exit status of an 'inaccurate' run (an error estimate over 10x its target, or the energy of a
#: conservative run off by over 1 %; ``controller.inaccuracy``), and of ``--strict`` on any miss
EXIT_INACCURATE = 3


def _print_error_estimate(acc: dict, quiet: bool) -> None:
    """One line with the run's error estimate (stdout), a warning on stderr when it misses the target."""
    if not acc:
        return
    est, target = acc["accuracy_estimate"], acc.get("accuracy_requested")
    parts = (f"amplitudes {acc['accuracy_estimate_amplitude']:.2g}, speeds {acc['accuracy_estimate_speed']:.2g}; "
             if "accuracy_estimate_speed" in acc else "")
    line = (f"error estimate: {est:.3g} of the wave amplitudes and speeds (target {target:g}; {parts}"
            f"{acc.get('accuracy_check', '').rstrip(',')})")  # the plan's wording continues after its comma
    if not quiet:
        typer.echo(line)
    if not acc.get("accuracy_met", 1):
        typer.echo(f"warning: the estimated error {est:.3g} exceeds the target {target:g}", err=True)


def _print_summary(path, analysis: str | None = None) -> None:
    """What ``flexmm analyze`` measures on the run (the same analysis, field and feature), in a
    few lines: the pulse, front, driven response or wave groups the scene is about, with theory."""
    from flexmm.analysis.report import analyze as report
    from flexmm.analysis.report.summary import principal, summary_lines
    from flexmm.cli.common import analysis_request
    from flexmm.plan.continuum import alongside
    from flexmm.plan.output import PURPOSES

    request = analysis_request(analysis)
    if request is not None and PURPOSES[request.kind].energies:  # a run for its energies: nothing to measure
        return
    kind = request.kind if request is not None else "auto"
    res, why = report.measure_run(path, kind=kind, field_spec=request.field if request else None)
    if res is None:  # the run is fine; there is just nothing (or no such field) to measure
        typer.echo(f"nothing measured: {why}")
        return
    for line in summary_lines(res):
        typer.echo(line)
    pick = principal(res)
    if res.kind == "pulse" and pick is not None:
        p = pick[1]
        line = alongside(res.ctx.ds, p.field, p.amplitude, p.fwhm_m / res.view.spacing_m, p.speed_m_s)
        if line:
            typer.echo(line)
