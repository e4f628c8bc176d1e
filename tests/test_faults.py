"""Runs and sweeps under faults: nothing finished is lost, nothing partial looks finished.

Real processes (the console script) receive real signals: SIGINT and SIGTERM during a rerun of
a finished scene, SIGKILL mid-run, a second run into the same directory, a sweep whose parent
is killed, two sweeps on one directory, a disk that fills up (ENOSPC injected into the writer),
runs beyond the resource limits, and `flexmm analyze` on partial runs.
"""

from __future__ import annotations

import errno
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import DEMO_AS_LEGO_SCENE_SETS, default_sigint

from flexmm.io.run_dataset import open_run

ROOT = Path(__file__).resolve().parents[1]
DEMO = ROOT / "configs" / "lego_vector_soliton.yaml"
FLEXMM = str(Path(sys.executable).with_name("flexmm"))
#: the demo's impact on its 200-unit chain with a free end (the sweeps here run whole points)
SMALL_DEMO = ["--set", "lattice.n_units=200", "--set", "damping.absorbing=null"]
SHORT = ["--set", "solver.duration_s=0.02", "--set", "output.n_frames=11", "--fidelity", "full"]
# fault handling during the time loop: no accuracy pilots before it (they would delay the stepping)
LONG = ["--set", "solver.duration_s=200", "--set", "output.n_frames=2001", "--fidelity", "full",
        "--set", "solver.accuracy=null", "--checkpoint-s", "0.5"]


def flexmm(*args, **kw) -> subprocess.CompletedProcess:
    return subprocess.run([FLEXMM, *map(str, args)], capture_output=True, text=True, timeout=300, **kw)


