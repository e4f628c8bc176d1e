"""Run the pending points of a sweep on local processes or a Dask cluster, resumably.

``prepare`` validates the spec once (``SweepSpec.check``) and reads the sweep's status array;
points are built and validated by the workers as they run them (an invalid one is recorded as
failed with the reason), so planning costs the same for 10 points as for 10⁶. ``execute`` lays
out the store (``flexmm.sweep.store``) and runs what is pending (failed points only with
``retry_failed``) in batches of several points per task:

- locally: ``concurrent.futures.ProcessPoolExecutor`` (spawned processes, one per core by
  default, numba and BLAS pinned to one thread each; the spec is sent once per process);
- ``scheduler="tcp://host:8786"``: an existing ``dask.distributed`` scheduler (workers need
  flexmm installed and the sweep directory on a shared filesystem; the spec is scattered once);
- ``local_dask=True``: a ``distributed.LocalCluster`` started for the sweep.

Ctrl-C stops the workers' current points (they stay pending, each with a checkpoint of where it
stopped), cancels the rest and returns with ``interrupted=True``; every point finished so far stays
finished. The next run continues the stopped points from their checkpoints, and so it does for
points whose worker was killed (from their last checkpoint, written every ``checkpoint_s`` of
wall time): ``flexmm.sweep.worker.run_point``.
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
from typing import Callable, Iterator

import numpy as np

from flexmm.errors import UsageError
from flexmm.sweep.shard import Shard, store_lock
from flexmm.sweep.spec import SweepSpec, spec_summary
from flexmm.sweep.store import CODE, FAILED, FINISHED, PENDING, SweepStore, spec_fingerprint, write_json_atomic
from flexmm.sweep.worker import (
    BUSY, CHECKPOINT_S, ELSEWHERE, INTERRUPTED, ONE_THREAD, Batch, init_worker, run_batch,
)

MAX_BATCH = 8
BATCHES_PER_WORKER = 3

Outcome = dict
OnOutcome = Callable[[Outcome], None]

#: how long to wait for a Dask scheduler before saying it cannot be reached
SCHEDULER_TIMEOUT_S = 10.0


@dataclass
class SweepPlan:
    """A checked sweep, its directory, the status of every point when planned, what to run."""

    spec: SweepSpec
    store: SweepStore
    status: np.ndarray  # status byte per point (flexmm.sweep.store.STATES)
    tasks: np.ndarray  # numbers of the points to run
    retry_failed: bool = False
    shard: Shard | None = None  # the slice of the points this plan runs (all if None)

    @property
    def n_points(self) -> int:
        return self.spec.n_points

    @property
    def scope(self) -> range:
        """The point numbers this plan is about: its shard's, or all."""
        return self.shard.range(self.n_points) if self.shard else range(self.n_points)

    def count(self, state: str, everywhere: bool = False) -> int:
        """Points in ``state`` in the plan's scope (in the whole sweep with ``everywhere``)."""
        r = range(self.n_points) if everywhere else self.scope
        return int(np.count_nonzero(self.status[r.start:r.stop] == CODE[state]))

    def state(self, index: int) -> str:
        return (PENDING, FINISHED, FAILED)[int(self.status[index])]

    @property
    def fingerprint(self) -> str:
        return spec_fingerprint(spec_summary(self.spec), self.spec.base_data)


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
    n_elsewhere: int = 0  # points handed to this sweep that another worker held (flexmm.sweep.lease)
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


def prepare(spec: SweepSpec, sweep_dir: str | Path, *, retry_failed: bool = False,
            shard: Shard | None = None) -> SweepPlan:
    """Check the spec (ConfigError with every problem found up front) and read the sweep's
    status array (a store of another spec is refused); nothing is written. With ``shard``, only
    the points of that slice are run (``flexmm.sweep.shard``)."""
    spec.check()
    store = SweepStore(sweep_dir)
    plan = SweepPlan(spec, store, np.zeros(spec.n_points, np.uint8), np.zeros(0, np.int64), retry_failed, shard)
    if store.exists():
        store.check(plan.fingerprint, spec.n_points)
        plan.status = store.status()
    r = plan.scope
    todo = plan.status[r.start:r.stop] == CODE[PENDING]
    if retry_failed:
        todo |= plan.status[r.start:r.stop] == CODE[FAILED]
    plan.tasks = np.flatnonzero(todo) + r.start
    return plan


def batch_size_for(n_tasks: int, n_workers: int, batch_size: int = 0) -> int:
    """Points per task: the given size, or about BATCHES_PER_WORKER tasks per worker (≤ MAX_BATCH)."""
    return batch_size or min(MAX_BATCH, max(1, math.ceil(n_tasks / (BATCHES_PER_WORKER * n_workers))))


def batches(tasks: np.ndarray, root: str, size: int, checkpoint_s: float = CHECKPOINT_S,
            retry_failed: bool = False) -> Iterator[Batch]:
    """The tasks in consecutive batches of ``size`` points (made as they are submitted)."""
    for i in range(0, len(tasks), size):
        yield Batch(tuple(int(k) for k in tasks[i : i + size]), root, checkpoint_s, retry_failed)


