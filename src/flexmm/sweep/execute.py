"""Run the pending points of a sweep on local processes or a Dask cluster, resumably.

``prepare`` validates every point and reads the sweep directory's state; ``execute`` runs what is
pending (failed points only with ``retry_failed``) in batches of several points per task:

- locally: ``concurrent.futures.ProcessPoolExecutor`` (spawned processes, one per core by
  default, numba and BLAS pinned to one thread each);
- ``scheduler="tcp://host:8786"``: an existing ``dask.distributed`` scheduler (workers need
  flexmm installed and the sweep directory on a shared filesystem);
- ``local_dask=True``: a ``distributed.LocalCluster`` started for the sweep.

Ctrl-C stops the workers' current points (their partial files are removed), cancels the rest
and returns with ``interrupted=True``; every point finished so far stays finished.
"""

from __future__ import annotations

import math
import os
import signal
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from flexmm.errors import UsageError
from flexmm.io.provenance import resolved_config
from flexmm.sweep.spec import Point, SweepSpec, spec_summary
from flexmm.sweep.store import FAILED, FINISHED, PENDING, SweepStore, write_json_atomic
from flexmm.sweep.worker import INTERRUPTED, ONE_THREAD, Task, init_worker, run_batch

MAX_BATCH = 8
BATCHES_PER_WORKER = 3

Outcome = dict
OnOutcome = Callable[[Outcome], None]

#: how long to wait for a Dask scheduler before saying it cannot be reached
SCHEDULER_TIMEOUT_S = 10.0


@dataclass
class SweepPlan:
    """A validated sweep, its directory, and the state of each distinct point when planned."""

    spec: SweepSpec
    store: SweepStore
    points: list[Point]
    states: dict[str, str]
    tasks: list[Task]
    retry_failed: bool = False

    @property
    def n_points(self) -> int:
        return len(self.points)

    def count(self, state: str) -> int:
        return sum(1 for s in self.states.values() if s == state)


@dataclass
class SweepReport:
    """What a sweep call did: counts per state (distinct configs), timing and the result file."""

    sweep_dir: Path
    n_points: int
    n_cached: int
    n_skipped_failed: int
    n_run: int = 0
    n_finished: int = 0
    n_failed: int = 0
    n_pending: int = 0
    interrupted: bool = False
    result_path: Path | None = None
    wall_s: float = 0.0
    backend: str = "local"
    errors: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.interrupted and self.n_failed == 0 and self.n_pending == 0


@contextmanager
def one_thread_environment():
    """NUMBA_NUM_THREADS=1 (and BLAS/OpenMP) in os.environ while worker processes are spawned.

    A spawned worker re-imports the parent's main script (for the ``flexmm`` entry point that
    loads numba) before any initialiser runs, so the variables must already be in the
    environment it inherits; this process's own numba keeps its settings (restored on exit).
    """
    saved = {name: os.environ.get(name) for name in ONE_THREAD}
    os.environ.update({name: "1" for name in ONE_THREAD})
    try:
        yield
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


