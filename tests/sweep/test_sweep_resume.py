"""Sweep points go on from their checkpoints: after Ctrl-C, after a SIGKILL of the sweep, after a
SIGKILL of a Dask worker in the middle of a point. Real processes throughout (the sweep's own
worker pool; a ``dask scheduler`` and ``dask worker`` started here), and every point ends
bit-identical to the same sweep never stopped: the store's observables (points kept in memory,
their frames written beside their checkpoints) or every variable of the kept datasets.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import default_sigint

from flexmm import checkpoint as ck
from flexmm.io.run_dataset import open_run
from flexmm.sweep import load_sweep
from flexmm.sweep.store import SweepStore

REPO = Path(__file__).resolve().parents[2]
LEGO = REPO / "configs" / "lego_vector_soliton.yaml"
#: four points of 40 000 verlet steps on 3000 units (about a second each on one core), no pilots
SPEC = f"""\
name: long_points
base: {LEGO}
set:
  lattice.n_units: 3000
  solver.duration_s: 1.0
  solver.accuracy: null
  solver.integrator: velocity_verlet
  solver.dt_s: 2.5e-5
  output.n_frames: 41
keep: {{keep}}
vary:
  grid:
    excitation.velocity_m_s: [2.0, 2.5, 3.0, 3.5]
