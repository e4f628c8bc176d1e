"""What a worker (local process or Dask worker) does: run a batch of points, one by one.

A batch is a list of point numbers; the worker builds and validates each point from the sweep
spec it holds (``SweepSpec.point_at``: the spec is sent once per worker process, and the base
with its fixed overrides is computed once per process), runs it, measures it and publishes its
observables and status into the sweep's store (``flexmm.sweep.store``). A point whose values are
invalid, or whose run fails, is recorded as failed with the reason. Points that the spec keeps
(``keep:``) are run into their sharded run directory; the others into a scratch directory of the
worker that is emptied after they are measured.

Kept import-light at module level so a freshly spawned process can pin numba and BLAS to
one thread (``init_worker``) before numpy or numba are loaded.
"""

from __future__ import annotations

import os
import shutil
import signal
import sys
import tempfile
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

INTERRUPTED = "interrupted"
#: outcomes of a point another worker held (``flexmm.sweep.lease``): still running there when this
#: batch was stopped (BUSY), or stored by that worker (ELSEWHERE); neither is run here
BUSY, ELSEWHERE = "busy", "elsewhere"
ONE_THREAD = ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
FINISHED, FAILED = "finished", "failed"

#: the spec of the sweep this process works for (set by ``init_worker`` in a local pool)
_SPEC = None


#: wall time between a point's checkpoints unless told (``flexmm sweep --checkpoint-s``)
CHECKPOINT_S = 60.0


@dataclass(frozen=True)
class Batch:
    """Points to compute (their numbers in the sweep), the sweep directory they go to, and the wall
    time between their checkpoints (``math.inf``: only when a signal stops them)."""

    indices: tuple[int, ...]
    root: str
    checkpoint_s: float = CHECKPOINT_S
    retry_failed: bool = False  # a point found failed is run again (else only pending ones are)

    def __len__(self) -> int:
        return len(self.indices)


def init_worker(spec=None, parent: int | None = None) -> None:
    """Process initialiser: the sweep's spec; one numba/BLAS thread; Ctrl-C is only honoured
    inside a batch; the worker dies with the sweep ``parent`` (its pid) that spawned it
    (``die_with_parent``)."""
    global _SPEC
    _SPEC = spec
    pin_threads()
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    die_with_parent(os.getppid() if parent is None else parent)


def die_with_parent(parent: int, poll_s: float = 1.0) -> None:
    """End this process when its parent ``parent`` does (a ``kill -9`` of the sweep must not
    leave workers running and writing points): the kernel's parent-death signal on Linux, and a
    watchdog thread that notices being re-parented, everywhere. ``parent`` comes from the sweep
    itself: a worker whose sweep died while it was still starting (a spawned interpreter takes a
    second or more) is re-parented already, and its own ``getppid`` would name the new parent."""
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGKILL, 0, 0, 0)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass

    def watch() -> None:
        while True:
            time.sleep(poll_s)
            if os.getppid() != parent:
                os._exit(1)

    if os.getppid() != parent:  # the parent died before the signal was armed
        os._exit(1)
    threading.Thread(target=watch, name="flexmm-parent-watch", daemon=True).start()


def pin_threads() -> None:
    """Set NUMBA_NUM_THREADS=1 (and BLAS/OpenMP) for this process.

    A spawned process may already have imported numba (multiprocessing re-imports the parent's
    main script, e.g. the ``flexmm`` entry point); while its thread pool has not started,
    re-reading the environment still takes effect. If the pool already runs with another size,
    the environment is left as it was and ``_one_thread`` masks the pool per batch instead.
    """
    previous = {name: os.environ.get(name) for name in ONE_THREAD}
    for name in ONE_THREAD:
        os.environ[name] = "1"
    if "numba" not in sys.modules:
        return
    from numba.core import config

    try:
        config.reload_config()
    except RuntimeError:
        for name, value in previous.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value
        config.reload_config()


def _one_thread() -> None:
    """Limit numba's parallel kernels to one thread on workers started without init_worker (Dask)."""
    from numba.core import config

    if config.NUMBA_NUM_THREADS > 1:
        import numba

        numba.set_num_threads(1)


