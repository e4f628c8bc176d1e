"""``flexmm sweep SPEC``: run a family of scenes, resumably, locally or on a Dask cluster."""

from __future__ import annotations

from pathlib import Path

import typer

from flexmm.cli.common import (
    EXIT_FAILED_RUN, EXIT_INTERRUPTED, OverrideOption, check_output_dir, error, stderr_is_tty, writing,
)


def _load(path: str, vary: list[str], zip_axes: bool, overrides: list[str]):
    from flexmm.config.loader import read_yaml
    from flexmm.sweep.spec import is_sweep_spec, load_sweep, spec_from_scene

    data, _ = read_yaml(path)
    if is_sweep_spec(data):
        if vary:
            raise error(f"{path} is a sweep file with its own `vary:`; --vary goes with a scene config")
        return load_sweep(path, overrides=overrides)
    if not vary:
        raise error(f"{path} is a scene config: give the parameters to vary, e.g. "
                    "--vary excitation.velocity_m_s=0.5:3:6")
    return spec_from_scene(path, vary, zip_axes=zip_axes, overrides=overrides)


class _Bar:
    """Rich progress bar (finished / failed / remaining, ETA), or one line per point without a TTY."""

    def __init__(self, total: int, enabled: bool, lines: bool):
        self.total, self.finished, self.failed = total, 0, 0
        self.lines = lines and not enabled
        self.prog = None
        if enabled and total:
            from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

            self.prog = Progress(
                TextColumn("[bold]sweep"), BarColumn(), MofNCompleteColumn(),
                TextColumn("[green]{task.fields[finished]} finished"), TextColumn("[red]{task.fields[failed]} failed"),
                TextColumn("{task.fields[remaining]} remaining"), TextColumn("ETA"), TimeRemainingColumn(),
                transient=True,
            )
            self.task = self.prog.add_task("sweep", total=total, finished=0, failed=0, remaining=total)
            self.prog.start()

    def __call__(self, outcome: dict) -> None:
        status = outcome["status"]
        if status in ("busy", "elsewhere"):  # another worker holds or stored it (flexmm.sweep.lease)
            if self.lines:
                params = ", ".join(f"{k}={v}" for k, v in outcome["params"].items())
                typer.echo(f"[point {outcome['index']}] not run here: {params}: {outcome.get('reason')}", err=True)
            return
        if status == "interrupted":
            return
        self.finished += status == "finished"
        self.failed += status != "finished"
        done = self.finished + self.failed
        if self.prog:
            self.prog.update(self.task, completed=done, finished=self.finished, failed=self.failed,
                             remaining=self.total - done)
        elif self.lines:
            params = ", ".join(f"{k}={v}" for k, v in outcome["params"].items())
            extra = f": {outcome.get('reason')}" if status != "finished" else ""
            went_on = outcome.get("resumed") or (f"checkpoint not used, run from the start: {outcome['restarted']}"
                                                 if outcome.get("restarted") else "")
            extra += f"; {went_on}" if went_on else ""
            typer.echo(f"[{done}/{self.total}] {status} {params} ({outcome.get('wall_s', 0):.1f} s){extra}", err=True)

    def stop(self) -> None:
        if self.prog:
            self.prog.stop()


