"""A signal in each phase of a run stops it (the phases of ``benchmarks/signal_latency.py``):
``flexmm run`` is stopped by the fault tests' hook at the start of the phase (``FLEXMM_PAUSE_AT``,
``flexmm.io.pause``), the signal is sent and the process resumed. Each time: exit 130 / 143, no
traceback, and — once the time loop has begun — its checkpoint kept for ``--resume``. Moments
chosen by the hook, not by timing: robust on a loaded machine."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import is_stopped

ROOT = Path(__file__).resolve().parents[1]
DEMO = ROOT / "configs" / "lego_vector_soliton.yaml"
FLEXMM = str(Path(sys.executable).with_name("flexmm"))
# the demo with its accuracy pilots, a checkpoint at every frame
SCENE = ["--set", "solver.duration_s=0.1", "--set", "output.n_frames=21", "--checkpoint-s", "0.000001"]

PHASES = [("plan", False), ("build", False), ("pilot", False), ("frame:3", True), ("checkpoint:2", True)]


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
@pytest.mark.parametrize(("point", "checkpointed"), PHASES)
def test_a_signal_in_each_phase_stops_the_run(tmp_path, point, checkpointed, sig) -> None:
    out = tmp_path / "run"
    proc = subprocess.Popen([FLEXMM, "run", str(DEMO), *SCENE, "--out", str(out)], stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True, env={**os.environ, "FLEXMM_PAUSE_AT": point})
    try:
        t0 = time.monotonic()
        while not is_stopped(proc.pid):
            assert proc.poll() is None, f"ended before reaching {point}: {proc.communicate()[1][-2000:]}"
            assert time.monotonic() - t0 < 600, f"never reached {point}"
            time.sleep(0.02)
        os.kill(proc.pid, sig)
        os.kill(proc.pid, signal.SIGCONT)
        _, err = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 128 + sig, err[-2000:]
    assert "Traceback" not in err
    assert not out.exists()  # nothing published as finished
    kept = out.with_name("run.interrupted") / "checkpoint.ckpt"
    assert kept.is_file() == checkpointed, sorted(p.name for p in tmp_path.iterdir())
