"""A run whose disk fills during a checkpoint or while it publishes, or that is killed while it
publishes, loses nothing it had: real processes, a real small filesystem, real SIGKILL.

The moment is chosen with the test hook ``FLEXMM_PAUSE_AT`` (``flexmm.io.pause``: the process
stops itself with SIGSTOP at a named point, as at a breakpoint); the test then fills the
filesystem or sends SIGKILL, and lets it go on. Nothing is injected into the writes: a write
that fails, fails on the full tmpfs. Each case ends with ``flexmm run --resume`` publishing,
bit for bit, what a run never stopped publishes.
"""

from __future__ import annotations

import hashlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from flexmm import checkpoint as ck
from flexmm.io.pause import VARIABLE
from flexmm.io.run_dataset import open_run
from conftest import assert_same_data, is_stopped, mounted_tmpfs

ROOT = Path(__file__).resolve().parents[1]
DEMO = ROOT / "configs" / "lego_vector_soliton.yaml"
FLEXMM = str(Path(sys.executable).with_name("flexmm"))
#: velocity Verlet, no pilots: a small run (the commit cases)
SMALL = ["--set", "lattice.n_units=500", "--set", "output.n_frames=21", "--set", "solver.accuracy=null",
         "--set", "solver.integrator=velocity_verlet", "--set", "solver.dt_s=2.5e-5", "--fidelity", "full"]
OLD, NEW = ["--set", "solver.duration_s=0.2"], ["--set", "solver.duration_s=0.3"]
#: a large state (10⁵ units: a 6 MiB checkpoint) with small frames (every 1000th unit saved)
BIG_STATE = ["--set", "lattice.n_units=100000", "--set", "output.site_stride=1000", "--set", "output.n_frames=21",
             "--set", "solver.duration_s=0.05", "--set", "solver.accuracy=null",
             "--set", "solver.integrator=velocity_verlet", "--set", "solver.dt_s=2.5e-5", "--fidelity", "full"]


