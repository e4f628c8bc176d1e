"""Checkpoints, ``flexmm run --resume`` and ``--extend`` with real processes and real signals.

A run is killed (SIGKILL at a random moment after its first checkpoint, during checkpoint writes
included) or stopped (SIGTERM), then resumed; every data variable of the published dataset must
equal, bit for bit, those of the same scene run without a stop. Around that: a corrupted newest
checkpoint is refused and the previous one used, two resumes at once (one refused by the lock),
a changed scene and another code version refused with what changed, and a finished run extended
to a longer duration equals the longer run made from the start.
"""

from __future__ import annotations

import hashlib
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import assert_same_data, default_sigint, is_stopped

from flexmm import checkpoint as ck
from flexmm.integrators import INTEGRATORS
from flexmm.io.run_dataset import open_run

ROOT = Path(__file__).resolve().parents[1]
DEMO = ROOT / "configs" / "lego_vector_soliton.yaml"
FLEXMM = str(Path(sys.executable).with_name("flexmm"))
# velocity Verlet fused with the chain force and blocked in time (verlet_chain), no pilots
VERLET = ["--set", "lattice.n_units=20000", "--set", "solver.duration_s=1.2", "--set", "output.n_frames=31",
          "--set", "solver.accuracy=null", "--set", "solver.integrator=velocity_verlet", "--set", "solver.dt_s=2.5e-5",
          "--fidelity", "full", "--checkpoint-s", "0.3"]
# the accuracy pilots choose the method and step (PEFRL, a splitting): the decision is checkpointed
PILOTED = ["--set", "lattice.n_units=2000", "--set", "solver.duration_s=2.0", "--set", "output.n_frames=101",
           "--fidelity", "full", "--checkpoint-s", "0.3"]


def flexmm(*args) -> subprocess.CompletedProcess:
    return subprocess.run([FLEXMM, *map(str, args)], capture_output=True, text=True, timeout=600)


