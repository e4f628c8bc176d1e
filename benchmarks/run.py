"""flexmm benchmarks: throughput, memory, the 2D target and work–precision (not timed tests).

    python benchmarks/run.py                  # throughput + memory + sheet (a few minutes)
    python benchmarks/run.py throughput       # one section: throughput | memory | sheet | workprecision
    python benchmarks/run.py workprecision    # flexmm bench on benchmarks/configs/*.yaml (slow)

Every timing is the minimum over repeats after a compile warm-up; thread/process CPU time is
printed next to wall time because the machine may be shared (CPU time excludes time spent
descheduled). Results go to benchmarks/results/<section>.json (git-ignored).
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent
RESULTS = ROOT / "results"
LEGO = ROOT.parent / "configs" / "lego_vector_soliton.yaml"
FLEXMM = str(Path(sys.executable).with_name("flexmm"))  # the console script of this environment


def _chain(n_units: int):
    """The LEGO impact chain with n_units, built without the ω_max solve (not needed here)."""
    from flexmm.assemble import apply_excitation, damping_arrays
    from flexmm.config import load_scene
    from flexmm.integrators.common import empty_terms
    from flexmm.models import MODELS

    scene = load_scene(LEGO, [f"lattice.n_units={n_units}"])
    system = MODELS[scene.lattice.kind].build(scene.lattice)
    terms = empty_terms()
    apply_excitation(system, scene, terms)
    damp = damping_arrays(system, scene, terms)
    keys = ("con_ij", "con_prm", "dash_ij", "dash_c", "drv_dof", "drv_mode", "drv_shape", "drv_prm")
    return system, tuple(terms[k] for k in keys), damp


def throughput(sizes=(1_000, 100_000, 1_000_000), threads=(1, 2), repeats: int = 7) -> list[dict]:
    """Unit-steps per second of velocity Verlet on the LEGO chain (compile excluded)."""
    import numba

    from flexmm.integrators import INTEGRATORS
    from flexmm.integrators.parallel import kernels

    spec = INTEGRATORS["velocity_verlet"]
    out = []
    for n in sizes:
        system, terms, damp = _chain(n)
        steps = max(20, int(3e7 / n))
        for th in threads:
            if th > numba.config.NUMBA_NUM_THREADS:
                continue
            advance, force, used = kernels(spec, system.force, th)
            q, v, f, acc = system.q0.copy(), system.v0.copy(), np.zeros(system.ndof), np.zeros(8)
            spec.init(force, system.args, q, v, 0.0, f, terms)
            advance(force, system.args, q, v, f, system.inv_mass, damp, terms, 0.0, 0.1, 2, acc)
            walls, cpus = [], []
            for _ in range(repeats):
                t0, c0 = time.perf_counter(), time.process_time()
                advance(force, system.args, q, v, f, system.inv_mass, damp, terms, 0.0, 0.1, steps, acc)
                walls.append(time.perf_counter() - t0)
                cpus.append(time.process_time() - c0)
            row = {"n_units": n, "threads": used, "steps": steps, "wall_min_s": min(walls),
                   "wall_median_s": float(np.median(walls)), "cpu_min_s": min(cpus),
                   "M_unit_steps_per_s": steps * n / min(walls) / 1e6,
                   "M_unit_steps_per_cpu_s": steps * n / min(cpus) / 1e6 * used,
                   "finite": bool(np.isfinite(q).all())}
            print(f"N = {n:>9,d}  threads {used}: {row['M_unit_steps_per_s']:7.1f} M unit-steps/s "
                  f"(wall, min of {repeats}; median {steps * n / row['wall_median_s'] / 1e6:.1f}); "
                  f"per CPU-second x threads {row['M_unit_steps_per_cpu_s']:.1f}")
            out.append(row)
    for n in sizes:
        one = [r for r in out if r["n_units"] == n and r["threads"] == 1]
        two = [r for r in out if r["n_units"] == n and r["threads"] == 2]
        if one and two:
            print(f"N = {n:>9,d}: two threads / one thread = {two[0]['M_unit_steps_per_s'] / one[0]['M_unit_steps_per_s']:.2f}x")
    return out


def memory(n_units: int = 1_000_000, duration_s: float = 0.01, n_frames: int = 11) -> dict:
    """Peak RSS of ``flexmm run`` on a 1e6-unit chain (a subprocess; streamed output)."""
    out_dir = RESULTS / "memory_run"
    cmd = [FLEXMM, "run", str(LEGO), "--quiet", "--fidelity", "full", "--out", str(out_dir),
           "--set", f"lattice.n_units={n_units}", "--set", f"solver.duration_s={duration_s}",
           "--set", f"output.n_frames={n_frames}"]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    peak_kib = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    size = (out_dir / "dataset.nc").stat().st_size if (out_dir / "dataset.nc").exists() else 0
    row = {"n_units": n_units, "duration_s": duration_s, "n_frames": n_frames, "exit_code": proc.returncode,
           "peak_rss_GiB": peak_kib / 2**20, "dataset_GiB": size / 2**30, "wall_s": wall,
           "stderr_tail": proc.stderr[-400:]}
    print(f"flexmm run, {n_units:,d} units, {n_frames} frames: exit {proc.returncode}, peak RSS "
          f"{row['peak_rss_GiB']:.2f} GiB, dataset {row['dataset_GiB']:.2f} GiB, {wall:.0f} s")
    return row


def sheet(target_error: float = 1e-6, repeats: int = 7) -> dict:
    """The 2D target: 40 x 20 sheet to t = 40 with final error ≤ 1e-6; cheapest method found."""
    from flexmm import workprecision as wp
    from flexmm.assemble import build_problem
    from flexmm.config import load_scene
    from flexmm.integrators import INTEGRATORS
    from flexmm.integrators.runner import integrate

    problem = build_problem(load_scene(ROOT / "configs" / "sheet_pulse.yaml"))
    ref = wp.reference(problem, 2)
    best = None
    for name in ("pefrl", "velocity_verlet", "rk4", "dopri5"):
        spec = INTEGRATORS[name]
        grid = ([("rtol", r, {"rtol": r, "atol": r * wp.ATOL_RATIO}) for r in (1e-5, 1e-6, 1e-7)] if spec.adaptive
                else [("dt_fraction", f, {"h": f * spec.stability_limit / problem.omega_max})
                      for f in np.geomspace(0.9, 0.01, 40)])
        for pname, value, kw in grid:
            tr = integrate(problem, name, n_frames=2, **kw)
            err = float(np.max(np.abs(tr.q[-1] - ref.q[-1]))) if tr.ok else np.inf
            if err <= target_error:
                walls, cpus = [], []
                for _ in range(repeats):
                    tr = integrate(problem, name, n_frames=2, **kw)
                    walls.append(tr.wall_s)
                    cpus.append(tr.cpu_s)
                row = {"method": name, pname: value, "final_error": err, "wall_min_ms": 1e3 * min(walls),
                       "cpu_min_ms": 1e3 * min(cpus), "force_evaluations": tr.counters["force_evaluations"]}
                print(f"sheet 40x20 to t = 40: {name} {pname} {value:.3g}: error {err:.2e}, "
                      f"{row['wall_min_ms']:.1f} ms wall (min of {repeats}), {row['cpu_min_ms']:.1f} ms CPU, "
                      f"{row['force_evaluations']} force evaluations")
                if best is None or row["wall_min_ms"] < best["wall_min_ms"]:
                    best = row
                break
    print(f"sheet target (< 20 ms at error ≤ {target_error:g}): best {best}")
    return best or {}


def workprecision() -> list[str]:
    """``flexmm bench`` on every config in benchmarks/configs (writes under benchmarks/results)."""
    done = []
    for cfg in sorted((ROOT / "configs").glob("*.yaml")):
        out = RESULTS / f"bench_{cfg.stem}"
        subprocess.run([FLEXMM, "bench", str(cfg), "--out", str(out)], check=False)
        done.append(str(out))
    return done


SECTIONS = {"throughput": throughput, "memory": memory, "sheet": sheet, "workprecision": workprecision}


def main(argv: list[str]) -> None:
    RESULTS.mkdir(exist_ok=True)
    names = argv or ["throughput", "memory", "sheet"]
    print(f"load average {os.getloadavg()}, {os.cpu_count()} CPUs")
    for name in names:
        result = SECTIONS[name]()
        (RESULTS / f"{name}.json").write_text(json.dumps(result, indent=1, default=str))


if __name__ == "__main__":
    main(sys.argv[1:])