def start(*args) -> subprocess.Popen:
    return subprocess.Popen([FLEXMM, *map(str, args)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=default_sigint)


def wait_until_stepping(out: Path, proc: subprocess.Popen, timeout: float = 300.0) -> None:
    """Until the run has written a checkpoint (``LONG`` checkpoints every 0.5 s): it is in its time
    loop with frames written, whatever compiling took on a loaded machine."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        if list(out.parent.glob(f".{out.name}.work.*/checkpoint.ckpt")):
            return
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.05)
    raise AssertionError("the run never started stepping")


def leftovers(parent: Path) -> list[str]:
    return sorted(p.name for p in parent.iterdir() if ".staging." in p.name or ".work." in p.name or p.name.endswith(".tmp"))


@pytest.mark.parametrize("sig, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_signal_during_a_rerun_keeps_the_finished_result(tmp_path, sig, code) -> None:
    out = tmp_path / "demo"
    assert flexmm("run", DEMO, "--out", out, "-q", *SHORT).returncode == 0
    before = open_run(out)
    assert before.attrs["status"] == "finished"
    proc = start("run", DEMO, "--out", out, *LONG)
    wait_until_stepping(out, proc)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == code, err
    after = open_run(out)  # the finished result, untouched
    assert after.attrs["status"] == "finished" and after.sizes == before.sizes
    np.testing.assert_array_equal(after["theta"].values, before["theta"].values)
    partial = open_run(tmp_path / "demo.interrupted")
    assert partial.attrs["status"] == "interrupted" and signal.Signals(sig).name in partial.attrs["status_reason"]
    assert 1 < partial.sizes["time"] < 2001 and np.isfinite(partial["theta"].values).all()
    assert {p.name for p in (tmp_path / "demo.interrupted").iterdir()} - {"checkpoint.prev.ckpt"} == {
        "dataset.nc", "config.yaml", "run.log", "checkpoint.ckpt"}  # the checkpoint --resume continues from
    assert leftovers(tmp_path) == []
    res = flexmm("analyze", tmp_path / "demo.interrupted", "--no-save")
    assert res.returncode == 1 and "interrupted run" in res.stdout + res.stderr  # refused, not silently measured


def test_sigkill_leftovers_are_cleaned_by_the_next_run(tmp_path) -> None:
    out = tmp_path / "demo"
    proc = start("run", DEMO, "--out", out, *LONG)
    wait_until_stepping(out, proc)
    proc.kill()
    proc.wait()
    assert leftovers(tmp_path) and not out.exists()  # killed: nothing published, its work directory left behind
    assert flexmm("run", DEMO, "--out", out, "-q", *SHORT).returncode == 0
    assert leftovers(tmp_path) == [] and open_run(out).attrs["status"] == "finished"


def test_a_second_run_into_the_same_directory_is_refused(tmp_path) -> None:
    out = tmp_path / "demo"
    proc = start("run", DEMO, "--out", out, *LONG)
    try:
        wait_until_stepping(out, proc)
        res = flexmm("run", DEMO, "--out", out, *SHORT)
        assert res.returncode == 2 and "in use by another flexmm process" in res.stderr
        assert "Traceback" not in res.stderr
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.communicate(timeout=60)


def test_disk_full_stops_the_run_and_keeps_the_frames_written(tmp_path, monkeypatch) -> None:
    import flexmm.io.run_dataset as run_dataset
    from flexmm.api import run_scene
    from flexmm.config import load_scene

    flush = run_dataset.DatasetWriter.flush

    def full_after_300(self) -> None:
        if self.n_written >= 300:
            raise OSError(errno.ENOSPC, "No space left on device")
        flush(self)

    monkeypatch.setattr(run_dataset.DatasetWriter, "flush", full_after_300)
    monkeypatch.setattr(run_dataset, "BUFFER_BYTES", 8 * 400 * 2 * 100)  # flush every 100 frames
    res = run_scene(load_scene(DEMO, DEMO_AS_LEGO_SCENE_SETS), run_dir=tmp_path / "demo")  # 200 units: 400 DOFs
    assert res.status == "failed" and "No space left on device" in res.reason
    assert res.path == tmp_path / "demo.failed" / "dataset.nc" and not (tmp_path / "demo").exists()
    ds = open_run(res.path)
    assert ds.sizes["time"] == ds.attrs["n_frames_written"] == 300 and ds.attrs["status"] == "failed"
    assert np.all(np.diff(ds["time"].values) > 0)


@pytest.mark.parametrize("override, expect", [
    ("lattice.n_units=20000000", "GiB"),  # 477 GiB of output: over the limit and the free disk
    ("solver.duration_s=1e9", "steps"),  # 4e13 steps
    ("solver.dt_s=1e-15", "steps"),
])
def test_runs_beyond_the_limits_are_refused_in_a_second(tmp_path, override, expect) -> None:
    for verb in ("validate", "run"):
        t0 = time.monotonic()
        res = flexmm(verb, DEMO, "--set", override, *(["--out", tmp_path / "x"] if verb == "run" else []))
        assert res.returncode == 2 and expect in res.stderr and "Traceback" not in res.stderr, res.stderr
        assert time.monotonic() - t0 < 15  # seconds, not the minutes a full build of 2e7 units took
    assert not (tmp_path / "x").exists()


def test_limits_are_configurable_and_force_overrides_them(tmp_path) -> None:
    env = {**os.environ, "FLEXMM_MAX_STEPS": "100"}
    res = flexmm("run", DEMO, "--out", tmp_path / "x", *SHORT, env=env)
    assert res.returncode == 2 and "FLEXMM_MAX_STEPS" in res.stderr
    assert flexmm("run", DEMO, "--out", tmp_path / "x", "-q", "--force", *SHORT, env=env).returncode == 0


def _children(pid: int) -> list[int]:
    import psutil

    try:
        return [c.pid for c in psutil.Process(pid).children(recursive=True)]
    except psutil.NoSuchProcess:
        return []


def test_sweep_workers_die_with_their_parent_and_the_sweep_resumes(tmp_path) -> None:
    import psutil

    sweep = tmp_path / "sw"
    vary = ["--vary", "excitation.velocity_m_s=0.5:3:2", *SMALL_DEMO, "--set", "solver.duration_s=5"]
    proc = start("sweep", DEMO, "--out", sweep, "--workers", "1", *vary)
    t0 = time.monotonic()
    workers: list[int] = []
    while not workers and time.monotonic() - t0 < 60:
        workers = [p for p in _children(proc.pid) if (sweep / "store" / "status.npy").exists()]
        time.sleep(0.2)
    assert workers, proc.communicate()
    proc.kill()
    proc.wait()
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline and any(psutil.pid_exists(w) and psutil.Process(w).status() != "zombie"
                                              for w in workers):
        time.sleep(0.2)
    alive = [w for w in workers if psutil.pid_exists(w) and psutil.Process(w).status() != "zombie"]
    assert alive == [], "workers outlived their sweep"
    # the same sweep resumes in the killed sweep's directory: every point ends done or failed (a long
    # demo may miss its accuracy by more than 10x: failed, exit 1), none is left pending
    res = flexmm("sweep", DEMO, "--out", sweep, "--workers", "1", *vary)
    assert res.returncode in (0, 1) and "Traceback" not in res.stderr, res.stderr
    from flexmm.sweep.store import CODE, PENDING, SweepStore

    assert not (SweepStore(sweep).status() == CODE[PENDING]).any()


def test_two_sweeps_on_one_directory_do_not_mix(tmp_path) -> None:
    sweep = tmp_path / "sw"
    vary = ["--vary", "excitation.velocity_m_s=0.5:3:3", *SMALL_DEMO, "--set", "solver.duration_s=40"]
    proc = start("sweep", DEMO, "--out", sweep, "--workers", "1", *vary)
    try:
        t0 = time.monotonic()
        while not (sweep / ".sweep.lock").exists() and time.monotonic() - t0 < 60:
            time.sleep(0.1)
        time.sleep(0.5)
        res = flexmm("sweep", DEMO, "--out", sweep, "--workers", "1", *vary)
        assert res.returncode == 2 and "in use by another flexmm process" in res.stderr
    finally:
        proc.send_signal(signal.SIGINT)
        proc.communicate(timeout=120)
    for d in (sweep / "points").glob("*"):
        assert not ((d / "done.json").exists() and (d / "error.json").exists())


@pytest.mark.slow  # waits out the 10 s connection timeout
def test_unreachable_scheduler_is_a_message_within_seconds(tmp_path) -> None:
    pytest.importorskip("distributed")
    t0 = time.monotonic()
    res = flexmm("sweep", DEMO, "--out", tmp_path / "sw", "--vary", "excitation.velocity_m_s=0.5,1",
                 "--scheduler", "tcp://127.0.0.1:9")
    assert res.returncode == 2 and "cannot reach the Dask scheduler" in res.stderr, res.stderr
    assert "Traceback" not in res.stderr and time.monotonic() - t0 < 30


def _random_signal_rounds(tmp_path: Path, seed: int, rounds: int) -> None:
    import random

    rng = random.Random(seed)
    out = tmp_path / "demo"
    assert flexmm("run", DEMO, "--out", out, "-q", *SHORT).returncode == 0
    reference = open_run(out)["theta"].values
    for _ in range(rounds):
        sig = rng.choice([signal.SIGINT, signal.SIGTERM, signal.SIGKILL])
        proc = start("run", DEMO, "--out", out, *LONG)
        time.sleep(rng.uniform(0.0, 3.0))  # imports, planning, compile or the time loop
        proc.send_signal(sig)
        proc.communicate(timeout=120)
        kept = open_run(out)
        assert kept.attrs["status"] == "finished"
        np.testing.assert_array_equal(kept["theta"].values, reference)
        partial = tmp_path / "demo.interrupted"
        if partial.exists():
            assert open_run(partial).attrs["status"] == "interrupted"
    assert flexmm("run", DEMO, "--out", out, "-q", *SHORT).returncode == 0
    assert leftovers(tmp_path) == [] and not (tmp_path / "demo.failed").exists()


def test_random_signals_during_reruns_never_lose_or_fake_a_result(tmp_path) -> None:
    """SIGINT, SIGTERM or SIGKILL at a random moment of a rerun: the finished result survives bit
    for bit, a partial one is only ever under .interrupted, and the next run cleans up."""
    _random_signal_rounds(tmp_path, 0, 3)


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(1, 6))
def test_random_signals_during_reruns_many_seeds(tmp_path, seed) -> None:
    _random_signal_rounds(tmp_path, seed, 4)


@pytest.mark.parametrize("sig", [pytest.param(signal.SIGINT, marks=pytest.mark.slow), signal.SIGKILL])
def test_a_sweep_stopped_at_a_random_moment_resumes_to_a_true_summary(tmp_path, sig) -> None:
    import random

    import numpy as np

    from flexmm.sweep.store import SweepStore

    sweep = tmp_path / "sw"
    vary = ["--vary", "excitation.velocity_m_s=0.5:3:6", *SMALL_DEMO, "--set", "solver.duration_s=2", "--workers", "2",
            "--set", "solver.accuracy=null"]
    proc = start("sweep", DEMO, "--out", sweep, *vary)
    time.sleep(random.Random(int(sig)).uniform(3.0, 6.0))
    proc.send_signal(sig)
    proc.communicate(timeout=120)
    store = SweepStore(sweep)
    before = store.status() if store.exists() else np.zeros(6, np.uint8)
    done_before = np.array(store.read()["observables"]) if store.exists() else None
    res = flexmm("sweep", DEMO, "--out", sweep, *vary)
    assert res.returncode == 0, res.stderr
    assert "6 finished" in res.stderr and "0 failed" in res.stderr and (sweep / "sweep.nc").exists()
    assert (store.status() == 1).all()  # every point finished, exactly once in the store
    assert f" {int((before == 1).sum())} already done)" in res.stderr  # finished before the stop: not run again
    if done_before is not None:  # and their observables untouched
        np.testing.assert_array_equal(np.array(store.read()["observables"])[before == 1], done_before[before == 1])


def test_progress_lines_outside_a_terminal(tmp_path, monkeypatch) -> None:
    """A batch job's log shows where a run is (a line every PROGRESS_EVERY_S; 0 here: every frame)."""
    import flexmm.controller as controller
    from flexmm.api import run_scene
    from flexmm.config import load_scene

    monkeypatch.setattr(controller, "PROGRESS_EVERY_S", 0.0)
    lines: list[str] = []
    scene = load_scene(DEMO, ["solver.duration_s=0.02", "output.n_frames=5"])
    assert run_scene(scene, run_dir=tmp_path / "r", log=lines.append, progress=False).ok
    progress = [ln for ln in lines if ln.startswith("progress:")]
    assert len(progress) == 4 and "100.0 %" in progress[-1] and "steps" in progress[0]
    assert not any(ln.startswith("progress:") for ln in (tmp_path / "r" / "run.log").read_text().splitlines())


def test_a_directory_that_is_not_a_run_directory_is_never_replaced(tmp_path) -> None:
    """`--out runs` (the parent of runs) must not swap away every other run."""
    other = tmp_path / "runs" / "other_scene"
    other.mkdir(parents=True)
    (other / "dataset.nc").write_bytes(b"keep me")
    (tmp_path / "runs" / "notes.txt").write_text("mine")
    res = flexmm("run", DEMO, "--out", tmp_path / "runs", *SHORT)
    assert res.returncode == 2 and "not a flexmm run directory" in res.stderr, res.stderr
    assert (other / "dataset.nc").read_bytes() == b"keep me" and (tmp_path / "runs" / "notes.txt").exists()
