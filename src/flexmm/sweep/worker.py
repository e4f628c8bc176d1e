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
ONE_THREAD = ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
FINISHED, FAILED = "finished", "failed"

#: the spec of the sweep this process works for (set by ``init_worker`` in a local pool)
_SPEC = None


@dataclass(frozen=True)
class Batch:
    """Points to compute (their numbers in the sweep) and the sweep directory they go to."""

    indices: tuple[int, ...]
    root: str

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
    """Run points in order; stop at the first interruption. Returns one outcome per point tried."""
    from flexmm.sweep.store import SweepStore

    spec = spec if spec is not None else _SPEC
    main = threading.current_thread() is threading.main_thread()
    old = signal.signal(signal.SIGINT, signal.default_int_handler) if main else None
    outcomes = []
    store = SweepStore(batch.root)
    scratch = Path(tempfile.mkdtemp(prefix="flexmm-point-", dir=_scratch_root()))
    try:
        _one_thread()
        for i in batch.indices:
            outcomes.append(run_point(spec, i, store, scratch))
            if outcomes[-1]["status"] == INTERRUPTED:
                break
    except KeyboardInterrupt:
        pass
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
        if main:
            signal.signal(signal.SIGINT, old)
    return outcomes


def _scratch_root() -> str | None:
    """Memory-backed /dev/shm for the runs of points that are not kept, if there is one."""
    shm = Path("/dev/shm")
    return str(shm) if shm.is_dir() and os.access(shm, os.W_OK) else None


def run_point(spec, index: int, store, scratch: Path) -> dict:
    """Validate, integrate and measure point ``index``; publish it in the store (status last).

    Ctrl-C at any moment before the status byte is written leaves the point pending (a kept
    point's partial run goes to ``<dir>.interrupted``); the store write itself runs with SIGINT
    blocked, so it is all or nothing.
    """
    t0 = time.perf_counter()
    outcome = {"index": index, "params": _plain_params(spec.params_at(index)), "pid": os.getpid()}
    try:
        info, values, labels = _compute(spec, index, store, scratch, outcome)
        info["wall_s"] = time.perf_counter() - t0
        if info["status"] != INTERRUPTED:
            with _sigint_blocked():
                store.write_point(index, info["status"], values, info.get("reason") or "", labels)
    except KeyboardInterrupt:
        return {**outcome, "status": INTERRUPTED, "reason": "interrupted"}
    finally:
        for p in scratch.iterdir():
            shutil.rmtree(p, ignore_errors=True) if p.is_dir() else p.unlink(missing_ok=True)
    return info


def _plain_params(params: dict) -> dict:
    return {k: (v.item() if hasattr(v, "item") else v) for k, v in params.items()}


def _compute(spec, index: int, store, scratch: Path, outcome: dict):
    """(what the outcome records, observables row or None, labels) of one point."""
    from flexmm.config.loader import ConfigError

    try:
        point = spec.point_at(index)
    except ConfigError as exc:
        return {**outcome, "status": FAILED, "reason": f"invalid point: {exc}"}, None, ("", "", "")
    keep = spec.keeps(index)
    d = store.point_dir(point.hash) if keep else scratch / "run"
    try:
        from flexmm.api import run_scene

        result = run_scene(point.scene, run_dir=d, atomic=keep, in_memory=not keep)  # dropped: no file
    except Exception as exc:  # noqa: BLE001 - any error of a point is recorded, not raised
        return {**outcome, "status": FAILED, "reason": f"{type(exc).__name__}: {exc}"}, None, ("", "", "")
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