def run_batch(batch: Batch, spec=None) -> list[dict]:
    """Run points in order; stop at the first interruption. Returns one outcome per point tried.

    A point leased by another live worker (``flexmm.sweep.lease``) is left until the batch's other
    points are done, then waited for: stored there (ELSEWHERE) or pending again (run here)."""
    from flexmm.sweep.lease import Lease
    from flexmm.sweep.store import SweepStore

    spec = spec if spec is not None else _SPEC
    main = threading.current_thread() is threading.main_thread()
    old = signal.signal(signal.SIGINT, signal.default_int_handler) if main else None
    outcomes: list[dict] = []
    busy: dict[int, dict] = {}
    store = SweepStore(batch.root)
    scratch = Path(tempfile.mkdtemp(prefix="flexmm-point-", dir=_scratch_root()))
    try:
        _one_thread()
        todo = list(batch.indices)
        while todo:
            i = todo.pop(0)
            if i in busy:  # its other points are done: wait for the worker that holds it
                Lease(store.dir, i).wait()
            o = run_point(spec, i, store, scratch, batch.checkpoint_s, batch.retry_failed)
            if o["status"] == BUSY:
                busy[i] = o
                todo.append(i)
                continue
            busy.pop(i, None)
            outcomes.append(o)
            if o["status"] == INTERRUPTED:
                break
    except KeyboardInterrupt:
        pass
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
        if main:
            signal.signal(signal.SIGINT, old)
    return outcomes + list(busy.values())


def _scratch_root() -> str | None:
    """Memory-backed /dev/shm for the runs of points that are not kept, if there is one."""
    shm = Path("/dev/shm")
    return str(shm) if shm.is_dir() and os.access(shm, os.W_OK) else None


def run_point(spec, index: int, store, scratch: Path, checkpoint_s: float = CHECKPOINT_S,
              retry_failed: bool = False) -> dict:
    """Validate, integrate and measure point ``index``; publish it in the store (status last).

    The point's lease is taken first (``flexmm.sweep.lease``): held by another live worker, the
    point is not touched (BUSY); once taken, a point that another worker has stored meanwhile
    (finished, or failed without ``retry_failed``) is not run again (ELSEWHERE); and the point is
    published only if the lease is still this worker's (ELSEWHERE if it was taken over).

    The point's run writes checkpoints every ``checkpoint_s`` of wall time and when a signal stops
    it (a kept point's into its run directory's work directory, ``flexmm run``'s; another's into
    ``store.work_dir(index)``, its frames beside them), and continues from the newest one left by
    an earlier attempt that was interrupted or killed (``_run``). Ctrl-C at any moment before the
    status byte is written leaves the point pending (a kept point's partial run goes to
    ``<dir>.interrupted``); the store write itself runs with SIGINT blocked, so it is all or
    nothing; the point's checkpoints are removed after it.
    """
    from flexmm.sweep.lease import Lease

    t0 = time.perf_counter()
    outcome = {"index": index, "params": _plain_params(spec.params_at(index)), "pid": os.getpid()}
    lease = Lease(store.dir, index)
    try:
        holder = lease.acquire()
        if holder is not None:
            return {**outcome, "status": BUSY, "reason": f"being run by {holder} (lease {lease.path})"}
        state = store.state(index)
        if state == FINISHED or (state == FAILED and not retry_failed):
            return {**outcome, "status": ELSEWHERE, "reason": f"{state} by another worker"}
        info, values, labels = _compute(spec, index, store, scratch, outcome, checkpoint_s)
        info["wall_s"] = time.perf_counter() - t0
        if info["status"] != INTERRUPTED:
            with _sigint_blocked():
                if not lease.held():
                    return {**outcome, "status": ELSEWHERE,
                            "reason": f"its lease {lease.path} was taken over (no heartbeat for {lease.ttl_s:g} s)"}
                store.write_point(index, info["status"], values, info.get("reason") or "", labels)
            shutil.rmtree(store.work_dir(index), ignore_errors=True)
    except KeyboardInterrupt:
        return {**outcome, "status": INTERRUPTED, "reason": "interrupted"}
    finally:
        lease.release()
        for p in scratch.iterdir():
            shutil.rmtree(p, ignore_errors=True) if p.is_dir() else p.unlink(missing_ok=True)
    return info


def _plain_params(params: dict) -> dict:
    return {k: (v.item() if hasattr(v, "item") else v) for k, v in params.items()}


