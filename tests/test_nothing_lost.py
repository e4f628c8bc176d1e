"""Nothing lost, at any moment (issue 33): the user's inputs, locks without flock, a really full
disk, signals during the accuracy pilots. Real processes (the console script) on real files.
"""

from __future__ import annotations

import json
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
from conftest import DEMO_AS_LEGO_SCENE_SETS, default_sigint, mounted_tmpfs
from test_faults import DEMO, FLEXMM, LONG, SHORT, flexmm, wait_until_stepping

from flexmm.io.run_dataset import open_run

SCENE_TEXT = DEMO.read_text()


def _own_scene(where: Path) -> Path:
    """The demo scene as a user keeps it: with a comment of their own."""
    where.mkdir(parents=True, exist_ok=True)
    path = where / "config.yaml"
    path.write_text("# my experiment 1: do not lose this note\n" + SCENE_TEXT)
    return path


def test_a_run_never_writes_over_its_input_config(tmp_path) -> None:
    """`cp X.yaml exp1/config.yaml; flexmm run exp1/config.yaml --out exp1`: refused, input untouched."""
    exp = tmp_path / "exp1"
    cfg = _own_scene(exp)
    before = cfg.read_bytes()
    res = flexmm("run", cfg, "--out", exp, *SHORT)
    assert res.returncode == 2, res.stderr
    assert res.stderr.startswith("error: ") and "Traceback" not in res.stderr
    assert str(cfg) in res.stderr and "inside the run directory" in res.stderr
    assert cfg.read_bytes() == before and sorted(p.name for p in exp.iterdir()) == ["config.yaml"]
    assert not exp.with_name("exp1.failed").exists() and not exp.with_name("exp1.interrupted").exists()


def test_a_directory_holding_files_flexmm_did_not_write_is_refused(tmp_path) -> None:
    """A scene elsewhere, `--out` a directory holding the user's own files: refused, naming them."""
    exp = tmp_path / "exp1"
    mine = _own_scene(exp)
    cfg = tmp_path / "scene.yaml"
    shutil.copy(DEMO, cfg)
    res = flexmm("run", cfg, "--out", exp, *SHORT)
    assert res.returncode == 2 and "not a flexmm run directory" in res.stderr and "config.yaml" in res.stderr
    assert mine.read_text().startswith("# my experiment 1")
    # a partial sibling is replaced by the next partial: it is refused too when flexmm did not write it
    exp2 = tmp_path / "exp2"
    keep = _own_scene(tmp_path / "exp2.failed")
    res = flexmm("run", cfg, "--out", exp2, *SHORT)
    assert res.returncode == 2 and "exp2.failed" in res.stderr and keep.exists()
    # a run directory flexmm wrote is replaced as before (a rerun)
    res = flexmm("run", cfg, "--out", tmp_path / "demo", "-q", *SHORT)
    assert res.returncode == 0, res.stderr
    res = flexmm("run", cfg, "--out", tmp_path / "demo", "-q", *SHORT)
    assert res.returncode == 0, res.stderr


# -- locks where flock is unsupported -------------------------------------------------------------

NO_FLOCK_C = """
#include <errno.h>
int flock(int fd, int operation) { (void)fd; (void)operation; errno = ENOSYS; return -1; }
"""


@pytest.fixture(scope="module")
def no_flock_env(tmp_path_factory) -> dict:
    """The environment of a process whose flock() fails with ENOSYS (an LD_PRELOAD shim, built here)."""
    cc = shutil.which("gcc") or shutil.which("cc")
    if cc is None:
        pytest.skip("no C compiler to build the LD_PRELOAD shim whose flock() returns ENOSYS")
    d = tmp_path_factory.mktemp("shim")
    (d / "noflock.c").write_text(NO_FLOCK_C)
    res = subprocess.run([cc, "-shared", "-fPIC", "-o", d / "noflock.so", d / "noflock.c"], capture_output=True,
                         text=True)
    if res.returncode != 0:
        pytest.skip(f"the LD_PRELOAD shim does not build: {res.stderr.strip()[:200]}")
    env = dict(os.environ, LD_PRELOAD=str(d / "noflock.so"))
    probe = subprocess.run([sys.executable, "-c", "import fcntl, os; fcntl.flock(os.open('/', os.O_RDONLY), "
                            "fcntl.LOCK_EX)"], env=env, capture_output=True, text=True)
    assert probe.returncode != 0 and "Function not implemented" in probe.stderr, probe.stderr  # the shim is real
    return env


