"""flexmm benchmarks: throughput, memory, the 2D target and work–precision (not timed tests).

    python benchmarks/run.py                  # startup + sweep + throughput + memory + sheet (minutes)
    python benchmarks/run.py startup          # one section: startup | sweep | throughput | bandwidth | memory
                                              #              | sheet | workprecision | render | accuracy
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
    from flexmm.integrators.common import Terms, empty_terms
    from flexmm.models import MODELS

    scene = load_scene(LEGO, [f"lattice.n_units={n_units}"])
    system = MODELS[scene.lattice.kind].build(scene.lattice)
    terms = empty_terms()._asdict()
    apply_excitation(system, scene, terms)
    damp = damping_arrays(system, scene, terms)
    return system, Terms(**terms), damp


def _grade(system) -> None:
    """Vary the lateral torsional stiffness by ±0.1 % along the chain: not uniform, so the fused
    Verlet streams the parameter tables instead of keeping block-sized copies in cache."""
    from flexmm.models.hinge import S_KR

    system.args[3][:, S_KR] *= 1.0 + 1e-3 * np.linspace(-1.0, 1.0, system.n_sites)


def _time_advance(spec, system, terms, damp, threads: int, steps: int, repeats: int) -> dict:
    from flexmm.integrators.stepper import Stepper

    st = Stepper(spec, system, terms, damp, 0.1, threads=threads, check_energy=False)
    st.warm_up()
    walls, cpus = [], []
    for _ in range(repeats):
        w0, c0 = st.wall_s, st.cpu_s
        st.advance(steps)
        walls.append(st.wall_s - w0)
        cpus.append(st.cpu_s - c0)
    q, used, advance = st.q, st.threads, st.kernel
    n = system.n_sites
    return {"n_units": n, "threads": used, "steps": steps, "wall_min_s": min(walls),
            "wall_median_s": float(np.median(walls)), "cpu_min_s": min(cpus),
            "M_unit_steps_per_s": steps * n / min(walls) / 1e6,
            "M_unit_steps_per_cpu_s": steps * n / min(cpus) / 1e6 * used,
            "finite": bool(np.isfinite(q).all()), "kernel": advance.__name__}


def throughput(sizes=(1_000, 100_000, 1_000_000), threads=(1, 2), repeats: int = 7,
               graded_sizes=(100_000, 1_000_000)) -> list[dict]:
    """Unit-steps per second of velocity Verlet on the LEGO chain (compile excluded); uniform
    chains for ``sizes``, graded ones (``_grade``) for ``graded_sizes``."""
    import numba

    from flexmm.integrators import INTEGRATORS

    spec = INTEGRATORS["velocity_verlet"]
    out = []
    cases = [(n, "uniform") for n in sizes] + [(n, "graded") for n in graded_sizes]
    for n, chain in cases:
        system, terms, damp = _chain(n)
        if chain == "graded":
            _grade(system)
        for th in threads:
            if th > numba.config.NUMBA_NUM_THREADS:
                continue
            row = {"chain": chain, **_time_advance(spec, system, terms, damp, th, max(20, int(3e7 / n)), repeats)}
            rate = row["M_unit_steps_per_s"]
            print(f"N = {n:>9,d} {chain:7s} threads {row['threads']}: {rate:7.1f} M unit-steps/s (wall, min of "
                  f"{repeats}; median {rate * row['wall_min_s'] / row['wall_median_s']:.1f}); per CPU-second x "
                  f"threads {row['M_unit_steps_per_cpu_s']:.1f} ({row['kernel']})")
            out.append(row)
    for n, chain in cases:
        rate = {r["threads"]: r["M_unit_steps_per_s"] for r in out if (r["n_units"], r["chain"]) == (n, chain)}
        if 1 in rate and 2 in rate:
            print(f"N = {n:>9,d} {chain:7s}: two threads / one thread = {rate[2] / rate[1]:.2f}x")
    return out


def _triad_kernel():
    from flexmm._jit import jit, prange

    @jit
    def triad_block(a, b, c, s):
        for i in range(a.shape[0]):
            a[i] = b[i] + s * c[i]

    @jit(parallel=True)
    def triad(a, b, c, s, nb):
        n = a.shape[0]
        for k in prange(nb):
            lo, hi = k * n // nb, (k + 1) * n // nb
            triad_block(a[lo:hi], b[lo:hi], c[lo:hi], s)

    return triad


def bandwidth(sizes=(2_000_000, 16_000_000), threads=(1, 2), repeats: int = 15) -> list[dict]:
    """STREAM-like triad a = b + s c (24 bytes per element) on one and two threads.

    2e6 doubles (16 MiB per array) is the size of the state vector of a 1e6-unit chain; the
    ratio of the two-thread to the one-thread figure bounds the scaling of any kernel that is
    limited by memory traffic at that size.
    """
    import numba

    triad = _triad_kernel()
    out = []
    for n in sizes:
        rng = np.random.default_rng(0)
        a, b, c = rng.random(n), rng.random(n), rng.random(n)
        for th in threads:
            if th > numba.config.NUMBA_NUM_THREADS:
                continue
            numba.set_num_threads(th)
            triad(a, b, c, 0.5, 16)
            walls, cpus = [], []
            for _ in range(repeats):
                t0, c0 = time.perf_counter(), time.process_time()
                triad(a, b, c, 0.5, 16)
                walls.append(time.perf_counter() - t0)
                cpus.append(time.process_time() - c0)
            row = {"n": n, "threads": th, "GB_per_s": 24 * n / min(walls) / 1e9,
                   "GB_per_s_median": 24 * n / float(np.median(walls)) / 1e9, "cpu_over_wall": min(cpus) / min(walls)}
            print(f"triad {n:>11,d} doubles ({8 * n / 2**20:.0f} MiB/array), threads {th}: {row['GB_per_s']:6.1f} GB/s "
                  f"(max of {repeats}; median {row['GB_per_s_median']:.1f}; CPU/wall {row['cpu_over_wall']:.2f})")
            out.append(row)
    for n in sizes:
        r = {row["threads"]: row["GB_per_s"] for row in out if row["n"] == n}
        if 1 in r and 2 in r:
            print(f"triad {n:>11,d}: two threads / one thread = {r[2] / r[1]:.2f}x")
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

def _timed(cmd: list[str], env: dict | None = None) -> tuple[float, float, int]:
    """(wall s, CPU s of the child, exit code) of one subprocess run."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, proc.returncode


