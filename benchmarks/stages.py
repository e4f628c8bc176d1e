"""Where a run's time goes, by stage, for small and large scenes (issue 37): before and after.

    python benchmarks/stages.py                       # every case, this tree only
    FLEXMM_BASELINE=/work/main python benchmarks/stages.py demo chain_1e6   # two trees, interleaved
    python benchmarks/stages.py chain_1e7 --repeats 1 --warmup 0 --only before   # one tree, cache warm

Each case is ``flexmm run`` in a fresh interpreter with the stage functions of ``run.py``'s
``STAGE_FUNCS`` wrapped (``run._stages_once``): imports, plan (less its builds), build, step
bound (``omega_max``), pilot (the accuracy pilots, all they call), integration (the stepper's
advances), frames (observer and dataset writer), checks (blow-up and energy checks, stiffness
tracking), the rest of the run, the summary, and the interpreter's start and exit. One warm-up
run per tree and case first (numba's cache); then ``--repeats`` runs, the trees alternating; the
table shows the minimum of each stage's wall time (the machine is shared: the load is printed),
end to end, and end to end over integration. The large chains are the demo's LEGO chain at 10⁶
units × 10⁴ steps and 10⁷ units × 1,000 steps, one thread, velocity Verlet, the step given and
``--fidelity full`` (no trimming of the lattice): a 10⁷-unit chain holds several GB, so run the
big cases one at a time. Results: benchmarks/results/stages.json.
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from run import BASELINE_ENV, LEGO, RESULTS, ROOT, _load, _stages_once  # noqa: E402

CONFIGS = ROOT.parent / "configs"


def _chain(n_units: int, steps: int, dt_s: float = 1e-4) -> dict:
    return {"config": LEGO, "args": ["--fidelity", "full", "-s", f"lattice.n_units={n_units}",
                                     "-s", "solver.integrator=velocity_verlet", "-s", f"solver.dt_s={dt_s:g}",
                                     "-s", f"solver.duration_s={steps * dt_s:.10g}", "-s", "output.n_frames=11",
                                     "-s", "solver.threads=1"]}


#: case -> the scene and the arguments of ``flexmm run``
CASES = {
    "demo": {"config": LEGO, "args": []},
    "sheet": {"config": CONFIGS / "a_sheet_sound_bullet.yaml", "args": []},
    "chain_1e6": _chain(1_000_000, 10_000),
    "chain_1e7": _chain(10_000_000, 1_000),
}
STAGES = ("imports", "plan", "build", "step bound", "pilot", "integration", "frames", "checks",
          "run (rest)", "summary", "start/exit", "cli (rest)")


def measure(case: str, repeats: int, only: str | None = None, warmup: int = 1) -> list[dict]:
    """The stage table of ``case`` in this tree (and ``$FLEXMM_BASELINE``'s, alternating; ``only``:
    one of the two, "before" or "after")."""
    trees = {"after": ROOT.parent / "src"}
    if os.environ.get(BASELINE_ENV):
        trees = {"before": Path(os.environ[BASELINE_ENV]) / "src", **trees}
    if only:
        trees = {only: trees[only]}
    spec = CASES[case]
    env = dict(os.environ, NUMBA_NUM_THREADS="1")
    runs: dict[str, list[dict]] = {tag: [] for tag in trees}
    with tempfile.TemporaryDirectory(prefix="flexmm-bench-stages-") as tmp:
        for k in range(repeats + warmup):
            for tag in (list(trees) if k % 2 == 0 else list(trees)[::-1]):
                row = _stages_once(trees[tag], Path(tmp) / tag, tuple(spec["args"]), spec["config"], env)
                row["load"] = os.getloadavg()[0]
                if k >= warmup:  # the first round warms numba's cache and the file system
                    runs[tag].append(row)
                print(f"  {case} {tag} run {k}: {row['wall_s']:.2f} s (load {row['load']:.2f})", flush=True)
    out = []
    for tag, rows in runs.items():
        table = {s: min(r["stages"].get(s, 0.0) for r in rows) for s in STAGES}
        cpu = {s: min(r["stages_cpu"].get(s, 0.0) for r in rows) for s in STAGES}
        wall, cpu_total = min(r["wall_s"] for r in rows), min(r["cpu_s"] for r in rows)
        integ = table["integration"]
        plan = [ln.strip() for ln in rows[0]["summary_text"] if ln.strip().startswith("plan:")]
        out.append({"case": case, "tree": tag, "repeats": repeats, "stages_min_s": table, "wall_min_s": wall,
                    "wall_over_integration": wall / integ if integ > 0 else float("nan"),
                    "stages_cpu_min_s": cpu, "cpu_min_s": cpu_total,
                    "cpu_over_integration": cpu_total / cpu["integration"] if cpu["integration"] > 0 else float("nan"),
                    "loads": [r["load"] for r in rows], "plan": plan})
    return out


def print_table(rows: list[dict]) -> None:
    """Wall and CPU seconds by stage (the CPU time of a one-thread run is the steadier on a shared
    machine: it leaves out the time the process waited for a core)."""
    head = ["case", "tree", "clock"] + [s.replace(" ", "_") for s in STAGES] + ["total", "total/integ"]
    print(" ".join(f"{h:>11s}" for h in head))
    for r in rows:
        for clock, key, total, ratio in (("wall", "stages_min_s", "wall_min_s", "wall_over_integration"),
                                         ("cpu", "stages_cpu_min_s", "cpu_min_s", "cpu_over_integration")):
            vals = [r[key][s] for s in STAGES]
            print(" ".join([f"{r['case']:>11s}", f"{r['tree']:>11s}", f"{clock:>11s}"] + [f"{v:11.3f}" for v in vals]
                           + [f"{r[total]:11.3f}", f"{r[ratio]:11.2f}"]))
    print(f"(minimum over repeats of each stage's seconds; {_load()})")


def main(argv: list[str]) -> None:
    repeats = 3
    if "--repeats" in argv:
        i = argv.index("--repeats")
        repeats = int(argv[i + 1])
        argv = argv[:i] + argv[i + 2:]
    only, warmup = None, 1
    if "--warmup" in argv:
        i = argv.index("--warmup")
        warmup = int(argv[i + 1])
        argv = argv[:i] + argv[i + 2:]
    if "--only" in argv:
        i = argv.index("--only")
        only = argv[i + 1]
        argv = argv[:i] + argv[i + 2:]
    cases = argv or list(CASES)
    rows = []
    for case in cases:
        rows += measure(case, repeats, only, warmup)
        print_table(rows)
    RESULTS.mkdir(exist_ok=True)
    path = RESULTS / "stages.json"
    old = json.loads(path.read_text()) if path.exists() else []
    keep = [r for r in old if (r["case"], r["tree"]) not in {(x["case"], x["tree"]) for x in rows}]
    path.write_text(json.dumps(keep + rows, indent=1, default=float))
    print(f"wrote {path}")


if __name__ == "__main__":
    main(sys.argv[1:])
