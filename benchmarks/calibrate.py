"""Calibrate the run-time estimate every verb prints (``flexmm.plan.cost.throughput``).

    python benchmarks/calibrate.py          # time the stepper on every shipped scene and on larger
                                            # copies of the chains; writes src/flexmm/data/throughput.csv
    python benchmarks/calibrate.py resume   # the same, keeping the scenes already timed
                                            # (benchmarks/results/calibration_rows.json)
    python benchmarks/calibrate.py check    # run every shipped scene (auto fidelity, as `flexmm run`)
                                            # and compare the estimate with the integration time

The table holds unit-steps per CPU second of the compiled stepper (compile excluded; the minimum
of ``REPEATS`` fresh steppers, each advancing the same steps from the scene's initial state) and
the CPU seconds of a call beyond its steps (a run makes one per frame) for
the model kind, the method, the lattice size and the threads the run would use: the planned
problem of each shipped scene (``prepare.resolve``: its trimmed domain, its method and step), with
the method it runs and with velocity Verlet, and the chains at 8× and 64× their size (not the
predeformed ones, whose relaxation at that size takes longer than the timing). Regenerate
it after a change to the kernels or on another machine (the estimate is then that machine's).
``check`` compares with the integration's CPU time (``cpu_time_s``; on a shared machine its wall
time is that stretched by the load) and writes benchmarks/results/calibration_check.json with the
load average.
"""

from __future__ import annotations

import csv
import json
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent
CONFIGS = ROOT.parent / "configs"
TABLE = ROOT.parent / "src" / "flexmm" / "data" / "throughput.csv"
RESULTS = ROOT / "results"
REPEATS = 3
TIMED_S = 0.15  # at least this long per timed advance
SCALES = (8, 64)  # larger copies of the 1D lattices
MAX_UNITS = 100_000
CALLS = 200  # single-step calls timed for the cost of a call (one per frame in a run)


def _load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def _advance_cpu(problem, spec, h: float, steps: int) -> float:
    """CPU seconds of a fresh stepper advancing ``steps`` steps in one call (compile excluded)."""
    from flexmm.integrators.stepper import make_stepper

    st = make_stepper(problem, spec, h=h, check_energy=False)
    st.advance(steps)
    return st.cpu_s


