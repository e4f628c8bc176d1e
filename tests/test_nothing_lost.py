"""Nothing lost, at any moment (issue 33): the user's inputs, locks without flock, a really full
disk, signals during the accuracy pilots. Real processes (the console script) on real files.
"""

from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import default_sigint
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
