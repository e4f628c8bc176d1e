"""Calibrate the run-time estimate every verb prints (``flexmm.plan.cost.throughput``).

    python benchmarks/calibrate.py          # time the stepper on every shipped scene and on larger
                                            # copies of the chains; writes src/flexmm/data/throughput.csv
    python benchmarks/calibrate.py resume   # the same, keeping the scenes already timed
                                            # (benchmarks/results/calibration_rows.json)
    python benchmarks/calibrate.py check    # run every shipped scene (auto fidelity, as `flexmm run`)
                                            # and compare the estimate with the integration time

The table holds unit-steps per second of the compiled stepper (compile excluded; the minimum time
of ``REPEATS`` fresh steppers, each advancing the same steps from the scene's initial state) for
the model kind, the method, the lattice size and the threads the run would use: the planned
problem of each shipped scene (``prepare.resolve``: its trimmed domain, its method and step), with
the method it runs and with velocity Verlet, and the chains at 8× and 64× their size (not the
predeformed ones, whose relaxation at that size takes longer than the timing). Regenerate
it after a change to the kernels or on another machine (the estimate is then that machine's).
``check`` writes benchmarks/results/calibration_check.json with the load average.
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


def _load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def _rate(problem, method: str, max_steps: int) -> tuple[float, int]:
    """(unit-steps per second, threads) of ``method`` on ``problem`` at a stable step."""
    from flexmm.integrators import INTEGRATORS
    from flexmm.integrators.stepper import make_stepper

    spec = INTEGRATORS[method]
    h = problem.dt
    if method != problem.scene.solver.integrator and problem.omega_max > 0:
        h = min(h, 0.5 * spec.stability_limit / problem.omega_max)
    n = problem.system.n_sites
    steps = max(1, min(max_steps, int(2e5 // n) or 1))
    while True:  # grow the window until one advance takes TIMED_S (or the run's own steps)
        st = make_stepper(problem, spec, h=h, check_energy=False)
        t0 = time.perf_counter()
        st.advance(steps)
        dt = time.perf_counter() - t0
        if dt >= TIMED_S or steps >= max_steps:
            break
        steps = min(max_steps, int(steps * max(2.0, 1.2 * TIMED_S / max(dt, 1e-6))))
    best = dt
    for _ in range(REPEATS - 1):
        st = make_stepper(problem, spec, h=h, check_energy=False)
        t0 = time.perf_counter()
        st.advance(steps)
        best = min(best, time.perf_counter() - t0)
    return steps * n / best, st.threads


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
                rate, threads = _rate(pb, m, max_steps)
                row = {"kind": pb.scene.lattice.kind, "method": m, "n_units": pb.system.n_sites,
                       "threads": threads, "unit_steps_per_s": f"{rate:.4g}", "scene": path.stem}
                rows.append(row)
                print(f"{row['scene']:<40} {row['kind']:<28} {m:<16} {row['n_units']:>8} units "
                      f"{rate / 1e6:8.3g} M unit-steps/s (load {_load()})", flush=True)
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
        ratio = est / res.wall_s if res.wall_s > 0 else float("nan")
        worst = max(worst, ratio, 1 / ratio)
        row = {"scene": path.stem, "estimate_s": est, "integration_s": res.wall_s, "ratio": ratio,
               "status": res.status, "load": _load()}
        out.append(row)
        print(f"{path.stem:<40} estimate {est:9.3g} s  integration {res.wall_s:9.3g} s  ratio {ratio:6.3g}  "
              f"(load {row['load']})", flush=True)
    print(f"worst ratio (max of estimate/actual and actual/estimate): {worst:.3g}")
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "calibration_check.json").write_text(json.dumps({"rows": out, "worst": worst}, indent=1))


if __name__ == "__main__":
    if sys.argv[1:2] == ["check"]:
        check(sys.argv[2:])
    else:
        calibrate(resume=sys.argv[1:2] == ["resume"])