def execute(plan: SweepPlan, *, workers: int = 0, batch_size: int = 0, scheduler: str | None = None,
            local_dask: bool = False, dask_processes: bool = True, checkpoint_s: float = CHECKPOINT_S,
            on_outcome: OnOutcome | None = None) -> SweepReport:
    """Run the plan's tasks; the report counts every point's state afterwards. ``checkpoint_s``: wall
    time between a running point's checkpoints (``flexmm.sweep.worker.run_point``)."""
    from flexmm.sweep.observe import OBSERVABLES

    t0 = time.perf_counter()
    store = plan.store
    store.root.mkdir(parents=True, exist_ok=True)
    with store_lock(store.root):  # shards running at once: the first lays the store out
        store.create_or_check(plan.fingerprint, plan.n_points, list(OBSERVABLES), plan.spec.name)
        write_json_atomic(store.root / "spec.json", spec_summary(plan.spec))
    report = SweepReport(store.root, plan.n_points, plan.count(FINISHED),
                         0 if plan.retry_failed else plan.count(FAILED))
    if len(plan.tasks):
        with store_lock(store.root):
            store.result_path.unlink(missing_ok=True)  # sweep.nc exists only after a complete run
    n_workers = workers or default_workers()
    seen: list[Outcome] = []

    def record(o: Outcome) -> None:
        seen.append(o)
        if on_outcome:
            on_outcome(o)

    if len(plan.tasks):
        size = batch_size_for(len(plan.tasks), n_workers, batch_size)
        work = batches(plan.tasks, str(store.root.resolve()), size, checkpoint_s, plan.retry_failed)
        n_batches = math.ceil(len(plan.tasks) / size)
        if scheduler or local_dask:
            report.backend = f"dask {scheduler}" if scheduler else "dask LocalCluster"
            report.interrupted = _run_dask(plan.spec, work, scheduler, n_workers, dask_processes,
                                           record, report.errors)
        else:
            report.backend = f"local processes ({min(n_workers, n_batches)})"
            report.interrupted = _run_local(plan.spec, work, min(n_workers, n_batches), record, report.errors)
    report.interrupted |= any(o["status"] == INTERRUPTED for o in seen)
    report.n_run = sum(1 for o in seen if o["status"] not in (INTERRUPTED, BUSY, ELSEWHERE))
    report.n_elsewhere = sum(1 for o in seen if o["status"] in (BUSY, ELSEWHERE))
    plan.status = store.status()
    report.n_finished, report.n_failed, report.n_pending = (plan.count(s) for s in (FINISHED, FAILED, PENDING))
    report.wall_s = time.perf_counter() - t0
    return report


def _run_local(spec, work: Iterator[Batch], n_workers, record: OnOutcome, errors: list[str]) -> bool:
    """Keep one batch per worker in flight (nothing queued behind them, so Ctrl-C stops promptly)."""
    import multiprocessing
    from concurrent.futures.process import BrokenProcessPool

    n = max(1, n_workers)
    ex = ProcessPoolExecutor(max_workers=n, mp_context=multiprocessing.get_context("spawn"),
                             initializer=init_worker, initargs=(spec, os.getpid()))
    in_flight: dict = {}
    nxt = [next(work, None)]

    def submit_next() -> None:
        if nxt[0] is not None:
            try:
                in_flight[ex.submit(run_batch, nxt[0])] = nxt[0]
                nxt[0] = next(work, None)
            except BrokenProcessPool as exc:
                errors.append(f"worker pool broken ({exc}); the points not run are left pending")
                nxt[0] = None

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


def _run_dask(spec, work: Iterator[Batch], scheduler, n_workers, processes, record: OnOutcome,
              errors: list[str]) -> bool:
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
    else:
        with one_thread_environment():  # inherited by the worker processes spawned here
            cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=processes,
                                   dashboard_address=None)
        client = Client(cluster)
    shared = client.scatter(spec, broadcast=True)  # the spec once per worker, not once per task
    by_key, futures = {}, []
    for b in work:
        futures.append(client.submit(run_batch, b, shared, pure=False))
        by_key[futures[-1].key] = b
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
              shard: Shard | None = None, **options) -> SweepReport:
    """Prepare, execute and (when no point of the sweep is left pending) write SWEEP_DIR/sweep.nc.

    ``shard`` runs one slice of the points (``flexmm.sweep.shard``); the shard that finds the
    whole sweep done writes sweep.nc. ``options`` go to ``execute`` (workers, batch_size,
    scheduler, local_dask, dask_processes, checkpoint_s, on_outcome).
    """
    from flexmm.sweep.shard import sweep_lock

    root = Path(sweep_dir).expanduser()
    with sweep_lock(root, shard):  # one sweep per directory, or distinct shards of it
        plan = prepare(spec, root, retry_failed=retry_failed, shard=shard)
        report = execute(plan, **options)
        if not report.interrupted and report.n_pending == 0:
            report.result_path = combine_if_done(plan)
    return report


def combine_if_done(plan: SweepPlan) -> Path | None:
    """Write SWEEP_DIR/sweep.nc if no point of the whole sweep is pending (other shards may
    still be running: the last one to finish writes it); its path, or None."""
    from flexmm.sweep.combine import write_combined

    with store_lock(plan.store.root):
        plan.status = plan.store.status()
        if plan.count(PENDING, everywhere=True):
            return None
        return write_combined(plan)


def reanalyse(plan: SweepPlan, on_outcome: OnOutcome | None = None) -> int:
    """Measure every finished point that kept its dataset again (after the analysis changed);
    returns how many. Only the store's observables are rewritten; no point is re-run."""
    from flexmm.sweep.worker import measure

    n = 0
    plan.status = plan.store.status() if plan.store.exists() else plan.status
    observables = plan.store.read()["observables"] if plan.store.exists() else None
    for i in np.flatnonzero(plan.status == CODE[FINISHED]):
        if not plan.spec.keeps(int(i), observables[i]):
            continue
        d = plan.store.point_dir(plan.spec.point_at(int(i)).hash)
        values, labels, note = measure(d / "dataset.nc", plan.spec.analysis)
        plan.store.write_point(int(i), FINISHED, values, note, labels)
        n += 1
        if on_outcome:
            on_outcome({"index": int(i), "status": FINISHED, "params": plan.spec.params_at(int(i))})
    return n