"""
ONE_THREAD = {name: "1" for name in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")}
CLI = "from flexmm.cli import main; main()"


def spec_file(where: Path, keep: str) -> Path:
    where.mkdir(parents=True, exist_ok=True)
    path = where / f"long_points_{keep}.yaml"
    path.write_text(SPEC.format(keep=keep))
    return path


def sweep(*args, **popen) -> subprocess.Popen:
    """`flexmm sweep ...` in its own process group (a signal to the group reaches its workers, like Ctrl-C)."""
    return subprocess.Popen([sys.executable, "-c", CLI, "sweep", *map(str, args)], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, start_new_session=True, preexec_fn=default_sigint,
                            **popen)


def wait_for(predicate, proc: subprocess.Popen, what: str, timeout: float = 300.0):
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        found = predicate()
        if found:
            return found
        assert proc.poll() is None, f"ended before {what}: {proc.communicate()[0][-3000:]}"
        time.sleep(0.02)
    raise AssertionError(f"timed out waiting for {what}")


def running_checkpoints(sweep_dir: Path) -> list[Path]:
    """Checkpoints of points kept in memory while they run (SWEEP_DIR/work/<point>/)."""
    return sorted((sweep_dir / "work").glob(f"*/{ck.NAME}"))


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> Path:
    """The sweep never stopped, its points kept (their datasets and the observables)."""
    root = tmp_path_factory.mktemp("reference")
    proc = sweep(spec_file(root, "all"), "--out", root / "sweep", "-j", "2")
    out, _ = proc.communicate(timeout=900)
    assert proc.returncode == 0, out
    return root / "sweep"


def same_observables(a: Path, b: Path) -> None:
    sa, sb = SweepStore(a).read(), SweepStore(b).read()
    assert np.all(sa["status"] == 1) and np.all(sb["status"] == 1)
    assert np.array_equal(sa["observables"], sb["observables"], equal_nan=True), "not bit-identical"
    assert np.isfinite(sa["observables"][:, 0]).all()  # every point measured a speed


@pytest.mark.slow  # the default suite keeps the Dask worker kill below (a point resumed mid-way)
def test_an_interrupted_sweep_goes_on_from_its_points_checkpoints(tmp_path, reference) -> None:
    d = tmp_path / "sweep"
    proc = sweep(spec_file(tmp_path, "none"), "--out", d, "-j", "2", "--batch-size", "1", "--checkpoint-s", "0.2")
    wait_for(lambda: running_checkpoints(d), proc, "a point's first checkpoint")
    time.sleep(0.3)
    os.killpg(proc.pid, signal.SIGINT)
    out, _ = proc.communicate(timeout=300)
    assert proc.returncode == 130, out
    assert "Traceback" not in out
    stopped = running_checkpoints(d)
    assert stopped, "Ctrl-C left no checkpoint of a running point"
    at = {p.parent.name: ck.read(p).meta["t_s"] for p in stopped}
    assert all(t > 0 for t in at.values())
    again = sweep(spec_file(tmp_path, "none"), "--out", d, "-j", "2", "--checkpoint-s", "0.2")
    out, _ = again.communicate(timeout=600)
    assert again.returncode == 0, out
    resumed = re.findall(r"resumed at t = ([0-9.e+-]+) s .* from (\S+)/checkpoint\.ckpt", out)
    assert {Path(w).name for _, w in resumed} == set(at), out  # each stopped point went on from where it stopped
    same_observables(reference, d)
    assert not (d / "work").exists() or not any((d / "work").iterdir())  # checkpoints removed once stored


@pytest.mark.slow  # as above; tests/sweep/test_sweep_interrupt.py kills the driver in the default suite
def test_a_killed_sweep_goes_on_from_its_last_checkpoints(tmp_path, reference) -> None:
    d = tmp_path / "sweep"
    proc = sweep(spec_file(tmp_path, "none"), "--out", d, "-j", "2", "--batch-size", "1", "--checkpoint-s", "0.2")
    wait_for(lambda: running_checkpoints(d), proc, "a point's first checkpoint")
    time.sleep(0.5)
    os.kill(proc.pid, signal.SIGKILL)  # the driver only: its workers die with it (parent-death signal)
    proc.communicate(timeout=60)
    assert running_checkpoints(d)
    again = sweep(spec_file(tmp_path, "none"), "--out", d, "-j", "2", "--checkpoint-s", "0.2")
    out, _ = again.communicate(timeout=600)
    assert again.returncode == 0, out
    assert "resumed at t = " in out, out
    same_observables(reference, d)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def dask_cluster(tmp_path):
    """A real ``dask scheduler`` and ``dask worker`` (two worker processes under a nanny, one thread
    each) on localhost; yields the scheduler's address."""
    pytest.importorskip("distributed")
    dask = shutil.which("dask", path=str(Path(sys.executable).parent))
    if dask is None:
        pytest.skip("the dask command line is not installed")
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    env = {**os.environ, **ONE_THREAD}
    logs = tmp_path / "dask-logs"
    logs.mkdir()
    procs = [subprocess.Popen([dask, "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
                              stdout=subprocess.DEVNULL, stderr=open(logs / "scheduler.log", "w"), env=env,
                              start_new_session=True)]
    procs.append(subprocess.Popen([dask, "worker", address, "--nworkers", "2", "--nthreads", "1", "--no-dashboard",
                                   "--local-directory", str(tmp_path / "dask-space")],
                                  stdout=subprocess.DEVNULL, stderr=open(logs / "workers.log", "w"), env=env,
                                  start_new_session=True))
    try:
        from distributed import Client

        with Client(address, timeout="60s") as client:
            client.wait_for_workers(2, timeout=120)
        yield address
    finally:
        for p in procs[::-1]:
            os.killpg(p.pid, signal.SIGTERM)
        for p in procs[::-1]:
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait()


def test_a_dask_worker_killed_mid_point_loses_only_the_time_since_its_checkpoint(tmp_path, reference,
                                                                                 dask_cluster) -> None:
    d = tmp_path / "sweep"
    spec = spec_file(tmp_path, "all")
    proc = sweep(spec, "--out", d, "--scheduler", dask_cluster, "--batch-size", "1", "--checkpoint-s", "0.2")

    def a_running_point_with_a_checkpoint() -> list[Path]:  # a kept point runs in .<hash>.work.<pid>
        return [w for w in (d / "points").glob("*/.*.work.*") if (w / ck.NAME).is_file()]

    work = wait_for(a_running_point_with_a_checkpoint, proc, "a point's first checkpoint")[0]
    time.sleep(0.3)
    pid = int(work.name.rsplit(".", 1)[1])
    os.kill(pid, signal.SIGKILL)  # the worker process running the point; its nanny starts another
    killed_hash = work.name[1:].split(".work.")[0]
    out, _ = proc.communicate(timeout=900)
    assert proc.returncode == 0, out  # the same sweep finishes: the batch is run again by a worker
    assert "Traceback" not in out
    went_on = open_run(d / "points" / killed_hash[:2] / killed_hash)
    assert went_on.attrs["n_resumptions"] == 1 and "resumed at t = " in went_on.attrs["resumed"], out
    for p in load_sweep(spec).points():  # every point: every variable the same bits as never stopped
        a = open_run(SweepStore(reference).point_dir(p.hash))
        b = open_run(SweepStore(d).point_dir(p.hash))
        differ = [k for k in a.variables if not np.array_equal(a[k].values, b[k].values)]
        assert set(a.variables) == set(b.variables) and differ == [], (p.index, differ)
        assert a.attrs["n_steps"] == b.attrs["n_steps"]
        assert not (SweepStore(d).point_dir(p.hash) / ck.NAME).exists()  # a kept point: dataset, config, log
    same_observables(reference, d)
    assert not list((d / "points").glob("*/.*.work.*"))
