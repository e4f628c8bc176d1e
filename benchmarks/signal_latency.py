"""How long after SIGINT/SIGTERM a run stops, phase by phase (issue 33: "a signal answered within 2 s").

    python benchmarks/signal_latency.py [REPEATS]       # or: python benchmarks/run.py signal_latency

``flexmm run`` of a scene whose phases each take seconds (the demo at 20,000 units, 3 s, 201 frames,
accuracy pilots, a checkpoint every 2 s of wall time) is stopped at the start of one phase by the
fault tests' hook (``FLEXMM_PAUSE_AT``, ``flexmm.io.pause``: the process stops itself with SIGSTOP).
The benchmark then sends the signal, resumes the process (SIGCONT) and — for the phases that run
compiled loops (pilot, integration) — sends the signal a moment later instead, so that it lands
inside them. The latency is the time from the signal (pending: from SIGCONT) to the process's exit,
and the CPU time the process used in between (what the latency would be on a free core).
Also checked: the exit status (130 / 143), and that a run stopped after its integration began left
its checkpoint (``<out>.interrupted/checkpoint.ckpt``) to resume from. Repeats alternate SIGINT and
SIGTERM; the table gives min / median / max seconds and the load average.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent
LEGO = ROOT.parent / "configs" / "lego_vector_soliton.yaml"
FLEXMM = str(Path(sys.executable).with_name("flexmm"))
SCENE = ["--set", "lattice.n_units=20000", "--set", "solver.duration_s=3", "--set", "output.n_frames=201"]

#: phase: (pause point, seconds after SIGCONT before the signal (None: sent while stopped), extra
#: arguments, whether a checkpoint must be left)
PHASES = {
    "planning": ("plan", None, [], False),
    "build": ("build", None, [], False),
    "pilot": ("pilot", 0.4, [], False),
    "integration": ("frame:3", 0.7, [], True),
    "frame write": ("frame:5", None, [], True),
    "checkpoint": ("checkpoint", None, [], True),
    "commit": ("commit", None, ["--set", "solver.duration_s=0.3"], False),
}


def _is_stopped(pid: int) -> bool:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat[stat.rfind(")") + 2] == "T"


def _cpu_s(pid: int) -> float:
    """CPU seconds (user + system) process ``pid`` has used so far."""
    stat = Path(f"/proc/{pid}/stat").read_text()
    fields = stat[stat.rfind(")") + 2 :].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def stop_once(phase: str, signum: int, root: Path) -> dict:
    """One run stopped in ``phase`` by ``signum``: latency, exit status, checkpoint kept."""
    point, delay, extra, needs_ck = PHASES[phase]
    out = root / f"run-{phase.replace(' ', '_')}-{signum}-{time.monotonic_ns()}"
    env = {**os.environ, "FLEXMM_PAUSE_AT": point}
    log = root / f"{out.name}.log"
    with open(log, "w") as fh:
        proc = subprocess.Popen([FLEXMM, "run", str(LEGO), *SCENE, *extra, "--out", str(out), "--checkpoint-s", "2"],
                                stdout=subprocess.DEVNULL, stderr=fh, env=env)
    try:
        t_wait = time.monotonic()
        while not _is_stopped(proc.pid):
            if proc.poll() is not None:
                return {"phase": phase, "error": f"ended (exit {proc.returncode}) before reaching {point}: "
                                                 f"{log.read_text()[-400:]}"}
            if time.monotonic() - t_wait > 900:
                raise TimeoutError(f"{phase}: never reached {point}")
            time.sleep(0.02)
        if delay is None:
            cpu0 = _cpu_s(proc.pid)
            os.kill(proc.pid, signum)  # pending until the process runs again
            t0 = time.monotonic()
            os.kill(proc.pid, signal.SIGCONT)
        else:
            os.kill(proc.pid, signal.SIGCONT)
            time.sleep(delay)
            cpu0 = _cpu_s(proc.pid)
            t0 = time.monotonic()
            os.kill(proc.pid, signum)
        _, status, usage = os.wait4(proc.pid, 0)
        latency = time.monotonic() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
        err = log.read_text()
        cpu = usage.ru_utime + usage.ru_stime - cpu0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    kept = (out.with_name(out.name + ".interrupted") / "checkpoint.ckpt").is_file()
    row = {"phase": phase, "signal": signal.Signals(signum).name, "latency_s": latency, "cpu_s": cpu, "exit": proc.returncode,
           "exit_ok": proc.returncode in (128 + signum, 0), "checkpoint_kept": kept,
           "checkpoint_ok": kept or not needs_ck, "traceback": "Traceback" in err, "load": os.getloadavg()[0]}
    for p in root.glob(out.name + "*"):
        shutil.rmtree(p, ignore_errors=True)
    return row


def signal_latency(repeats: int = 3, phases: tuple[str, ...] = tuple(PHASES)) -> dict:
    """The table of latencies per phase (module docstring)."""
    root = Path(tempfile.mkdtemp(prefix="flexmm-bench-signals-"))
    rows: list[dict] = []
    try:
        subprocess.run([FLEXMM, "run", str(LEGO), *SCENE, "--set", "solver.duration_s=0.05", "--out",
                        str(root / "warm")], capture_output=True, check=False)  # numba's cache warm
        for phase in phases:
            for r in range(repeats):
                row = stop_once(phase, (signal.SIGINT, signal.SIGTERM)[r % 2], root)
                rows.append(row)
                print(json.dumps(row), flush=True)
    finally:
        shutil.rmtree(root, ignore_errors=True)
    print(f"\n{'phase':12s} {'min s':>7s} {'median s':>9s} {'max s':>7s} {'CPU s (max)':>11s}  exit ok  "
          "checkpoint  load")
    table = []
    for phase in phases:
        got = [r for r in rows if r["phase"] == phase and "latency_s" in r]
        if not got:
            print(f"{phase:12s} (not reached: {[r.get('error') for r in rows if r['phase'] == phase][:1]})")
            continue
        lat = sorted(r["latency_s"] for r in got)
        line = {"phase": phase, "min_s": lat[0], "median_s": lat[len(lat) // 2], "max_s": lat[-1],
                "max_cpu_s": max(r["cpu_s"] for r in got), "exit_ok": all(r["exit_ok"] for r in got), "checkpoint_ok": all(r["checkpoint_ok"] for r in got),
                "no_traceback": not any(r["traceback"] for r in got),
                "load": sum(r["load"] for r in got) / len(got)}
        table.append(line)
        print(f"{phase:12s} {line['min_s']:7.2f} {line['median_s']:9.2f} {line['max_s']:7.2f} "
              f"{line['max_cpu_s']:11.2f}  "
              f"{'yes' if line['exit_ok'] else 'NO':7s}  {'yes' if line['checkpoint_ok'] else 'NO':10s}  "
              f"{line['load']:.1f}")
    return {"rows": rows, "table": table, "cpus": os.cpu_count()}


if __name__ == "__main__":
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 3
    chosen = tuple(sys.argv[2].split(",")) if len(sys.argv) > 2 else tuple(PHASES)
    print(f"load average {os.getloadavg()}, {os.cpu_count()} CPUs")
    signal_latency(n, chosen)