def test_runs_lock_with_a_lock_file_where_flock_is_unsupported(tmp_path, no_flock_env) -> None:
    out = tmp_path / "demo"
    res = flexmm("run", DEMO, "--out", out, "-q", *SHORT, env=no_flock_env)
    assert res.returncode == 0, res.stderr
    assert open_run(out).attrs["status"] == "finished"
    assert not (tmp_path / ".demo.lock.excl").exists()  # released at the end
    # a second run while the first holds the lock is refused, naming the mechanism and the holder
    proc = subprocess.Popen([FLEXMM, "run", DEMO, "--out", out, *LONG], env=no_flock_env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, preexec_fn=default_sigint)
    try:
        wait_until_stepping(out, proc)
        lock = tmp_path / ".demo.lock.excl"
        holder = json.loads(lock.read_text())
        assert holder["pid"] == proc.pid and holder["host"] == socket.gethostname() and holder["start"]
        res = flexmm("run", DEMO, "--out", out, "-q", *SHORT, env=no_flock_env)
        assert res.returncode == 2 and "Traceback" not in res.stderr, res.stderr
        assert "O_EXCL" in res.stderr and "flock" in res.stderr and f"pid {proc.pid}" in res.stderr
        # killed: its lock file stays, on this host with a dead pid: the next run breaks it
        proc.kill()
        proc.communicate(timeout=60)
        assert lock.exists()
        res = flexmm("run", DEMO, "--out", out, "-q", *SHORT, env=no_flock_env)
        assert res.returncode == 0, res.stderr
        assert not lock.exists()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()


def _dead_pid() -> int:
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


def test_stale_lock_rule() -> None:
    from flexmm.io.rundir import lock_holder, lock_is_stale

    me = lock_holder()
    here = me["host"]
    assert not lock_is_stale(me)  # alive, this host
    assert lock_is_stale(dict(me, pid=_dead_pid()))  # this host, dead pid
    assert lock_is_stale(dict(me, start=str(int(me["start"]) + 1)))  # the pid now runs another process
    elsewhere = here + "-elsewhere"
    assert not lock_is_stale(dict(me, host=elsewhere, pid=_dead_pid()))  # another host: never stale from here
    assert not lock_is_stale(dict(me, host=elsewhere))
    assert not lock_is_stale({"host": here})  # no pid: cannot be judged dead


def test_a_live_lock_of_another_host_is_reported_never_taken(tmp_path) -> None:
    from flexmm.errors import OutputError
    from flexmm.io.rundir import _exclusive_file, lock_holder

    lock = tmp_path / ".demo.lock.excl"
    theirs = dict(lock_holder(), host="node-42.cluster", pid=_dead_pid())
    lock.write_text(json.dumps(theirs))
    with pytest.raises(OutputError) as info, _exclusive_file(lock, "run directory demo"):
        pass
    msg = str(info.value)
    assert "node-42.cluster" in msg and "O_EXCL" in msg and f"remove {lock}" in msg
    assert json.loads(lock.read_text()) == theirs
    mine = dict(theirs, host=lock_holder()["host"])  # the same dead pid on this host: broken, then ours
    lock.write_text(json.dumps(mine))
    with _exclusive_file(lock, "run directory demo"):
        assert json.loads(lock.read_text())["pid"] == os.getpid()
    assert not lock.exists()


# -- a really full disk ---------------------------------------------------------------------------

#: 2003 frames of u and theta on the demo's 200-unit free-ended chain: 6.2 MiB, on a 3 MiB filesystem
FILLS_3M = [*(a for s in DEMO_AS_LEGO_SCENE_SETS for a in ("--set", s)), "--set", "solver.duration_s=20", "--set", "output.n_frames=2001", "--fidelity", "full",
            "--set", "solver.accuracy=null", "--set", "output.velocities=false", "--force"]


@pytest.fixture
def small_disk(tmp_path):
    """A 3 MiB tmpfs mounted for the test, 0.5 MB of it already used."""
    with mounted_tmpfs(tmp_path / "small", "3m") as where:
        (where / "filler").write_bytes(bytes(500_000))
        yield where


def _no_leftovers(where: Path) -> None:
    left = [p.name for p in where.iterdir() if ".staging." in p.name or p.name.endswith((".tmp", ".reserve"))]
    assert left == []


def test_a_full_disk_keeps_the_frames_it_says_it_kept(small_disk) -> None:
    out = small_disk / "demo"
    res = flexmm("run", DEMO, "--out", out, *FILLS_3M)
    assert res.returncode == 1, res.stderr
    assert "Traceback" not in res.stderr and "No space left on device" in res.stderr
    m = re.search(r"the (\d+) frames written before it \(to t = ([0-9.e+-]+) s\) are kept", res.stderr)
    assert m, res.stderr
    n_kept, t_kept = int(m.group(1)), float(m.group(2))
    assert not out.exists()
    ds = open_run(small_disk / "demo.failed")
    assert ds.attrs["status"] == "failed" and ds.sizes["time"] == ds.attrs["n_frames_written"] == n_kept > 0
    assert ds["time"].values[-1] == pytest.approx(t_kept, rel=1e-5) and np.all(np.diff(ds["time"].values) > 0)
    assert np.isfinite(ds["theta"].values).all() and np.abs(ds["theta"].values[-1]).max() > 0
    _no_leftovers(small_disk)