def flexmm(*args, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([FLEXMM, *map(str, args)], capture_output=True, text=True, timeout=600,
                          env={**os.environ, **(env or {})})


def paused(pause_at: str, *args, cmd: list[str] | None = None) -> subprocess.Popen:
    """Start flexmm with ``FLEXMM_PAUSE_AT=pause_at`` and wait until it has stopped itself there."""
    proc = subprocess.Popen([*(cmd or [FLEXMM]), *map(str, args)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env={**os.environ, VARIABLE: pause_at})
    t0 = time.monotonic()
    while not is_stopped(proc.pid):
        assert proc.poll() is None, f"never reached {pause_at}: {proc.communicate()}"
        assert time.monotonic() - t0 < 300, f"never reached {pause_at}"
        time.sleep(0.02)
    return proc


def files(run_dir: Path) -> dict[str, str]:
    """Every file of a directory with the SHA-256 of its contents."""
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(run_dir.iterdir()) if p.is_file()}


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> dict[str, Path]:
    """The runs never stopped: the old and the new small run, the large-state run."""
    root = tmp_path_factory.mktemp("reference")
    out = {}
    for name, args in (("old", SMALL + OLD), ("new", SMALL + NEW), ("big", BIG_STATE)):
        res = flexmm("run", DEMO, "--out", root / name, "-q", *args)
        assert res.returncode == 0, res.stderr
        out[name] = root / name
    return out


@pytest.fixture
def small_disk(tmp_path):
    """A 40 MiB tmpfs mounted for the test (root, or skipped)."""
    with mounted_tmpfs(tmp_path / "small", "40m") as where:
        yield where


def fill(disk: Path, leave: int = 0) -> Path:
    """Fill the filesystem of ``disk`` until ``leave`` bytes are free (as near as it allows)."""
    filler = disk / "filler"
    st = os.statvfs(disk)
    size = max(0, st.f_bavail * st.f_frsize - leave)
    with open(filler, "wb") as fh:
        try:
            while size > 0:
                fh.write(bytes(min(size, 1 << 20)))
                size -= 1 << 20
            fh.flush()
        except OSError:
            pass
    return filler


def test_a_full_disk_during_a_checkpoint_stops_the_run_and_keeps_the_previous_one(small_disk, reference) -> None:
    out = small_disk / "big"
    proc = paused("checkpoint:2", "run", DEMO, "--out", out, "-q", *BIG_STATE, "--checkpoint-s", "0.01")
    work = next(small_disk.glob(".big.work.*"))
    first = ck.read(work / ck.NAME)  # the first checkpoint, complete
    filler = fill(small_disk, leave=first.path.stat().st_size // 2)  # room for half a checkpoint
    proc.send_signal(signal.SIGCONT)
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 1, err
    assert "Traceback" not in err and "No space left on device" in err, err
    assert "writing a checkpoint failed at t = " in err and f"the checkpoint of t = {first.meta['t_s']:.6g} s" in err
    failed = small_disk / "big.failed"
    kept = ck.read(failed / ck.NAME)  # the previous checkpoint, intact (its checksum verified)
    assert kept.meta["steps"] == first.meta["steps"] and not (failed / ck.PREVIOUS).exists()
    ds = open_run(failed)
    assert ds.attrs["status"] == "failed" and ds.sizes["time"] >= kept.meta["frames_written"]
    assert not any(p.name.endswith(".tmp") for p in failed.iterdir())
    filler.unlink()  # room again: the run goes on from the checkpoint kept
    res = flexmm("run", "--resume", out, "--checkpoint-s", "0.01")
    assert res.returncode == 0, res.stderr
    assert_same_data(reference["big"], out)
    assert open_run(out).attrs["n_resumptions"] == 1 and not failed.exists()


def test_a_full_disk_while_publishing_keeps_the_old_result_and_the_new_one_resumes(small_disk, reference) -> None:
    out = small_disk / "demo"
    assert flexmm("run", DEMO, "--out", out, "-q", *SMALL, *OLD).returncode == 0
    before = files(out)
    proc = paused("commit", "run", DEMO, "--out", out, "-q", *SMALL, *NEW)
    filler = fill(small_disk)  # the disk full when config.yaml and run.log are written
    proc.send_signal(signal.SIGCONT)
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 2, err
    assert "Traceback" not in err and "No space left on device" in err and "config.yaml" in err, err
    assert "the run ended (finished, t = 0.3 s) but its outputs could not be published" in err, err
    assert f"flexmm run --resume {out}" in err
    assert files(out) == before  # the old result, untouched
    filler.unlink()
    res = flexmm("run", "--resume", out)
    assert res.returncode == 0, res.stderr
    assert_same_data(reference["new"], out)
    assert not list(small_disk.glob(".demo.work.*"))


@pytest.mark.parametrize("point", ["commit", "commit:exchanged"])
def test_sigkill_while_publishing_leaves_the_old_or_the_new_run_never_a_mix(tmp_path, reference, point) -> None:
    out = tmp_path / "demo"
    assert flexmm("run", DEMO, "--out", out, "-q", *SMALL, *OLD).returncode == 0
    old = files(out)
    proc = paused(point, "run", DEMO, "--out", out, "-q", *SMALL, *NEW)
    proc.kill()
    proc.communicate()
    now = files(out)
    if point == "commit":  # before the rename: the old run, as it was
        assert now == old
    else:  # after the exchange: the new run, whole
        assert set(now) == set(old) and now["dataset.nc"] != old["dataset.nc"]
        assert_same_data(reference["new"], out)
    res = flexmm("run", "--resume", out)
    assert res.returncode == 0, res.stderr
    if point == "commit:exchanged":
        assert "nothing to resume" in res.stderr and files(out) == now  # the old run swapped out is not revived
    assert_same_data(reference["new"], out)
    assert not list(tmp_path.glob(".demo.*.*"))  # no work or staging directory left


def test_sigkill_between_the_two_renames_of_a_commit_without_exchange(tmp_path, reference) -> None:
    """Where the filesystem cannot exchange two directories, a commit is two renames: killed between
    them, the next run puts the old result back, and --resume publishes the new one."""
    out = tmp_path / "demo"
    assert flexmm("run", DEMO, "--out", out, "-q", *SMALL, *OLD).returncode == 0
    old = files(out)
    no_exchange = [sys.executable, "-c", "import flexmm.io.rundir as r; r._exchange = lambda a, b: False\n"
                                         "from flexmm.cli import main; import sys; sys.argv[0] = 'flexmm'; main()"]
    proc = paused("commit:moved-old", "run", DEMO, "--out", out, "-q", *SMALL, *NEW, cmd=no_exchange)
    proc.kill()
    proc.communicate()
    aside = list(tmp_path.glob(".demo.old.*"))
    assert not out.exists() and len(aside) == 1 and files(aside[0]) == old  # the old run aside, whole
    res = flexmm("run", "--resume", out)
    assert res.returncode == 0, res.stderr
    assert_same_data(reference["new"], out)
    assert not list(tmp_path.glob(".demo.*.*"))