def start(*args) -> subprocess.Popen:
    return subprocess.Popen([FLEXMM, *map(str, args)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=default_sigint)


def work_dirs(out: Path) -> list[Path]:
    return sorted(out.parent.glob(f".{out.name}.work.*"))


def wait_for_checkpoint(out: Path, proc: subprocess.Popen, timeout: float = 300.0) -> None:
    """Until the running process has written a checkpoint into its work directory."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        if any((d / ck.NAME).is_file() for d in work_dirs(out)):
            return
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.02)
    raise AssertionError("no checkpoint was written")


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory) -> dict[str, Path]:
    """The reference runs, never stopped."""
    root = tmp_path_factory.mktemp("reference")
    out = {}
    for name, args in (("verlet", VERLET), ("piloted", PILOTED)):
        res = flexmm("run", DEMO, "--out", root / name, "-q", *args)
        assert res.returncode == 0, res.stderr
        out[name] = root / name
    return out


def test_a_killed_run_resumes_bit_identical(tmp_path, uninterrupted) -> None:
    out = tmp_path / "demo"
    proc = start("run", DEMO, "--out", out, "-q", *VERLET)
    wait_for_checkpoint(out, proc)
    delay = random.Random(os.getpid()).uniform(0.0, 0.8)  # checkpoints every 0.3 s: some kills land in one
    time.sleep(delay)
    proc.kill()
    proc.communicate()
    assert proc.returncode == -signal.SIGKILL, f"the run ended before the kill {delay:.2f} s after its first checkpoint"
    assert not out.exists() and len(work_dirs(out)) == 1
    work = work_dirs(out)[0]
    if (work / ck.PREVIOUS).is_file():  # a damaged newest checkpoint: refused, the previous one used
        data = (work / ck.NAME).read_bytes()
        (work / ck.NAME).write_bytes(data[: len(data) // 2])
    # two resumes at once: the second is refused by the lock the first holds (the first stopped at
    # its commit, FLEXMM_PAUSE_AT, so that it cannot finish before the second starts)
    first = subprocess.Popen([FLEXMM, "run", "--resume", str(out), "--checkpoint-s", "0.3"], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True, preexec_fn=default_sigint,
                             env=dict(os.environ, FLEXMM_PAUSE_AT="commit"))
    t0 = time.monotonic()
    while not is_stopped(first.pid):
        assert first.poll() is None, first.communicate()
        assert time.monotonic() - t0 < 300, "the resume never reached its commit"
        time.sleep(0.02)
    second = flexmm("run", "--resume", out)
    first.send_signal(signal.SIGCONT)
    assert second.returncode == 2 and "in use by another flexmm process" in second.stderr, second.stderr
    _, err = first.communicate(timeout=600)
    assert first.returncode == 0, err
    if "refused" in err:
        assert "checksum does not match" in err
    assert_same_data(uninterrupted["verlet"], out)
    ds = open_run(out)
    assert ds.attrs["n_resumptions"] == 1 and "resumed at t = " in ds.attrs["resumed"]
    assert work_dirs(out) == [] and not (tmp_path / "demo.interrupted").exists()


def test_an_interrupted_run_resumes_and_refuses_changes(tmp_path, uninterrupted) -> None:
    out = tmp_path / "demo"
    proc = start("run", DEMO, "--out", out, "-q", *PILOTED)
    wait_for_checkpoint(out, proc)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 143, err
    partial = tmp_path / "demo.interrupted"
    assert (partial / ck.NAME).is_file() and open_run(partial).attrs["status"] == "interrupted"
    # the scene it was started with, changed: refused, naming the change
    res = flexmm("run", DEMO, "--resume", out, *PILOTED[:6], "--set", "excitation.velocity_m_s=2.0")
    assert res.returncode == 2 and "excitation.velocity_m_s: 3.0 -> 2.0" in res.stderr, res.stderr
    # a checkpoint written by another version: refused, naming it
    keep = (partial / ck.NAME).read_bytes()
    version = ck.read(partial / ck.NAME).meta["flexmm_version"]
    raw = keep.replace(f'"flexmm_version": "{version}"'.encode(), b'"flexmm_version": "0.0.1"')
    (partial / ck.NAME).write_bytes(raw[:-32] + hashlib.sha256(raw[:-32]).digest())  # a valid file, other code
    (partial / ck.PREVIOUS).unlink(missing_ok=True)
    res = flexmm("run", "--resume", out)
    assert res.returncode == 2 and "flexmm version 0.0.1 ->" in res.stderr, res.stderr
    (partial / ck.NAME).write_bytes(keep)
    # the same scene given again: accepted; the result is the uninterrupted run's
    res = flexmm("run", DEMO, "--resume", out, *PILOTED[:6], "--checkpoint-s", "0.3")
    assert res.returncode == 0, res.stderr
    assert_same_data(uninterrupted["piloted"], out)
    assert not partial.exists()  # superseded by the finished result


def test_extend_equals_the_longer_run_from_the_start(tmp_path) -> None:
    short, longer = tmp_path / "short", tmp_path / "long"
    args = ["--set", "lattice.n_units=500", "--set", "output.n_frames=21", "--fidelity", "full"]
    assert flexmm("run", DEMO, "--out", short, "-q", *args, "--set", "solver.duration_s=0.2").returncode == 0
    interval = float(open_run(short).attrs["frame_interval_s"])
    # the rule: the run's config.yaml (method and step fixed) with the longer duration and its frame interval
    res = flexmm("run", short / "config.yaml", "--out", longer, "-q", "--set", "solver.duration_s=0.5",
                 "--set", f"output.every_s={interval!r}")
    assert res.returncode == 0, res.stderr
    res = flexmm("run", "--extend", short, "--set", "solver.duration_s=0.5")
    assert res.returncode == 0, res.stderr
    assert_same_data(longer, short)
    assert open_run(short).sizes["time"] == 51
    res = flexmm("run", "--extend", short, "--set", "solver.duration_s=0.5", "--set", "solver.dt_s=1e-5")
    assert res.returncode == 2 and "solver.dt_s" in res.stderr, res.stderr


@pytest.mark.parametrize("sig, exc", [(signal.SIGINT, "KeyboardInterrupt"), (signal.SIGTERM, "Terminated")])
def test_a_signal_waits_for_the_end_of_a_deferred_block(sig, exc) -> None:
    from flexmm._signals import deferred, stop_on_signals

    # Python's own Ctrl-C handler, also where the suite was started with SIGINT ignored (a
    # background job of a script inherits SIG_IGN, and Python then installs no handler)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    seen = []
    try:
        with stop_on_signals(), pytest.raises(KeyboardInterrupt) as caught:
            with deferred():
                os.kill(os.getpid(), sig)
                time.sleep(0.05)
                seen.append("the block ran to its end")
            seen.append("not reached")
    finally:
        signal.signal(signal.SIGINT, previous)
    assert seen == ["the block ran to its end"] and type(caught.value).__name__ == exc


def test_a_damaged_checkpoint_is_refused_and_the_previous_one_used(tmp_path) -> None:
    q = np.arange(5.0)
    ck.write(tmp_path, {"frames_done": 3, "steps": 30}, {"q": q})
    ck.write(tmp_path, {"frames_done": 4, "steps": 40}, {"q": q + 1})
    found, refused = ck.best([tmp_path])
    assert found.meta["steps"] == 40 and np.array_equal(found.arrays["q"], q + 1) and refused == []
    data = bytearray((tmp_path / ck.NAME).read_bytes())
    data[-40] ^= 1  # one bit of the arrays flipped
    (tmp_path / ck.NAME).write_bytes(bytes(data))
    found, refused = ck.best([tmp_path])
    assert found.meta["steps"] == 30 and np.array_equal(found.arrays["q"], q)
    assert len(refused) == 1 and "checksum does not match" in refused[0]
    (tmp_path / ck.PREVIOUS).write_bytes(bytes(data[:100]))  # cut short
    with pytest.raises(ck.CheckpointError, match="checksum does not match"):
        ck.best([tmp_path])


def test_nothing_to_resume_is_a_user_error(tmp_path) -> None:
    res = flexmm("run", "--resume", tmp_path / "never_ran")
    assert res.returncode == 2 and "no checkpoint to continue from" in res.stderr and "Traceback" not in res.stderr
    res = flexmm("run")
    assert res.returncode == 2 and "missing the scene" in res.stderr, res.stderr


@pytest.mark.parametrize("integrator", sorted(INTEGRATORS))
def test_every_integrator_continues_bit_identical_from_a_checkpoint(tmp_path, integrator) -> None:
    """A run continued from its end checkpoint equals the longer run from t = 0, for every method:
    nothing a compiled stepper needs crosses a frame boundary outside the checkpoint (q, v, f, t,
    the accumulator with an adaptive or implicit method's state slots)."""
    from flexmm.assemble import build_problem
    from flexmm.config import load_scene
    from flexmm.controller import run_problem

    base = ["lattice.n_units=60", "damping.absorbing=null", "solver.accuracy=null",
            f"solver.integrator={integrator}", "output.every_s=0.002"]

    def problem(duration: float):
        return build_problem(load_scene(DEMO, [*base, f"solver.duration_s={duration}"]))

    first = run_problem(problem(0.02), tmp_path / "first", checkpoints=ck.Checkpointing(tmp_path / "first", np.inf))
    assert first.status == "finished" and (tmp_path / "first" / ck.NAME).is_file()
    whole = run_problem(problem(0.05), tmp_path / "whole")
    went_on = run_problem(problem(0.05), tmp_path / "went_on", resume=ck.read(tmp_path / "first" / ck.NAME))
    assert whole.status == went_on.status == "finished" and whole.n_steps == went_on.n_steps
    assert any(line.startswith("resumed at t = ") for line in went_on.log)  # not from t = 0
    assert_same_data(tmp_path / "whole", tmp_path / "went_on")