def _repeat(name: str, cmd: list[str], repeats: int, warmup: int = 1, env: dict | None = None,
            fresh_cache: bool = False) -> dict:
    """Min and median wall (and CPU) time of ``cmd`` over ``repeats`` runs after ``warmup`` runs;
    ``fresh_cache``: every run gets an empty numba cache directory (a first run after install)."""
    import tempfile

    walls, cpus, codes = [], [], []
    for k in range(warmup + repeats):
        run_env = dict(env or os.environ)
        tmp = tempfile.mkdtemp(prefix="flexmm-bench-cache-") if fresh_cache else None
        if tmp:
            run_env["NUMBA_CACHE_DIR"] = tmp
        wall, cpu, code = _timed(cmd, run_env)
        if tmp:
            subprocess.run(["rm", "-rf", tmp], check=False)
        if k >= warmup:
            walls.append(wall)
            cpus.append(cpu)
            codes.append(code)
    row = {"what": name, "repeats": repeats, "wall_min_s": min(walls), "wall_median_s": float(np.median(walls)),
           "cpu_min_s": min(cpus), "cpu_median_s": float(np.median(cpus)), "exit_codes": sorted(set(codes)),
           "load_after": os.getloadavg()[0]}
    print(f"{name:<44s} wall min {row['wall_min_s']:6.2f} s, median {row['wall_median_s']:6.2f} s; "
          f"CPU min {row['cpu_min_s']:6.2f} s (n = {repeats}, load {row['load_after']:.2f}, exit {row['exit_codes']})")
    return row