def default_workers() -> int:
    """Cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def prepare(spec: SweepSpec, sweep_dir: str | Path, *, retry_failed: bool = False) -> SweepPlan:
    """Validate all points (ConfigError if any is invalid) and list the tasks to run."""
    points = spec.points()
    store = SweepStore(sweep_dir)
    states, tasks = {}, []
    analysis = spec.analysis.model_dump(exclude_defaults=True)  # plain data for the workers
    for p in points:
        if p.hash in states:
            continue
        states[p.hash] = store.state(p.hash)
        if states[p.hash] == PENDING or (states[p.hash] == FAILED and retry_failed):
            tasks.append(Task(p.hash, resolved_config(p.scene), str(store.point_dir(p.hash).resolve()),
                              _plain_params(p.params), analysis))
    return SweepPlan(spec, store, points, states, tasks, retry_failed)


def _plain_params(params: dict) -> dict:
    return {k: (v.item() if hasattr(v, "item") else v) for k, v in params.items()}


def batches(tasks: list[Task], n_workers: int, batch_size: int = 0) -> list[list[Task]]:
    """Split tasks into batches: given size, or about BATCHES_PER_WORKER per worker (≤ MAX_BATCH)."""
    if not tasks:
        return []
    size = batch_size or min(MAX_BATCH, max(1, math.ceil(len(tasks) / (BATCHES_PER_WORKER * n_workers))))
    return [tasks[i : i + size] for i in range(0, len(tasks), size)]


def execute(plan: SweepPlan, *, workers: int = 0, batch_size: int = 0, scheduler: str | None = None,
            local_dask: bool = False, dask_processes: bool = True,
            on_outcome: OnOutcome | None = None) -> SweepReport:
    """Run the plan's tasks; the report counts every distinct point's state afterwards."""
    t0 = time.perf_counter()
    plan.store.root.mkdir(parents=True, exist_ok=True)
    write_json_atomic(plan.store.root / "spec.json", spec_summary(plan.spec))
    report = SweepReport(plan.store.root, len(plan.states), plan.count(FINISHED),
                         0 if plan.retry_failed else plan.count(FAILED))
    if plan.tasks:
        plan.store.result_path.unlink(missing_ok=True)  # sweep.nc exists only after a complete run
    n_workers = workers or default_workers()
    seen: list[Outcome] = []

    def record(o: Outcome) -> None:
        seen.append(o)
        if on_outcome:
            on_outcome(o)

    if plan.tasks:
        if scheduler or local_dask:
            report.backend = f"dask {scheduler}" if scheduler else "dask LocalCluster"
            report.interrupted = _run_dask(plan.tasks, scheduler, n_workers, batch_size, dask_processes,
                                           record, report.errors)
        else:
            report.backend = f"local processes ({min(n_workers, len(batches(plan.tasks, n_workers, batch_size)))})"
            report.interrupted = _run_local(plan.tasks, n_workers, batch_size, record, report.errors)
    report.interrupted |= any(o["status"] == INTERRUPTED for o in seen)
    report.n_run = sum(1 for o in seen if o["status"] != INTERRUPTED)
    final = {h: plan.store.state(h) for h in plan.states}
    report.n_finished = sum(s == FINISHED for s in final.values())
    report.n_failed = sum(s == FAILED for s in final.values())
    report.n_pending = sum(s == PENDING for s in final.values())
    report.wall_s = time.perf_counter() - t0
    return report


def _run_local(tasks, n_workers, batch_size, record: OnOutcome, errors: list[str]) -> bool:
    """Keep one batch per worker in flight (nothing queued behind them, so Ctrl-C stops promptly)."""
    import multiprocessing
    from concurrent.futures.process import BrokenProcessPool

    work = batches(tasks, n_workers, batch_size)
    n = max(1, min(n_workers, len(work)))
    ex = ProcessPoolExecutor(max_workers=n, mp_context=multiprocessing.get_context("spawn"),
                             initializer=init_worker)
    todo = list(reversed(work))
    in_flight: dict = {}

    def submit_next() -> None:
        if todo:
            try:
                in_flight[ex.submit(run_batch, todo[-1])] = todo[-1]
                todo.pop()
            except BrokenProcessPool as exc:
                errors.append(f"worker pool broken ({exc}); {sum(map(len, todo))} point(s) left pending")
                todo.clear()

    interrupted = False
    try:
        with one_thread_environment():  # the workers spawned by these submits inherit it
            for _ in range(n):
                submit_next()
        while in_flight:
            done, _ = wait(in_flight, return_when=FIRST_COMPLETED)
            for fut in done:
                _collect(fut, in_flight.pop(fut), record, errors)
                submit_next()
    except KeyboardInterrupt:
        interrupted = True
        _stop_local(ex, in_flight, record, errors)
    finally:
        ex.shutdown(wait=True, cancel_futures=True)
    return interrupted


def _stop_local(ex: ProcessPoolExecutor, futures: dict, record: OnOutcome, errors: list[str]) -> None:
    """Interrupt the running batches (workers ignore SIGINT between batches) until all have returned."""
    pending = {f for f in futures if not f.cancel()}
    while pending:
        for proc in list(getattr(ex, "_processes", None or {}).values()):
            try:
                os.kill(proc.pid, signal.SIGINT)
            except (ProcessLookupError, PermissionError):
                pass
        done, pending = wait(pending, timeout=0.5)
        for fut in done:
            _collect(fut, futures[fut], record, errors)


def _collect(fut, batch, record: OnOutcome, errors: list[str]) -> None:
    try:
        outcomes = fut.result()
    except Exception as exc:  # noqa: BLE001 - a crashed worker loses its batch; the points stay pending
        errors.append(f"a worker failed ({type(exc).__name__}: {exc}); "
                      f"{len(batch)} point(s) left pending, rerun to resume")
        return
    for o in outcomes:
        record(o)


def _run_dask(tasks, scheduler, n_workers, batch_size, processes, record: OnOutcome, errors: list[str]) -> bool:
    try:
        from distributed import Client, LocalCluster, as_completed
    except ImportError:
        raise UsageError("Dask sweeps need dask.distributed: pip install 'flexmm[dask]'") from None

    cluster = None
    if scheduler:
        try:
            client = Client(scheduler, timeout=f"{SCHEDULER_TIMEOUT_S:g}s")
        except (OSError, TimeoutError) as exc:
            raise UsageError(f"cannot reach the Dask scheduler at {scheduler} within "
                             f"{SCHEDULER_TIMEOUT_S:g} s ({type(exc).__name__}: {exc})") from None
        n = sum(w.get("nthreads", 1) for w in client.scheduler_info()["workers"].values()) or 1
    else:
        with one_thread_environment():  # inherited by the worker processes spawned here
            cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=processes,
                                   dashboard_address=None)
        client = Client(cluster)
        n = n_workers
    work = batches(tasks, n, batch_size)
    futures = [client.submit(run_batch, b, pure=False) for b in work]
    by_key = {f.key: b for f, b in zip(futures, work)}
    interrupted = False
    try:
        for fut in as_completed(futures):
            _collect(fut, by_key[fut.key], record, errors)
    except KeyboardInterrupt:
        interrupted = True
        client.cancel(futures)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    return interrupted


def run_sweep(spec: SweepSpec, sweep_dir: str | Path, *, retry_failed: bool = False,
              **options) -> SweepReport:
    """Prepare, execute and (when no point is left pending) write SWEEP_DIR/sweep.nc.

    ``options`` go to ``execute`` (workers, batch_size, scheduler, local_dask, dask_processes,
    on_outcome).
    """
    from flexmm.sweep.combine import write_combined

    from flexmm.io.rundir import exclusive

    root = Path(sweep_dir).expanduser()
    with exclusive(root / ".sweep.lock", f"sweep directory {root}"):  # one sweep per directory
        plan = prepare(spec, root, retry_failed=retry_failed)
        report = execute(plan, **options)
        if not report.interrupted and report.n_pending == 0:
            report.result_path = write_combined(plan)
    return report


def reanalyse(plan: SweepPlan, on_outcome: OnOutcome | None = None) -> int:
    """Measure every finished point again (after the analysis changed); returns how many.

    Only done.json is rewritten (atomically, observables replaced); no point is re-run.
    """
    from flexmm.sweep.observe import observe_run
    from flexmm.sweep.store import DATASET, DONE

    n = 0
    for h, state in plan.states.items():
        if plan.store.state(h) != FINISHED:
            continue
        info = plan.store.read(h, DONE)
        try:
            info["observables"] = observe_run(plan.store.point_dir(h) / DATASET, plan.spec.analysis)
        except Exception as exc:  # noqa: BLE001 - as in the worker: a note, not a crash
            info["observables"] = {"note": f"analysis error: {type(exc).__name__}: {exc}"}
        write_json_atomic(plan.store.point_dir(h) / DONE, info)
        n += 1
        if on_outcome:
            on_outcome(info)
    return n
