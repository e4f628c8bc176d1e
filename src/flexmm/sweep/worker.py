"""What a worker (local process or Dask worker) does: run a batch of points, one by one.

Kept import-light at module level so a freshly spawned process can pin numba and BLAS to
one thread (``init_worker``) before numpy or numba are loaded.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
import traceback
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

from flexmm.sweep.store import DATASET, DONE, ERROR, FAILED, FINISHED, POINT, clean_point, write_json_atomic

INTERRUPTED = "interrupted"
ONE_THREAD = ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


@dataclass(frozen=True)
class Task:
    """One point to compute: the resolved config (plain data), its hash and its directory."""

    config_hash: str
    config: dict
    directory: str
    params: dict
    analysis: dict = field(default_factory=dict)


def init_worker() -> None:
    """Process initialiser: one numba/BLAS thread; Ctrl-C is only honoured inside a batch; the
    worker dies with the sweep that spawned it (``die_with_parent``)."""
    pin_threads()
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    die_with_parent()


def die_with_parent(poll_s: float = 1.0) -> None:
    """End this process when its parent does (a ``kill -9`` of the sweep must not leave workers
    running and writing points): the kernel's parent-death signal on Linux, and a watchdog
    thread that notices being re-parented, everywhere."""
    parent = os.getppid()
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


def run_batch(tasks: list[Task]) -> list[dict]:
    """Run points in order; stop at the first interruption. Returns one outcome per point tried."""
    main = threading.current_thread() is threading.main_thread()
    old = signal.signal(signal.SIGINT, signal.default_int_handler) if main else None
    outcomes = []
    try:
        _one_thread()
        for task in tasks:
            outcomes.append(run_point(task))
            if outcomes[-1]["status"] == INTERRUPTED:
                break
    except KeyboardInterrupt:
        pass
    finally:
        if main:
            signal.signal(signal.SIGINT, old)
    return outcomes


def run_point(task: Task) -> dict:
    """Integrate one point, analyse it, and publish done.json (or error.json) last.

    Ctrl-C at any moment before the marker is published removes the point's files (it is
    pending again); the marker itself is written with SIGINT blocked, so it is all or nothing.
    """
    d = Path(task.directory)
    d.mkdir(parents=True, exist_ok=True)
    clean_point(d)
    t0 = time.perf_counter()
    outcome = {"config_sha256": task.config_hash, "params": task.params, "pid": os.getpid()}
    published = None
    try:
        write_json_atomic(d / POINT, {"config_sha256": task.config_hash, "params": task.params})
        marker, info = _compute(task, d, outcome)
        info["wall_s"] = time.perf_counter() - t0
        with _sigint_blocked():
            if marker is not None:
                (d / (ERROR if marker == DONE else DONE)).unlink(missing_ok=True)  # never both
                write_json_atomic(d / marker, info)
            published = info
    except KeyboardInterrupt:
        if published is not None and published["status"] != INTERRUPTED:  # delivered after publishing
            return published
        with _sigint_blocked():
            clean_point(d)
        return {**outcome, "status": INTERRUPTED, "reason": "interrupted"}
    if marker is None:
        with _sigint_blocked():
            clean_point(d)
    return info


def _compute(task: Task, d: Path, outcome: dict) -> tuple[str | None, dict]:
    """Run and analyse; (marker to publish or None if interrupted, what it records)."""
    try:
        result = _run(task, d)
    except Exception as exc:  # noqa: BLE001 - any error of a point is recorded, not raised
        return ERROR, {**outcome, "status": FAILED, "reason": f"{type(exc).__name__}: {exc}",
                       "traceback": traceback.format_exc()}
    if result.status == INTERRUPTED:
        return None, {**outcome, "status": INTERRUPTED, "reason": result.reason}
    info = {**outcome, "status": result.status, "reason": result.reason, "n_steps": result.n_steps,
            "dt_s": result.dt_s, "compile_s": result.compile_s, "run_wall_s": result.wall_s,
            "numba_threads": _numba_threads()}
    if result.status != FINISHED:
        return ERROR, info
    info["observables"] = _observe(d / DATASET, task.analysis)
    info["finished_at"] = time.strftime("%Y-%m-%dT%H:%M:%S%z")
    return DONE, info


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


def _run(task: Task, d: Path):
    from flexmm.api import run_scene
    from flexmm.config import scene_from_dict
    from flexmm.io.provenance import config_hash

    scene = scene_from_dict(task.config, source=f"sweep point {task.config_hash[:12]}")
    if config_hash(scene) != task.config_hash:
        raise RuntimeError("config hash changed on the worker (flexmm versions differ?)")
    return run_scene(scene, run_dir=d, atomic=False)  # the point's markers publish it (module docstring)


def _observe(path: Path, options: dict) -> dict:
    from flexmm.sweep.observe import observe_run

    try:
        return observe_run(path, options)
    except Exception as exc:  # noqa: BLE001 - the run finished; the analysis note says why not measured
        return {"note": f"analysis error: {type(exc).__name__}: {exc}"}


__all__ = ["Task", "init_worker", "run_batch", "run_point", "DONE", "ERROR"]