def sweep(
    spec: str = typer.Argument(..., help="Sweep YAML (base + vary), or a scene YAML together with --vary."),
    vary: list[str] = typer.Option(
        None, "--vary", help="PATH=start:stop:num, PATH=log:start:stop:num or PATH=a,b,c (repeatable: a grid)."),
    zip_axes: bool = typer.Option(False, "--zip", help="Pair the --vary lists element-wise instead of a grid."),
    overrides: list[str] = OverrideOption,
    out: str = typer.Option(None, "--out", "-o", help="Sweep directory (default <output.directory>/sweeps/<name>)."),
    workers: int = typer.Option(0, "--workers", "-j", min=0, help="Local worker processes (0: one per core)."),
    batch_size: int = typer.Option(0, "--batch-size", min=0, help="Points per task (0: automatic)."),
    scheduler: str = typer.Option(None, "--scheduler", help="Running Dask scheduler, e.g. tcp://host:8786."),
    local_dask: bool = typer.Option(False, "--local-dask", help="Start a dask.distributed LocalCluster for the sweep."),
    retry_failed: bool = typer.Option(False, "--retry-failed", help="Run points that failed before again."),
    dry_run: bool = typer.Option(False, "--dry-run", help="Validate and list the points with their state; run nothing."),
    reanalyse: bool = typer.Option(False, "--reanalyse", help="Measure finished points again (no re-run)."),
    plot: str = typer.Option(None, "--plot", help="Also plot the finished sweep to this PNG."),
    keep: str = typer.Option(None, "--keep", help="Points that keep their full run directory: all, none, "
                             "'every N' or 'where CONDITION' on observables, e.g. 'where speed > 2' "
                             "(default: the spec's keep:, else none)."),
    shard: str = typer.Option(None, "--shard", help="Run slice K of N of the points (K = 0..N-1) into the "
                              "sweep directory; shards run at once share one store. E.g. --shard $SLURM_ARRAY_TASK_ID/4."),
    cluster: str = typer.Option(None, "--cluster", help="'slurm' or 'pbs': submit the sweep as a job array of "
                                "--shards tasks (with --dry-run: print its batch script)."),
    shards: int = typer.Option(4, "--shards", min=1, help="Tasks of the --cluster job array."),
    job_options: list[str] = typer.Option(
        None, "--job-option", "--sbatch", "--qsub",
        help="Extra directive of the --cluster job script, after #SBATCH or #PBS, e.g. --sbatch=--partition=short "
             "or --qsub='-l walltime=2:00:00' (repeatable)."),
    checkpoint_s: float = typer.Option(None, "--checkpoint-s", metavar="SECONDS", show_default=False,
                                       help="Wall time between a running point's checkpoints (default 60; 0: only "
                                            "when Ctrl-C/SIGTERM stops it). A stopped or killed point goes on "
                                            "from its checkpoint when the sweep is run again."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Only print the paths written (sweep dataset, figure)."),
) -> None:
    """Run every point of a sweep (skipping finished ones) and combine them into SWEEP_DIR/sweep.nc."""
    from flexmm.sweep.execute import combine_if_done, execute, prepare
    from flexmm.sweep.execute import reanalyse as measure_again
    from flexmm.sweep.shard import parse_shard, sweep_lock

    if scheduler and local_dask:
        raise error("give --scheduler or --local-dask, not both")
    part = parse_shard(shard) if shard is not None else None
    if cluster is not None:
        from flexmm.sweep.jobarray import scheduler as batch_system

        batch_system(cluster)  # a UsageError naming the valid ones
        if part is not None:
            raise error(f"--cluster {cluster} makes the shards itself: give --shards N, not --shard")
    sw = _load(spec, list(vary or []), zip_axes, list(overrides or []))
    if keep is not None:
        import dataclasses

        from flexmm.sweep.spec import check_keep

        check_keep(keep, "--keep")
        sw = dataclasses.replace(sw, keep=keep)
    base = sw.base_scene()
    sweep_dir = check_output_dir(Path(out) if out else Path(base.output.directory) / "sweeps" / sw.name)
    if cluster:
        _job_array(sw, spec, vary, zip_axes, overrides, keep, retry_failed, Path(sweep_dir), cluster, shards,
                   workers, tuple(job_options or ()), dry_run, quiet)
        return
    with sweep_lock(Path(sweep_dir), part):  # one sweep per directory, or distinct shards of it
        plan = prepare(sw, sweep_dir, retry_failed=retry_failed, shard=part)
        say = (lambda m: None) if quiet else (lambda m: typer.echo(m, err=True))
        what = f"shard {part} ({len(plan.scope)} of {sw.n_points} points)" if part else f"{sw.n_points} points"
        say(f"sweep {sw.name}: {what} ({sw.mode} of {', '.join(a.path for a in sw.axes)}), "
            f"{plan.count('finished')} finished, {plan.count('failed')} failed before, {len(plan.tasks)} to run"
            + f" -> {sweep_dir}")
        if dry_run:
            _list_points(plan)
            return
        if reanalyse:
            say(f"re-measured {measure_again(plan)} finished points")
        bar = _Bar(len(plan.tasks), enabled=stderr_is_tty() and not quiet, lines=not quiet)
        try:
            report = execute(plan, workers=workers, batch_size=batch_size, scheduler=scheduler,
                             local_dask=local_dask, on_outcome=bar, checkpoint_s=_every(checkpoint_s))
        except KeyboardInterrupt:
            typer.echo("interrupted; rerun the same command to resume", err=True)
            raise typer.Exit(EXIT_INTERRUPTED) from None
        finally:
            bar.stop()
        for msg in report.errors:
            typer.echo(f"error: {msg}", err=True)
        say(f"{report.n_finished} finished ({report.n_run} run now, {report.n_cached} already done), "
            f"{report.n_failed} failed, {report.n_pending} pending; {report.wall_s:.1f} s on {report.backend}"
            + (f"; {report.n_elsewhere} left to another worker that held them" if report.n_elsewhere else ""))
        if report.interrupted:
            typer.echo(f"interrupted: {report.n_finished} of {report.n_points} points finished; "
                       "rerun the same command to resume", err=True)
            raise typer.Exit(EXIT_INTERRUPTED)
        if report.n_pending:
            raise typer.Exit(EXIT_FAILED_RUN)
        with writing(sweep_dir):
            path = combine_if_done(plan)
        if path is None:  # a shard done before the others: the last one to finish writes sweep.nc
            say(f"shard {part} done; {plan.count('pending', everywhere=True)} points of the sweep are pending "
                "in other shards (the last shard to finish writes sweep.nc)")
            if report.n_failed:
                _list_failed(plan)
                raise typer.Exit(EXIT_FAILED_RUN)
            return
        typer.echo(path if quiet else f"sweep dataset: {path}")
        if plot:
            from flexmm.sweep.plot import plot_sweep

            with writing(plot):
                figure = plot_sweep(sweep_dir, plot)
            typer.echo(figure if quiet else f"figure: {figure}")
        if report.n_failed:
            _list_failed(plan)
            raise typer.Exit(EXIT_FAILED_RUN)


def _every(checkpoint_s: float | None) -> float:
    """--checkpoint-s as the seconds between checkpoints (inf: only on a signal)."""
    import math

    from flexmm.sweep.worker import CHECKPOINT_S

    if checkpoint_s is not None and checkpoint_s < 0:
        raise error(f"--checkpoint-s {checkpoint_s:g}: expected seconds ≥ 0 (0: only when a signal stops a point)")
    seconds = CHECKPOINT_S if checkpoint_s is None else checkpoint_s
    return seconds if seconds > 0 else math.inf


def _job_array(sw, spec: str, vary, zip_axes: bool, overrides, keep, retry_failed: bool, sweep_dir: Path,
               system: str, shards: int, workers: int, options: tuple, dry_run: bool, quiet: bool) -> None:
    """Print (--dry-run) or submit the sweep as a job array of ``shards`` tasks (SLURM, PBS)."""
    from flexmm.sweep.execute import prepare
    from flexmm.sweep.jobarray import ArrayJob, job_script, submit

    prepare(sw, sweep_dir)  # the spec checked, a store of another spec refused, before anything is queued
    args = [str(Path(spec).resolve())]
    args += [f"--vary={v}" for v in vary or []] + (["--zip"] if zip_axes else [])
    args += [f"--set={o}" for o in overrides or []] + ([f"--keep={keep}"] if keep is not None else [])
    args += ["--retry-failed"] if retry_failed else []
    job = ArrayJob(sw.name, tuple(args), sweep_dir.resolve(), shards, workers or 1, options, system)
    if dry_run:
        typer.echo(job_script(job), nl=False)
        return
    script, job_id = submit(job)
    typer.echo(job_id if quiet else f"submitted {system.upper()} job array {job_id} ({shards} tasks, script "
               f"{script}; logs in {job.logs}); sweep.nc is written by the last task to finish")


def _list_points(plan) -> None:
    """One line per point: its number, state and varied values (nothing validated: fast)."""
    import itertools
    import sys

    spec = plan.spec
    words = [[f"{a.path}={v}" for v in a.values] for a in spec.axes]  # each value formatted once
    combos = zip(*words) if spec.mode == "zip" else itertools.product(*words)  # C order, as point_at
    states = ("pending ", "finished", "failed  ")
    width = len(str(spec.n_points - 1))
    status = plan.status.tolist()
    write = sys.stdout.write
    r = plan.scope  # a shard's points, or all
    for i, combo in enumerate(itertools.islice(combos, r.start, r.stop), start=r.start):
        write(f"{i:>{width}}  {states[status[i]]}  {', '.join(combo)}\n")
    sys.stdout.flush()


def _list_failed(plan, limit: int = 20) -> None:
    from flexmm.sweep.spec import label

    notes = plan.store.read()["note"]
    import numpy as np

    from flexmm.sweep.store import CODE

    failed = [int(i) for i in np.flatnonzero(plan.status == CODE["failed"])]
    for i in failed[:limit]:
        reason = notes[i].decode(errors="ignore")
        typer.echo(f"failed: point {i}: {label(plan.spec.params_at(i))}: {reason}", err=True)
    if len(failed) > limit:
        typer.echo(f"... and {len(failed) - limit} more failed points (status and note in {plan.store.result_path})",
                   err=True)
    typer.echo("rerun with --retry-failed to run failed points again", err=True)