def startup(repeats: int = 7) -> list[dict]:
    """What a user waits for: --help, validate, the demo's second run, the first run after install.

    Whole processes (the console script), minimum and median of repeats after a warm-up run;
    the first run after install gets an empty numba cache each time (it compiles every kernel
    the demo needs). The load average is printed with each row: the machine may be shared.
    """
    out_dir = RESULTS / "startup_run"
    run = [FLEXMM, "run", str(LEGO), "--quiet", "--out", str(out_dir)]
    rows = [
        _repeat("flexmm --help", [FLEXMM, "--help"], repeats),
        _repeat("flexmm validate (demo)", [FLEXMM, "validate", str(LEGO)], repeats),
        _repeat("flexmm run (demo, cache warm)", run, repeats),
        _repeat("flexmm run (demo, first run: empty cache)", run, max(2, repeats // 3), warmup=0, fresh_cache=True),
    ]
    return rows


def sweep_overhead(points: tuple[int, int] = (2, 10), repeats: int = 3) -> dict:
    """Per-point cost of a sweep beyond integration: the slope of wall time against points.

    One worker process sweeps the demo's impact velocity over ``points`` (few and many points,
    fresh output directories, a warm numba cache); (W_many − W_few)/(many − few) is what one
    more point costs, and the integration time each point's dataset records is subtracted.
    """
    import tempfile

    import xarray as xr

    walls = {n: [] for n in points}
    integ = []
    for _ in range(repeats):
        for n in points:
            d = Path(tempfile.mkdtemp(prefix="flexmm-bench-sweep-"))
            cmd = [FLEXMM, "sweep", str(LEGO), "--vary", f"excitation.velocity_m_s=0.5:3:{n}", "--out", str(d),
                   "--workers", "1", "--quiet"]
            wall, _, code = _timed(cmd)
            if code != 0:
                raise RuntimeError(f"sweep failed ({code}): {' '.join(cmd)}")
            walls[n].append(wall)
            if n == points[-1]:
                for ds_path in d.glob("points/*/dataset.nc"):
                    with xr.open_dataset(ds_path) as ds:
                        integ.append(float(ds.attrs["wall_time_s"]))
            subprocess.run(["rm", "-rf", str(d)], check=False)
    few, many = points
    slope = (float(np.median(walls[many])) - float(np.median(walls[few]))) / (many - few)
    mean_integ = float(np.mean(integ)) if integ else float("nan")
    row = {"points": points, "wall_median_s": {n: float(np.median(w)) for n, w in walls.items()},
           "per_point_s": slope, "integration_per_point_s": mean_integ, "overhead_per_point_s": slope - mean_integ,
           "load": os.getloadavg()[0]}
    print(f"sweep of the demo, 1 worker: {few} points {row['wall_median_s'][few]:.2f} s, {many} points "
          f"{row['wall_median_s'][many]:.2f} s (medians of {repeats}): {slope:.3f} s per point, of which "
          f"integration {mean_integ:.3f} s: overhead {row['overhead_per_point_s']:.3f} s per point (load {row['load']:.2f})")
    return row



def render(repeats: int = 3, n_frames: int = 400) -> list[dict]:
    """``flexmm render`` speed on the 2D target (issue 20): 400 frames of the 40 x 20 sheet in < 30 s.

    The sheet of benchmarks/configs/sheet_pulse.yaml is run once with ``n_frames`` frames; the whole
    ``flexmm render`` process (start-up included) then writes a GIF (and an MP4 if ffmpeg is on
    PATH), without and with the space–time diagram. Frames per second from the minimum and the
    median wall time of ``repeats`` runs after a warm-up; the load average is printed with each row.
    """
    import shutil

    run_dir = RESULTS / "render_run"
    if not (run_dir / "dataset.nc").exists():
        subprocess.run([FLEXMM, "run", str(ROOT / "configs" / "sheet_pulse.yaml"), "--quiet", "--fidelity", "full",
                        "--out", str(run_dir), "--set", f"output.n_frames={n_frames}"], check=True,
                       capture_output=True)
    rows = []
    for suffix in (".gif", ".mp4") if shutil.which("ffmpeg") else (".gif",):
        for extra in ([], ["--spacetime"]):
            out = RESULTS / f"render{suffix}"
            cmd = [FLEXMM, "render", str(run_dir), "--out", str(out), "--quiet", *extra]
            name = f"render 40x20 sheet, {n_frames} frames {suffix} {' '.join(extra)}".rstrip()
            row = _repeat(name, cmd, repeats)
            row.update(frames=n_frames, fps_best=n_frames / row["wall_min_s"], fps_median=n_frames / row["wall_median_s"],
                       output_MB=out.stat().st_size / 1e6 if out.exists() else None)
            print(f"    -> {row['fps_best']:.1f} frames/s (min wall), {row['fps_median']:.1f} frames/s (median); "
                  f"{row['output_MB']:.1f} MB; target: {n_frames} frames < 30 s")
            rows.append(row)
    return rows


def accuracy(names: tuple[str, ...] | None = None, repeats: int = 2, ref_factor: int = 8) -> list[dict]:
    """Issue 14: the default (solver.accuracy) against today's default, over the shipped scenes.

    For each configs/*.yaml (``names``: a subset by stem, or $FLEXMM_BENCH_SCENES, comma-separated):
    the whole ``run_scene`` pipeline (plan, pilots, run, writing; compile excluded by a warm-up
    run) with the new default and with today's (main at e769862: velocity Verlet at the scene's
    dt_fraction — 0.1 unless set — of the stable step at rest, ``solver.accuracy: null``), min and
    median wall of ``repeats`` runs, interleaved. Errors are those of the final state (relative to
    each field's peak, ``accuracy.state_error``) of both against a converged reference: the new
    method at dt/``ref_factor``; the new run's own estimate (``accuracy_estimate``) next to its
    measured error. Target: new error ≤ its target at ≤ 1.5 x today's cost.
    """
    import tempfile

    from flexmm.accuracy import integrate, state_error
    from flexmm.api import run_scene
    from flexmm.assemble import build_problem
    from flexmm.config import load_scene
    from flexmm.integrators import INTEGRATORS
    from flexmm.io.dataset import open_run
    from flexmm.plan import make_plan
    from flexmm.plan.planner import replace_section
    from flexmm.prepare import prepare

    env = os.environ.get("FLEXMM_BENCH_SCENES")
    names = names or (tuple(env.split(",")) if env else None)
    paths = sorted((ROOT.parent / "configs").glob("*.yaml"))
    if names:
        paths = [p for p in paths if p.stem in names]
    rows = []
    tmp = Path(tempfile.mkdtemp(prefix="flexmm-acc-"))
    for path in paths:
        new_scene = load_scene(path)
        old_scene = load_scene(path, ["solver.accuracy=null"])
        row = {"scene": path.stem, "load": os.getloadavg()[0]}
        try:
            walls = {"new": [], "old": []}
            for k in range(repeats + 1):  # the first round compiles
                for tag, sc in (("new", new_scene), ("old", old_scene)):
                    t0 = time.perf_counter()
                    res = run_scene(sc, run_dir=tmp / f"{path.stem}-{tag}", fidelity="auto")
                    if k:
                        walls[tag].append(time.perf_counter() - t0)
                    row[f"{tag}_status"] = res.status
                    if tag == "new" and res.path is not None and res.path.exists():
                        a = open_run(res.path).attrs
                        row.update(integrator=a.get("integrator"), dt_new_s=a.get("dt_s"),
                                   estimate=a.get("accuracy_estimate"), target=a.get("accuracy_requested"))
            for tag in walls:
                row[f"{tag}_wall_min_s"] = min(walls[tag])
                row[f"{tag}_wall_median_s"] = float(np.median(walls[tag]))
            row["cost_ratio"] = row["new_wall_min_s"] / row["old_wall_min_s"]
            # errors of the final state against a converged reference, on the planned (trimmed) scene
            plan = make_plan(new_scene, "auto")
            prob = prepare(plan)
            spec = INTEGRATORS[plan.scene.solver.integrator]
            old = build_problem(replace_section(plan.scene, "solver", integrator="velocity_verlet", dt_s=None,
                                                accuracy=None, dt_fraction=old_scene.solver.dt_fraction))
            q_new, _, pk_new, _ = integrate(prob, spec, prob.dt, prob.duration)
            q_old, _, pk_old, _ = integrate(old, INTEGRATORS["velocity_verlet"], old.dt, old.duration)
            q_ref, _, pk_ref, _ = integrate(prob, spec, prob.dt / ref_factor, prob.duration)
            pk = np.maximum(pk_ref, np.maximum(pk_new, pk_old))
            row["error_new"] = state_error(prob.system, q_new, q_ref, pk)
            row["error_old"] = state_error(prob.system, q_old, q_ref, pk)
        except Exception as exc:  # a scene that cannot be measured is reported, not fatal
            row["error"] = f"{type(exc).__name__}: {exc}"
        print(f"  {row['scene']:38s} {row.get('integrator', '?'):15s} err new {row.get('error_new', float('nan')):9.2e} "
              f"(est {row.get('estimate') or float('nan'):8.2e}) old {row.get('error_old', float('nan')):9.2e}  "
              f"wall new {row.get('new_wall_min_s', float('nan')):7.3f} s old {row.get('old_wall_min_s', float('nan')):7.3f} s "
              f"ratio {row.get('cost_ratio', float('nan')):5.2f}  load {row['load']:.1f} {row.get('error', '')}", flush=True)
        rows.append(row)
    met = [r for r in rows if "cost_ratio" in r]
    over = [r["scene"] for r in met if r["cost_ratio"] > 1.5 or (r.get("error_new") or 0) > (r.get("target") or 1)]
    print(f"  {len(met)} scenes measured; not meeting (error <= target at <= 1.5 x cost): {', '.join(over) or 'none'}")
    return rows


SECTIONS = {"accuracy": accuracy, "startup": startup, "sweep": sweep_overhead, "throughput": throughput, "bandwidth": bandwidth, "memory": memory, "sheet": sheet,
            "workprecision": workprecision, "render": render}


def main(argv: list[str]) -> None:
    RESULTS.mkdir(exist_ok=True)
    names = argv or ["startup", "sweep", "throughput", "memory", "sheet"]
    print(f"load average {os.getloadavg()}, {os.cpu_count()} CPUs")
    for name in names:
        result = SECTIONS[name]()
        (RESULTS / f"{name}.json").write_text(json.dumps(result, indent=1, default=str))


if __name__ == "__main__":
    main(sys.argv[1:])