def _compute(spec, index: int, store, scratch: Path, outcome: dict, checkpoint_s: float = CHECKPOINT_S):
    """(what the outcome records, observables row or None, labels) of one point."""
    from flexmm.config.loader import ConfigError

    try:
        point = spec.point_at(index)
    except ConfigError as exc:
        return {**outcome, "status": FAILED, "reason": f"invalid point: {exc}"}, None, ("", "", "")
    keep = spec.keeps(index)
    d = store.point_dir(point.hash) if keep else scratch / "run"
    try:
        result, notes = _run(point, keep, d, store.work_dir(index), checkpoint_s)
    except Exception as exc:  # noqa: BLE001 - any error of a point is recorded, not raised
        return {**outcome, "status": FAILED, "reason": f"{type(exc).__name__}: {exc}"}, None, ("", "", "")
    outcome = {**outcome, **notes}
    if result.status == INTERRUPTED:
        return {**outcome, "status": INTERRUPTED, "reason": result.reason}, None, ("", "", "")
    info = {**outcome, "status": result.status, "reason": result.reason, "n_steps": result.n_steps,
            "dt_s": result.dt_s, "compile_s": result.compile_s, "run_wall_s": result.wall_s,
            "numba_threads": _numba_threads(), "kept": keep}
    if result.status != FINISHED:
        return {**info, "status": FAILED}, None, ("", "", "")
    values, labels, note = measure(result.path if result.dataset is None else result.dataset, spec.analysis)
    if not keep and spec.keeps(index, values):  # keep: where <condition>, met
        info["kept"] = _keep_run(point, store.point_dir(point.hash))
    return {**info, "reason": note}, values, labels


def _run(point, keep: bool, run_dir: Path, work: Path, checkpoint_s: float):
    """Run a point, or continue it from the checkpoint an earlier attempt left: (RunResult, notes
    for the outcome: ``resumed`` — where it went on from — or ``restarted`` — why a checkpoint
    found was not used: damaged, of other code; the point then runs from the start).

    A kept point runs like ``flexmm run`` into its directory (``api.run_scene`` with checkpoints;
    ``api.continue_run``); its end checkpoint is dropped (a sweep never extends a point). Any other
    point runs in memory, its checkpoints and their frames in ``work`` (``api.continue_point``)."""
    from flexmm import checkpoint as ck
    from flexmm.api import continue_point, continue_run, run_scene

    notes: dict = {}
    if keep:
        if any(run_dir.parent.glob(f".{run_dir.name}.work.*")) or run_dir.with_name(f"{run_dir.name}.interrupted").is_dir():
            try:
                result = continue_run(run_dir, point.scene, checkpoint_s=checkpoint_s)
                notes["resumed"] = _resumed_at(result)
            except ck.CheckpointError as exc:
                notes["restarted"] = str(exc)
                result = None
        else:
            result = None
        if result is None:
            result = run_scene(point.scene, run_dir=run_dir, atomic=True, checkpoint_s=checkpoint_s)
        if result.path is not None:
            (result.path.parent / ck.NAME).unlink(missing_ok=True)
        return result, notes
    if work.is_dir():
        try:
            found, _refused = ck.best([work])
            result = continue_point(found, point.scene, run_dir, checkpoint_dir=work, checkpoint_s=checkpoint_s)
            return result, {"resumed": _resumed_at(result)}
        except ck.CheckpointError as exc:  # nothing valid to continue from: the point runs from the start
            notes["restarted"] = str(exc)
        shutil.rmtree(work, ignore_errors=True)
    return run_scene(point.scene, run_dir=run_dir, atomic=False, in_memory=True, checkpoint_s=checkpoint_s,
                     checkpoint_dir=work), notes  # the dataset is measured and dropped: no file


def _resumed_at(result) -> str:
    """The 'resumed at t = ...' line of a continued run's log ('' if it continued nothing)."""
    return next((line for line in reversed(result.log) if line.startswith("resumed at t = ")), "")


def _keep_run(point, run_dir: Path) -> bool:
    """Run a point whose observables met ``keep: where ...`` again, into its run directory (its
    run is deterministic: the same dataset ``keep: all`` would have kept). False if that run
    did not finish (the point's observables stand; it has no directory)."""
    from flexmm.api import run_scene

    try:
        return run_scene(point.scene, run_dir=run_dir, atomic=True).status == FINISHED
    except Exception:  # noqa: BLE001 - the point was measured; only its copy is missing
        return False


def measure(path, options) -> tuple[list[float], tuple[str, str, str], str]:
    """(observables in ``OBSERVABLES`` order, (kind, field, amplitude units), note) of a run
    (its directory, dataset file, or dataset in memory)."""
    from flexmm.sweep.observe import OBSERVABLES, observe_run

    try:
        obs = observe_run(path, options)
    except Exception as exc:  # noqa: BLE001 - the run finished; the note says why it was not measured
        obs = {"note": f"analysis error: {type(exc).__name__}: {exc}"}
    values = [float(obs.get(k, float("nan"))) for k in OBSERVABLES]
    return values, tuple(str(obs.get(k, "") or "") for k in ("kind", "field", "amplitude_units")), obs.get("note", "")


@contextmanager
def _sigint_blocked():
    """Defer SIGINT (main thread of a process only) until the block ends."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


def _numba_threads() -> int:
    import numba

    return int(numba.get_num_threads())


__all__ = ["Batch", "init_worker", "measure", "run_batch", "run_point"]
