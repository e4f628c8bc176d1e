"""A sweep interrupted (Ctrl-C) and killed (SIGKILL) midway resumes: no point lost or recomputed."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import default_sigint

from flexmm.sweep import load_sweep, run_sweep
from flexmm.sweep.store import CODE, FINISHED, SweepStore, dataset_status

REPO = Path(__file__).resolve().parents[2]
LEGO = REPO / "configs" / "lego_vector_soliton.yaml"
N_POINTS = 8

SPEC = f"""\
    name: interrupt_me
    base: {LEGO}
    set:
      lattice.n_units: 60
      lattice.left: free
      damping.absorbing: null
      excitation: {{kind: soliton, amplitude_rad: 0.4, center_site: 8}}
      solver.duration_s: 0.3
      solver.dt_fraction: 0.5
      output.n_frames: 61
    keep: all
    vary:
      grid:
        excitation.amplitude_rad: {{start: 0.3, stop: 0.65, num: {N_POINTS}}}
    """


def start(spec_path: Path, sweep_dir: Path) -> subprocess.Popen:
    """`flexmm sweep` in its own process group (so a signal reaches it and its workers, like Ctrl-C)."""
    code = "from flexmm.cli import main; main()"
    cmd = [sys.executable, "-c", code, "sweep", str(spec_path), "--out", str(sweep_dir),
           "--workers", "1", "--batch-size", "1"]
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, start_new_session=True,
                            preexec_fn=default_sigint)


def finished_indices(sweep_dir: Path) -> set[int]:
    """Points whose status byte says finished (none before the store is laid out)."""
    status = SweepStore(sweep_dir).status()
    return {int(i) for i in np.flatnonzero(status == CODE[FINISHED])}


def n_done(sweep_dir: Path) -> int:
    return len(finished_indices(sweep_dir))


def kill_after(proc: subprocess.Popen, sweep_dir: Path, n: int, sig: int) -> str:
    deadline = time.monotonic() + 180
    while n_done(sweep_dir) < n:
        assert proc.poll() is None, proc.stdout.read().decode()
        assert time.monotonic() < deadline, "sweep made no progress"
        time.sleep(0.02)
    os.killpg(proc.pid, sig)
    out, _ = proc.communicate(timeout=120)
    return out.decode()


def finished_files(store: SweepStore, hashes) -> dict[str, int]:
    return {str(p): p.stat().st_mtime_ns for h in hashes for p in store.point_dir(h).iterdir()}


def check_nothing_looks_finished_but_is_not(store: SweepStore, points) -> set[str]:
    """Every point the status array calls finished has its observables in the store and its kept
    dataset with status 'finished'; returns the finished hashes."""
    done = finished_indices(store.root)
    observables = store.read()["observables"]
    for p in points:
        if p.flat in done:
            assert dataset_status(store.point_dir(p.hash) / "dataset.nc") == FINISHED
            assert np.isfinite(observables[p.flat]).any()
        else:
            assert np.isnan(observables[p.flat]).all()  # nothing half-published
    assert not store.result_path.exists()  # no combined dataset for an incomplete sweep
    return {p.hash for p in points if p.flat in done}


def test_killed_sweep_resumes_without_losing_or_recomputing_points(tmp_path):
    spec_path = tmp_path / "interrupt.yaml"
    spec_path.write_text(textwrap.dedent(SPEC))
    spec = load_sweep(spec_path)
    points = spec.points()
    d = tmp_path / "sweep"
    store = SweepStore(d)

    # 1. Ctrl-C (SIGINT to the process group) after two points: a clean stop, exit code 130
    out = kill_after(start(spec_path, d), d, 2, signal.SIGINT)
    assert "interrupted" in out, out
    first = check_nothing_looks_finished_but_is_not(store, points)
    assert 2 <= len(first) < N_POINTS
    leftovers = [p for p in d.rglob("*") if p.name.endswith(".tmp")]
    assert leftovers == []  # the interrupted point cleaned up after itself
    assert all((store.point_dir(h) / "dataset.nc").exists() == (h in first) for h in (p.hash for p in points))
    mtimes = finished_files(store, first)

    # 2. resume, then SIGKILL everything two points later: no clean-up possible
    kill_after(start(spec_path, d), d, len(first) + 2, signal.SIGKILL)
    second = check_nothing_looks_finished_but_is_not(store, points)
    assert first < second
    assert finished_files(store, first) == mtimes
    mtimes = finished_files(store, second)

    # 3. resume to the end (on an in-process Dask cluster: no worker start-up to pay for again):
    #    only the missing points run, none is recomputed
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster:
        report = run_sweep(spec, d, scheduler=cluster.scheduler_address)
    assert report.ok and report.n_cached == len(second)
    assert report.n_run == N_POINTS - len(second)
    assert finished_files(store, second) == mtimes
    assert finished_indices(d) == set(range(N_POINTS))
    assert store.result_path.exists()
    assert not [p for p in d.rglob("*") if p.name.endswith(".tmp")]


@pytest.mark.slow
def test_cli_sweep_exit_codes_and_rerun(tmp_path):
    spec_path = tmp_path / "interrupt.yaml"
    spec_path.write_text(textwrap.dedent(SPEC).replace(f"num: {N_POINTS}", "num: 2"))
    code = "from flexmm.cli import main; main()"
    cmd = [sys.executable, "-c", code, "sweep", str(spec_path), "--out", str(tmp_path / "s"), "--workers", "1"]
    first = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert first.returncode == 0, first.stderr
    assert "2 finished (2 run now, 0 already done)" in first.stderr
    again = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert again.returncode == 0 and "0 to run" in again.stderr and "(0 run now, 2 already done)" in again.stderr