def _rate(problem, method: str, max_steps: int) -> tuple[float, float, int]:
    """(unit-steps per CPU second, CPU seconds per call beyond its steps, threads) of ``method`` on
    ``problem`` at a stable step. CPU time, not wall time: on a shared machine the wall time of a
    run is its CPU time stretched by the load, which the estimate cannot know."""
    from flexmm.integrators import INTEGRATORS
    from flexmm.integrators.stepper import make_stepper

    spec = INTEGRATORS[method]
    h = problem.dt
    if method != problem.scene.solver.integrator and problem.omega_max > 0:
        h = min(h, 0.5 * spec.stability_limit / problem.omega_max)
    n = problem.system.n_sites
    steps = max(1, min(max_steps, int(2e5 // n) or 1))
    while True:  # grow the window until one advance takes TIMED_S (or the run's own steps)
        cpu = _advance_cpu(problem, spec, h, steps)
        if cpu >= TIMED_S or steps >= max_steps:
            break
        steps = min(max_steps, int(steps * max(2.0, 1.2 * TIMED_S / max(cpu, 1e-6))))
    best = min([cpu] + [_advance_cpu(problem, spec, h, steps) for _ in range(REPEATS - 1)])
    st = make_stepper(problem, spec, h=h, check_energy=False)
    threads = max(st.threads, 1)
    rate = steps * n / best * threads  # CPU seconds of all threads: the wall time of an idle machine
    calls = max(1, min(CALLS, max_steps))
    st.advance(calls)
    one = st.cpu_s
    st.cpu_s = 0.0
    for _ in range(calls):
        st.advance(1)
    call_s = max(0.0, (st.cpu_s - one) / calls) / threads
    return rate, call_s, threads


def _scaled(scene, factor: int):
    """``scene`` with a 1D lattice ``factor`` times longer, or None."""
    from flexmm.config import scene_from_dict

    data = scene.model_dump(mode="json")
    lat = data["lattice"]
    if lat.get("predeform") or "n_units" not in lat or lat.get("n_lateral", 1) not in (1, None) or "n_rows" in lat:
        return None
    lat["n_units"] = lat["n_units"] * factor
    if lat["n_units"] > MAX_UNITS:
        return None
    try:
        return scene_from_dict(data, source="<calibrate>")
    except Exception:  # a scene whose other fields depend on the size: not scaled
        return None


def calibrate(resume: bool = False) -> None:
    from flexmm.assemble import build_problem
    from flexmm.config import load_scene
    from flexmm.prepare import resolve

    partial = RESULTS / "calibration_rows.json"
    rows = json.loads(partial.read_text()) if resume and partial.exists() else []
    done = {r["scene"] for r in rows}
    RESULTS.mkdir(exist_ok=True)
    for path in sorted(CONFIGS.glob("*.yaml")):
        if path.stem in done:
            continue
        rp = resolve(load_scene(path), "auto")
        if rp.problem is None:
            continue
        problem = rp.problem
        method = problem.scene.solver.integrator
        cases = [(problem, rp.frames.n_steps or 10_000)]
        for k in SCALES:
            sc = _scaled(problem.scene, k)
            if sc is not None:
                try:
                    cases.append((build_problem(sc), rp.frames.n_steps or 10_000))
                except Exception as exc:  # noqa: BLE001 - a copy that does not build is skipped
                    print(f"  {path.stem} x{k}: not built ({exc})", file=sys.stderr)
        for pb, max_steps in cases:
            for m in dict.fromkeys((method, "velocity_verlet")):
                rate, call_s, threads = _rate(pb, m, max_steps)
                row = {"kind": pb.scene.lattice.kind, "method": m, "n_units": pb.system.n_sites,
                       "threads": threads, "unit_steps_per_s": f"{rate:.4g}", "call_s": f"{call_s:.3g}",
                       "scene": path.stem}
                rows.append(row)
                print(f"{row['scene']:<40} {row['kind']:<28} {m:<16} {row['n_units']:>8} units "
                      f"{rate / 1e6:8.3g} M unit-steps/s, {call_s * 1e6:6.3g} µs a call (load {_load()})", flush=True)
        partial.write_text(json.dumps(rows, indent=0))
    with open(TABLE, "w", newline="") as fh:
        fh.write(f"# unit-steps per second of the compiled stepper; python benchmarks/calibrate.py; "
                 f"{time.strftime('%Y-%m-%d')}, {os.cpu_count()} cores, load {_load()}\n")
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    print(f"written: {TABLE} ({len(rows)} rows)")


def check(names: list[str]) -> None:
    from flexmm.api import run_scene
    from flexmm.config import load_scene

    out, worst = [], 1.0
    paths = [p for p in sorted(CONFIGS.glob("*.yaml")) if not names or p.stem in names]
    for path in paths:
        scene = load_scene(path)
        plan: list[str] = []
        with tempfile.TemporaryDirectory() as tmp:
            res = run_scene(scene, run_dir=Path(tmp) / scene.name, fidelity="auto", in_memory=True,
                            announce=plan.extend)
        est = res.dataset.attrs.get("plan_estimated_s") if res.dataset is not None else None
        if est is None:
            continue
        cpu = float(res.dataset.attrs["cpu_time_s"]) / max(int(res.dataset.attrs.get("threads", 1)), 1)
        ratio = est / cpu if cpu > 0 else float("nan")
        worst = max(worst, ratio, 1 / ratio)
        row = {"scene": path.stem, "estimate_s": est, "integration_cpu_s": cpu, "integration_wall_s": res.wall_s,
               "ratio": ratio, "status": res.status, "load": _load()}
        out.append(row)
        print(f"{path.stem:<40} estimate {est:9.3g} s  integration {cpu:9.3g} s CPU ({res.wall_s:9.3g} s wall)  "
              f"ratio {ratio:6.3g}  (load {row['load']})", flush=True)
    print(f"worst ratio (max of estimate/actual and actual/estimate): {worst:.3g}")
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "calibration_check.json").write_text(json.dumps({"rows": out, "worst": worst}, indent=1))


if __name__ == "__main__":
    if sys.argv[1:2] == ["check"]:
        check(sys.argv[2:])
    else:
        calibrate(resume=sys.argv[1:2] == ["resume"])