def test_hdf5_failing_on_a_full_disk_keeps_nothing_and_says_so(small_disk) -> None:
    """The room check bypassed, HDF5 itself hits the full disk: a message, exit 1, no crash."""
    out = small_disk / "demo"
    code = ("import sys; import flexmm.io.run_dataset as rd; rd.DatasetWriter._room = lambda self, i0, k: (k, '')\n"
            "from flexmm.cli import main\n"
            f"sys.argv = ['flexmm', 'run', {str(DEMO)!r}, '--out', {str(out)!r}, *{FILLS_3M!r}]\nmain()")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert res.returncode == 1, (res.returncode, res.stderr[-2000:])
    assert "Traceback" not in res.stderr and "nothing was kept" in res.stderr, res.stderr[-2000:]
    assert "No space left on device" in res.stderr
    assert not out.exists() and not (small_disk / "demo.failed" / "dataset.nc").exists()
    assert (small_disk / "demo.failed" / "run.log").exists()
    _no_leftovers(small_disk)


# -- signals during the accuracy pilots ----------------------------------------------------------

#: the issue's scene: pilots of several seconds before the run (20 000 units, accuracy 1e-4)
PILOT_SCENE = ["--set", "lattice.n_units=20000", "--set", "solver.duration_s=3", "--set", "output.n_frames=201"]
#: the CLI with faulthandler on SIGUSR1: the test asks for the stack until it is in a pilot
CLI_WITH_STACKS = ("import faulthandler, signal, sys; faulthandler.register(signal.SIGUSR1, all_threads=False)\n"
                   "print('stacks on SIGUSR1', file=sys.stderr, flush=True)\n"
                   "from flexmm.cli import main\nsys.argv[0] = 'flexmm'\nmain()")


def _stop_inside_a_pilot(tmp_path: Path, sig: int) -> tuple[int, float, str]:
    """Start the run, find it inside ``accuracy.trace``/``integrate`` (its stack), send ``sig``;
    (exit status, seconds from the signal to the exit, stderr)."""
    out, err_path = tmp_path / "pilot", tmp_path / "stderr.txt"
    with open(err_path, "w") as err:
        proc = subprocess.Popen([sys.executable, "-c", CLI_WITH_STACKS, "run", str(DEMO), "--out", str(out),
                                 *PILOT_SCENE], stdout=subprocess.DEVNULL, stderr=err, preexec_fn=default_sigint)
    try:
        t0, seen = time.monotonic(), 0
        while True:
            assert proc.poll() is None, err_path.read_text()[-3000:]
            assert time.monotonic() - t0 < 240, "the run never reached its accuracy pilots"
            if "stacks on SIGUSR1" not in err_path.read_text():
                time.sleep(0.1)
                continue
            proc.send_signal(signal.SIGUSR1)
            time.sleep(0.5)
            dumps = err_path.read_text()
            last = dumps[seen:]
            seen = len(dumps)
            if re.search(r'accuracy\.py", line \d+ in (trace|integrate)', last):
                break
        assert "rotating_squares_chain: " not in dumps  # the run itself has not started
        sent = time.monotonic()
        proc.send_signal(sig)
        proc.wait(timeout=120)
        return proc.returncode, time.monotonic() - sent, err_path.read_text()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


@pytest.mark.parametrize("sig, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_signal_during_the_accuracy_pilots_stops_the_run(tmp_path, sig, code) -> None:
    rc, latency, err = _stop_inside_a_pilot(tmp_path, sig)
    print(f"{signal.Signals(sig).name} inside a pilot: exit {rc} after {latency:.2f} s")
    assert rc == code, err[-3000:]
    assert latency < 30, latency  # ~0.2 s on a quiet machine; generous for a loaded one
    assert f"interrupted by {signal.Signals(sig).name} before the run started: nothing written" in err
    tail = err[err.rfind("most recent call first"):]  # after the last stack dump: no Python traceback
    assert "Traceback" not in tail
    # nothing published: no result, finished or partial, and no leftovers
    assert sorted(p.name for p in tmp_path.iterdir() if not p.name.startswith(".pilot.lock")) == ["stderr.txt"]

