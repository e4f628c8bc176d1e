"""flexmm benchmarks: throughput, memory, the 2D target and work–precision (not timed tests).

    python benchmarks/run.py                  # startup + sweep + throughput + memory + sheet (minutes)
    python benchmarks/run.py startup          # one section: startup | sweep | throughput | bandwidth | memory
                                              #              | roofline | sheet_throughput | contention | sheet | workprecision
                                              #              | render | gradient | gradient_dashpots | gradient_splitting | gradient_midpoint
                                              #              | gradient_models
                                              #              | accuracy | demo_stages | signal_latency
    python benchmarks/run.py workprecision    # flexmm bench on benchmarks/configs/*.yaml (slow)

Every timing is the minimum and the median over repeats after a compile warm-up, with the load
average; thread/process CPU time is printed next to wall time because the machine may be shared
(CPU time excludes time spent descheduled). Results go to benchmarks/results/<section>.json
(git-ignored).
"""

from __future__ import annotations

import dataclasses
import json
import math
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


def _grade_all(system) -> None:
    """Vary every parameter of the hinges and sites by ±0.1 % along the chain (rest length and
    angle, half sizes, all stiffnesses): the fused kernel then streams nine parameter columns."""
    from flexmm.models.hinge import (
        H_HALF_A,
        H_HALF_B,
        H_KL,
        H_KS,
        H_KT,
        H_REST,
        S_KG,
        S_KR,
        S_THETA0,
    )

    x = 1e-3 * np.linspace(-1.0, 1.0, system.n_sites)
    for k in (H_REST, H_HALF_A, H_HALF_B, H_KL, H_KS, H_KT):
        system.args[2][:, k] *= 1.0 + x[:-1]
    system.args[3][:, S_THETA0] += x
    for k in (S_KG, S_KR):
        system.args[3][:, k] *= 1.0 + x


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
            "finite": bool(np.isfinite(q).all()), "kernel": advance.__name__, "walls_s": walls, "cpus_s": cpus}


def _load() -> str:
    """The load averages (1, 5, 15 min), printed with every timing: the machine may be shared."""
    return "load {:.2f} {:.2f} {:.2f}".format(*os.getloadavg())


def throughput(sizes=(1_000, 100_000, 1_000_000, 10_000_000), threads=(1, 2), repeats: int = 7,
               graded_sizes=(100_000, 1_000_000, 10_000_000)) -> list[dict]:
    """Unit-steps per second of velocity Verlet on the LEGO chain (compile excluded); uniform
    chains for ``sizes``, graded ones (``_grade``) for ``graded_sizes``. Each call advances
    max(20, 3e7/N) steps; the fused kernel's tables are prepared once per stepper, in its
    warm-up (``roofline`` prints their cost)."""
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
            row["M_unit_steps_per_s_median"] = rate * row["wall_min_s"] / row["wall_median_s"]
            row["load"] = os.getloadavg()
            print(f"N = {n:>10,d} {chain:7s} threads {row['threads']}: {rate:7.1f} M unit-steps/s (wall, min of "
                  f"{repeats}; median {row['M_unit_steps_per_s_median']:.1f}); per CPU-second x "
                  f"threads {row['M_unit_steps_per_cpu_s']:.1f} ({row['kernel']}; {_load()})")
            out.append(row)
        del system
    for n, chain in cases:
        rate = {r["threads"]: r["M_unit_steps_per_s"] for r in out if (r["n_units"], r["chain"]) == (n, chain)}
        if 1 in rate and 2 in rate:
            print(f"N = {n:>10,d} {chain:7s}: two threads / one thread = {rate[2] / rate[1]:.2f}x")
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
            walls, cpus = _time_triad(triad, a, b, c, repeats)
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


def _time_triad(triad, a, b, c, repeats: int) -> tuple[list, list]:
    """(wall, process CPU) seconds of ``repeats`` triads after a warm-up call."""
    triad(a, b, c, 0.5, 16)
    walls, cpus = [], []
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        triad(a, b, c, 0.5, 16)
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    return walls, cpus


def _triad_gbs(nbytes: float, repeats: int = 9) -> tuple[float, float, float]:
    """(best, median, best per CPU-second) GB/s of the triad, one thread, on three arrays of ``nbytes`` in all: the
    bandwidth of the memory level a working set of that size lives in."""
    import numba

    n = max(4096, int(nbytes / 24))
    triad = _triad_kernel()
    numba.set_num_threads(1)
    walls, cpus = _time_triad(triad, np.zeros(n), np.ones(n), np.ones(n), repeats)
    return 24 * n / min(walls) / 1e9, 24 * n / float(np.median(walls)) / 1e9, 24 * n / max(min(cpus), 1e-9) / 1e9


#: flops per unit-step of the fused chain kernel, counted from its loops (a fused multiply-add,
#: ``_jit.fma``, counts as two, as a multiply and an add): sincos 36 (17 of its 19 operations
#: fused), θ0 + θ 1, lateral hinges 1 (5 with lateral stretch), the hinge to the right 25 (6 of
#: 19 fused), the site's two hinges 3, kicks and drift 10
CHAIN_FLOPS = 76
#: flops per unit-step of velocity Verlet on the sheet: sincos 36, θ0 + θ 1, two hinges 2 × 29
#: (6 fused multiply-adds each), the sites' sums 12, kicks and drift 15
SHEET_FLOPS = 122


def _sheet_bytes(system) -> float:
    """Bytes per unit-step the fused sheet kernel (``verlet.sheet_verlet_advance_prepared``) moves
    when nothing stays in cache from one step to the next, counted from its sweep: q and v read
    and written 96, F written (and read for ownership) 48, θ0 8 (cos/sin live in a window of a
    block and a row: none); the two hinges' shear signs 2 (int8) when all hinges share their
    other parameters (``uniform_hinges``), else their table rows 112; the kicks 24 unless each
    field's masses are equal."""
    from flexmm.models.sheet_kernels import uniform_hinges

    uni = uniform_hinges(system.args.hinge_prm)
    n = system.n_sites
    kicks = system.inv_mass.reshape(3, n)
    same = all(np.all(row == row[0]) for row in kicks)
    return 96.0 + 48.0 + 8.0 + (2.0 if uni[0] == uni[0] else 112.0) + (0.0 if same else 24.0)


def _chain_bytes(system, damp, h: float = 0.1) -> float:
    """Bytes per unit-step of one sweep of the fused chain kernel: q and v read and written (64),
    plus 8 for each parameter or kick column it streams where that column varies (the tables of
    ``verlet_chain.prepare``; a uniform chain streams none). The memory roof is taken against
    these bytes, what a kernel sweeping the chain once per step moves; blocked in time
    (``verlet_chain.TIME_BLOCK`` steps per sweep), the kernel moves them once per time block
    (``roofline`` prints both)."""
    from flexmm.integrators.verlet_chain import BLOCK, prepare

    n = system.n_sites
    flag = prepare(system.args, system.inv_mass, damp, h)[3]
    sizes = np.minimum(BLOCK, n - BLOCK * np.arange(flag.shape[0]))
    return 64.0 + 8.0 * float((flag.sum(axis=1) * sizes).sum()) / n


def _time_block(steps: int) -> int:
    """Steps per sweep over memory of the fused chain kernel in calls of ``steps`` steps."""
    from flexmm.integrators.verlet_chain import TIME_BLOCK

    return min(steps, TIME_BLOCK)


def _prepare_s(system, damp, repeats: int = 5) -> float:
    """Seconds of the fused chain kernel's table preparation (``verlet_chain.prepare``): paid once
    per ``Stepper`` (and again only if h or the arrays change), not per call."""
    from flexmm.integrators.verlet_chain import prepare

    prepare(system.args, system.inv_mass, damp, 0.1)
    walls = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        prepare(system.args, system.inv_mass, damp, 0.1)
        walls.append(time.perf_counter() - t0)
    return min(walls)


def _sheet(n_rows: int, n_cols: int):
    """The sheet of configs/sheet_pulse.yaml (force pulse on its left column) at another size,
    built without the ω_max solve."""
    from flexmm.assemble import apply_excitation, damping_arrays
    from flexmm.config import load_scene
    from flexmm.integrators.common import Terms, empty_terms
    from flexmm.models import MODELS

    scene = load_scene(ROOT / "configs" / "sheet_pulse.yaml", [f"lattice.n_rows={n_rows}", f"lattice.n_cols={n_cols}"])
    system = MODELS[scene.lattice.kind].build(scene.lattice)
    terms = empty_terms()._asdict()
    apply_excitation(system, scene, terms)
    damp = damping_arrays(system, scene, terms)
    return system, Terms(**terms), damp


SHEET_SIZES = ((20, 40), (100, 100), (316, 316), (1000, 1000))


def _sheet_rate(n_rows: int, n_cols: int, repeats: int) -> dict:
    """Velocity Verlet (``verlet_advance`` with ``sheet_force``) on one thread, and the force alone."""
    from flexmm.integrators import INTEGRATORS

    system, terms, damp = _sheet(n_rows, n_cols)
    n = system.n_sites
    rng = np.random.default_rng(0)
    system.q0[:] = 0.01 * rng.standard_normal(system.ndof)  # a generic state (no sincos shortcut)
    row = _time_advance(INTEGRATORS["velocity_verlet"], system, terms, damp, 1, max(20, int(3e6 / n)), repeats)
    out = np.zeros(system.ndof)
    force = system.force
    force(system.q0, system.args, out)
    reps = max(3, int(1e6 / n))
    walls = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(reps):
            force(system.q0, system.args, out)
        walls.append((time.perf_counter() - t0) / reps)
    row.update(rows=n_rows, cols=n_cols, bytes_per_unit_step=_sheet_bytes(system),
               force_ns_per_unit=min(walls) / n * 1e9,
               force_ns_per_unit_median=float(np.median(walls)) / n * 1e9,
               M_unit_steps_per_s_median=row["M_unit_steps_per_s"] * row["wall_min_s"] / row["wall_median_s"])
    return row


def sheet_throughput(sizes=SHEET_SIZES, repeats: int = 7) -> list[dict]:
    """Unit-steps per second of velocity Verlet on the rotating-squares sheet (one thread; the
    force pulse of configs/sheet_pulse.yaml on the left column, a random initial state), and
    ns per unit of one force evaluation (called from Python, so the dispatch is included)."""
    out = []
    for r, c in sizes:
        row = _sheet_rate(r, c, repeats)
        print(f"sheet {r}x{c} ({row['n_units']:,d} units): {row['M_unit_steps_per_s']:6.1f} M unit-steps/s "
              f"(min of {repeats}; median {row['M_unit_steps_per_s_median']:.1f}); force "
              f"{row['force_ns_per_unit']:.2f} ns/unit (median {row['force_ns_per_unit_median']:.2f}) ({_load()})")
        out.append(row)
    return out


def network(sizes=((100, 100), (316, 316)), methods=("velocity_verlet", "pefrl"), repeats: int = 7) -> list[dict]:
    """The generic ligament kernel (``models.ligaments`` through the rigid_network kind) against the
    rotating-squares sheet's own kernels on the same geometry (θ0 = 0.2, a random state), one
    thread, each method's stepper for both models made once and advanced alternately (interleaved;
    the order flips each repeat): M unit-steps/s min and median and the network's share."""
    from flexmm.config import scene_from_dict
    from flexmm.integrators import INTEGRATORS
    from flexmm.integrators.common import empty_terms
    from flexmm.integrators.stepper import Stepper
    from flexmm.models import MODELS

    law = {"a_m": 0.01, "theta0_rad": 0.2, "k_long_n_per_m": 1e4, "k_shear_n_per_m": 3e3,
           "k_rot_n_m_per_rad": 2e-3, "areal_density_kg_m2": 20.0}
    out = []
    for rows, cols in sizes:
        steppers = {}
        for kind in ("rotating_squares_sheet", "rigid_network"):
            lat = scene_from_dict({"name": "b", "lattice": {"kind": kind, "n_rows": rows, "n_cols": cols, **law},
                                   "solver": {"duration_s": 1.0}}).lattice
            system = MODELS[kind].build(lat)
            system.q0[:] = 0.01 * np.random.default_rng(0).standard_normal(system.ndof)
            steppers[kind] = system
        n = rows * cols
        steps = max(10, int(2e6 / n))
        for method in methods:
            sts = {k: Stepper(INTEGRATORS[method], s, empty_terms(), np.zeros(s.ndof), 0.05, threads=1, check_energy=False)
                   for k, s in steppers.items()}
            walls = {k: [] for k in sts}
            for st in sts.values():
                st.warm_up()
            for r in range(repeats):
                for k in (list(sts) if r % 2 == 0 else list(sts)[::-1]):
                    w0 = sts[k].wall_s
                    sts[k].advance(steps)
                    walls[k].append(sts[k].wall_s - w0)
            rate = {k: steps * n / np.array(w) / 1e6 for k, w in walls.items()}
            row = {"rows": rows, "cols": cols, "method": method, "steps": steps,
                   **{f"{k}_M_unit_steps_per_s": float(v.max()) for k, v in rate.items()},
                   **{f"{k}_median": float(np.median(v)) for k, v in rate.items()},
                   "network_share_of_sheet": float(np.median(rate["rigid_network"] / rate["rotating_squares_sheet"])),
                   "kernels": {k: st.kernel.__name__ for k, st in sts.items()}}
            print(f"network {rows}x{cols} {method}: sheet {row['rotating_squares_sheet_M_unit_steps_per_s']:.1f} "
                  f"(median {row['rotating_squares_sheet_median']:.1f}), network "
                  f"{row['rigid_network_M_unit_steps_per_s']:.1f} (median {row['rigid_network_median']:.1f}) "
                  f"M unit-steps/s; network/sheet {row['network_share_of_sheet']:.2f} (median of paired repeats) "
                  f"[{row['kernels']['rotating_squares_sheet']} vs {row['kernels']['rigid_network']}] ({_load()})")
            out.append(row)
    return out


def roofline(sizes=(1_000, 10_000, 100_000, 1_000_000, 10_000_000), sheet_sizes=SHEET_SIZES,
             repeats: int = 5) -> list[dict]:
    """Bytes and flops per unit-step, achieved GB/s and GFLOP/s, against the triad bandwidth of
    a working set of the same size (one thread). Two roofs for the chain:

    - the sweep roof (the one the issue's targets are against): triad bandwidth over the bytes a
      kernel sweeping the chain once per step moves (``_chain_bytes``);
    - the time-blocked roof: over the bytes the fused kernel actually moves, once per
      ``TIME_BLOCK`` steps (about TIME_BLOCK times higher: the kernel is then bound by its
      arithmetic and the L2 cache, not by memory).

    Chains (uniform; graded: k_r varies, so its column is streamed; all graded: nine columns
    streamed, ``_grade_all``) with the fused Verlet kernel, and the sheet stepper. The fused
    kernels' table preparation is paid once per stepper (in its warm-up, not in the rates); it
    is printed in steps of the same chain."""
    from flexmm.integrators import INTEGRATORS

    spec = INTEGRATORS["velocity_verlet"]
    out = []

    def report(what, n, rate, rate_med, rate_cpu, nbytes, flops, extra="", blocked_bytes=None):
        bw, bw_med, bw_cpu = _triad_gbs(nbytes * n)
        roof, roof_cpu = bw * 1e9 / nbytes / 1e6, bw_cpu * 1e9 / nbytes / 1e6
        row = {"what": what, "n_units": n, "M_unit_steps_per_s": rate, "M_unit_steps_per_s_median": rate_med,
               "M_unit_steps_per_cpu_s": rate_cpu, "bytes_per_unit_step": nbytes, "flops_per_unit_step": flops,
               "triad_GB_s": bw, "triad_GB_s_median": bw_med, "triad_GB_per_cpu_s": bw_cpu,
               "memory_roof_M_per_s": roof, "fraction_of_roof": rate / roof,
               "fraction_of_roof_median": rate_med / roof,
               "fraction_of_roof_per_cpu_s": rate_cpu / roof_cpu, "load": os.getloadavg()}
        if blocked_bytes is not None:
            row.update(time_blocked_bytes_per_unit_step=blocked_bytes,
                       time_blocked_roof_M_per_s=bw * 1e9 / blocked_bytes / 1e6,
                       fraction_of_time_blocked_roof=rate * blocked_bytes / (bw * 1e3))
            extra = (f"; time-blocked traffic {blocked_bytes:.1f} B per unit-step -> roof "
                     f"{row['time_blocked_roof_M_per_s']:,.0f} M/s: {100 * row['fraction_of_time_blocked_roof']:.1f} %"
                     + extra)
        print(f"{what:18s} N = {n:>10,d}: {rate:6.1f} M/s (median {rate_med:6.1f}); {nbytes:5.0f} B, {flops} flop per "
              f"unit-step -> {rate * nbytes / 1e3:5.1f} GB/s, {rate * flops / 1e3:5.1f} GFLOP/s; triad {bw:5.1f} GB/s "
              f"(median {bw_med:.1f}) -> sweep roof {roof:6.0f} M/s: {100 * rate / roof:4.0f} % of it (median "
              f"{100 * rate_med / roof:.0f} %); per CPU-second {rate_cpu:6.1f} M/s against a triad of {bw_cpu:5.1f} "
              f"GB/s: {100 * rate_cpu / roof_cpu:4.0f} % of that roof{extra} ({_load()})")
        out.append(row)

    for n in sizes:
        for chain in ("uniform", "graded", "all graded"):
            system, terms, damp = _chain(n)
            if chain == "graded":
                _grade(system)
            elif chain == "all graded":
                _grade_all(system)
            steps = max(20, int(3e7 / n))
            row = _time_advance(spec, system, terms, damp, 1, steps, repeats)
            rate = row["M_unit_steps_per_s"]
            prep = _prepare_s(system, damp)
            step_s = row["wall_min_s"] / steps
            nbytes = _chain_bytes(system, damp)
            report(f"chain {chain}", n, rate, rate * row["wall_min_s"] / row["wall_median_s"],
                   row["M_unit_steps_per_cpu_s"], nbytes, CHAIN_FLOPS,
                   f"; table preparation once per stepper {1e3 * prep:.2f} ms = {prep / step_s:.2f} steps",
                   blocked_bytes=nbytes / _time_block(steps))
            del system
    for r, c in sheet_sizes:
        row = _sheet_rate(r, c, repeats)
        report("sheet Verlet", row["n_units"], row["M_unit_steps_per_s"], row["M_unit_steps_per_s_median"],
               row["M_unit_steps_per_cpu_s"], row["bytes_per_unit_step"], SHEET_FLOPS)
    return out


def _busy_loop() -> subprocess.Popen:
    """A competing process: one core's worth of busy loop."""
    return subprocess.Popen([sys.executable, "-c", "while True: pass"])


def contention(sizes=(100_000, 1_000_000), repeats: int = 15) -> list[dict]:
    """One thread against two on the fused chain kernel, without and beside a busy loop (another
    process holding a core): advances of the steppers alternate in a cycle, ``repeats`` each.
    Prints each stepper's best and median rate (wall and per CPU-second), the ratio of the
    medians, and the paired ratios (two-thread / one-thread advance of the same pair) as
    median [quartiles] (min-max), so "never slower" can be judged against the spread (and a
    sign test: how likely that many lost pairs are if neither stepper is slower); the
    two-thread stepper's calls by thread count in that phase (``AdaptiveThreads``), and what
    ``parallel.choose_threads`` picks. A second one-thread stepper runs in the same rotation as
    a control: its paired ratio to the first is the noise floor of the comparison. Note the
    machine's own load: other processes compete too."""
    from flexmm.integrators import INTEGRATORS
    from flexmm.integrators.parallel import choose_threads
    from flexmm.integrators.stepper import Stepper

    spec = INTEGRATORS["velocity_verlet"]
    out = []
    for n in sizes:
        system, terms, damp = _chain(n)
        steppers = {th: Stepper(spec, system, terms, damp, 0.1, threads=th, check_energy=False) for th in (1, 2)}
        steppers[0] = Stepper(spec, system, terms, damp, 0.1, threads=1, check_energy=False)  # the control
        for st in steppers.values():
            st.warm_up()
        steps = max(20, int(3e7 / n))
        for loaded in (False, True):
            busy = _busy_loop() if loaded else None
            try:
                time.sleep(0.5)
                auto = choose_threads(n)
                before = dict(getattr(steppers[2].kernel, "counts", {}))
                rates = {1: [], 2: [], 0: []}
                cpu_rates = {1: [], 2: [], 0: []}
                cycle = (1, 2, 0)
                for rep in range(repeats):
                    # none runs twice in a row (its state still in cache); the order rotates each
                    # round, so no stepper always follows the same one (a position in the cycle
                    # alone moved a stepper's rate by 1-3 %)
                    for th in cycle[rep % 3:] + cycle[: rep % 3]:
                        st = steppers[th]
                        w0, c0 = st.wall_s, st.cpu_s
                        st.advance(steps)
                        rates[th].append(n * steps / (st.wall_s - w0) / 1e6)
                        cpu_rates[th].append(n * steps / max(st.cpu_s - c0, 1e-9) / 1e6)
                load = _load()
            finally:
                if busy is not None:
                    busy.kill()
                    busy.wait()
            control = np.array(rates.pop(0)) / np.array(rates[1])
            cpu_rates.pop(0)
            c1, c2, c3 = (float(x) for x in np.percentile(control, [25, 50, 75]))
            med = {th: float(np.median(r)) for th, r in rates.items()}
            paired = np.array(rates[2]) / np.array(rates[1])
            q1, q2, q3 = (float(x) for x in np.percentile(paired, [25, 50, 75]))
            after = dict(getattr(steppers[2].kernel, "counts", {}))
            counts = {k: after.get(k, 0) - before.get(k, 0) for k in after}
            slower = int((paired < 1.0).sum())  # sign test: pairs where two threads lost, if equally likely
            p_slower = sum(math.comb(repeats, k) for k in range(slower, repeats + 1)) / 2.0**repeats
            verdict = ("not slower" if q2 >= 1.0 else f"slower (sign test p = {p_slower:.3f})" if p_slower < 0.05
                       else f"not slower beyond the noise (sign test p = {p_slower:.2f})")
            row = {"n_units": n, "competing_process": loaded, "auto_threads": auto, "calls_by_threads": counts,
                   **{f"threads{th}_best": max(r) for th, r in rates.items()},
                   **{f"threads{th}_median": m for th, m in med.items()},
                   **{f"threads{th}_per_cpu_s_best": max(r) for th, r in cpu_rates.items()},
                   "median_ratio": med[2] / med[1], "paired_ratio_median": q2, "paired_ratio_quartiles": (q1, q3),
                   "paired_ratio_range": (float(paired.min()), float(paired.max())), "pairs_lost": slower,
                   "sign_test_p": p_slower, "verdict": verdict, "control_paired_ratio_median": c2,
                   "control_paired_ratio_quartiles": (c1, c3),
                   "load": os.getloadavg(), "kernel2": steppers[2].kernel.__name__}
            print(f"N = {n:>9,d} {'beside a busy loop' if loaded else 'no busy loop      '}: one thread "
                  f"{max(rates[1]):6.1f} M/s best, {med[1]:6.1f} median ({max(cpu_rates[1]):.1f} per CPU-s); two-thread "
                  f"stepper {max(rates[2]):6.1f} best, {med[2]:6.1f} median ({max(cpu_rates[2]):.1f} per CPU-s); ratio of "
                  f"medians {med[2] / med[1]:.2f}x, paired {q2:.2f}x [{q1:.2f}, {q3:.2f}] ({paired.min():.2f}-"
                  f"{paired.max():.2f}), {repeats} pairs: {verdict}; control (another one-thread stepper) {c2:.2f}x [{c1:.2f}, "
                  f"{c3:.2f}]; its calls by threads {counts}; choose_threads -> "
                  f"{auto} ({load})")
            out.append(row)
        del system, steppers
    out.append(_kinetic_contention())
    return out


def _kinetic_contention(rows: int = 60, cols: int = 80, repeats: int = 41) -> dict:
    """The per-frame kinetic energy of a 14 400-DOF sheet: ``System.kinetic_energy`` (compiled,
    one thread) against ``np.dot`` (OpenBLAS, its threads), idle and beside a busy loop; median
    and worst of ``repeats`` calls in ms."""
    system, _, _ = _sheet(rows, cols)
    v = np.random.default_rng(1).standard_normal(system.ndof)
    mass = system.mass
    row = {"dofs": system.ndof}
    for loaded in (False, True):
        tag = "busy" if loaded else "idle"
        busy = _busy_loop() if loaded else None
        try:
            time.sleep(0.5 if loaded else 0.0)
            for name, fn in (("compiled", lambda: system.kinetic_energy(v)),
                             ("np.dot", lambda: 0.5 * float(np.dot(mass, v * v)))):
                fn()
                walls = []
                for _ in range(repeats):
                    t0 = time.perf_counter()
                    fn()
                    walls.append(time.perf_counter() - t0)
                row[f"{name}_{tag}_median_ms"] = 1e3 * float(np.median(walls))
                row[f"{name}_{tag}_worst_ms"] = 1e3 * max(walls)
            load = _load()
        finally:
            if busy is not None:
                busy.kill()
                busy.wait()
        print(f"kinetic energy, {system.ndof:,d} DOFs, {'beside a busy loop' if loaded else 'no busy loop'}: "
              f"System.kinetic_energy median {row[f'compiled_{tag}_median_ms']:.3f} ms (worst "
              f"{row[f'compiled_{tag}_worst_ms']:.3f}); np.dot median {row[f'np.dot_{tag}_median_ms']:.3f} ms "
              f"(worst {row[f'np.dot_{tag}_worst_ms']:.3f}) ({load})")
    return row


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
    from flexmm.diagnostics import workprecision as wp
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


#: the warm demo's stages, timed in a fresh interpreter (``demo_stages``): stage -> (module, attribute)
#: of the functions or methods whose time (less that of timed calls nested in them) counts for it
STAGE_FUNCS = {
    "plan": [("flexmm.plan", "make_plan")],
    "build": [("flexmm.assemble", "build_system")],
    "step bound": [("flexmm.stability", "omega_max"), ("flexmm.stability", "top_mode")],
    "pilot": [("flexmm.prepare", "_accuracy")],
    "integration": [("flexmm.integrators.stepper", "Stepper.advance"), ("flexmm.integrators.stepper", "Stepper.warm_up")],
    "frames": [("flexmm.controller", "_Observer.__init__"), ("flexmm.controller", "_Observer.frame"),
               ("flexmm.io.run_dataset", "DatasetWriter.close")],
    "checks": [("flexmm.integrators.stepper", "Stepper.failure"), ("flexmm.integrators.stepper", "Stepper.energies"),
               ("flexmm.controller", "_StepFollower.check")],
    "run (rest)": [("flexmm.controller", "run_problem")],
    "summary": [("flexmm.cli.run", "_print_summary")],
}
#: stages that keep the time of everything called inside them (the pilots' integration is the pilot's)
OPAQUE_STAGES = ("pilot", "summary")
STAGE_ORDER = ("start/exit", "imports", "plan", "build", "step bound", "pilot", "integration", "frames", "checks",
               "run (rest)", "summary", "cli (rest)")

#: the child of ``demo_stages``: ``flexmm run`` in this interpreter with the stage functions wrapped;
#: its clock starts at its first line (the interpreter's own start-up is the parent's wall time less this)
STAGES_CHILD = r"""
import time
T0, C0 = time.perf_counter(), time.process_time()  # C0: the interpreter's start-up CPU time
import importlib, json, sys
args = json.loads(sys.argv[1])
for m in ("flexmm.cli", "flexmm.cli.run", "flexmm.api") + tuple({m for fs in args["stages"].values() for m, _ in fs}):
    importlib.import_module(m)
totals = {"imports": time.perf_counter() - T0}
cpu = {"start/exit": C0, "imports": time.process_time() - C0}
stack = []

def timed(fn, stage):
    def wrapper(*a, **k):
        if any(s[0] in args["opaque"] for s in stack):
            return fn(*a, **k)
        t0, c0 = time.perf_counter(), time.process_time()
        stack.append([stage, 0.0, 0.0])
        try:
            return fn(*a, **k)
        finally:
            _, inner, inner_c = stack.pop()
            dt, dc = time.perf_counter() - t0, time.process_time() - c0
            totals[stage] = totals.get(stage, 0.0) + dt - inner
            cpu[stage] = cpu.get(stage, 0.0) + dc - inner_c
            if stack:
                stack[-1][1] += dt
                stack[-1][2] += dc
    return wrapper

for stage, funcs in args["stages"].items():
    for mod, attr in funcs:
        owner = sys.modules[mod]
        if "." in attr:  # a method: patch the class
            cls, name = attr.split(".")
            owner = getattr(owner, cls)
            setattr(owner, name, timed(getattr(owner, name), stage))
            continue
        fn = getattr(owner, attr)
        for m in list(sys.modules.values()):  # every module that imported it by name
            if getattr(m, attr, None) is fn:
                setattr(m, attr, timed(fn, stage))
from flexmm.cli import app
t0, c0 = time.perf_counter(), time.process_time()
try:
    app(["run", *args["argv"]], standalone_mode=False)
finally:
    end, cend = time.perf_counter(), time.process_time()
    totals["cli (rest)"] = (end - t0) - sum(v for k, v in totals.items() if k != "imports")
    cpu["cli (rest)"] = (cend - c0) - sum(v for k, v in cpu.items() if k not in ("imports", "start/exit"))
    print(json.dumps({"totals": totals, "cpu": cpu, "in_process_s": end - T0}), flush=True)
ending = getattr(sys.modules["flexmm.cli"], "_end", None)  # the console script's own way out, if the tree has one
if ending is not None:
    ending(0)
"""


def _stages_once(src: Path, out_dir: Path, extra: tuple[str, ...] = (), config: Path = LEGO,
                 env: dict | None = None) -> dict:
    """One warm ``flexmm run config`` (default the demo) in a fresh interpreter of tree ``src``:
    {stage: wall seconds}, {stage: CPU seconds of the process} (on a shared machine the CPU times
    are the steadier), wall and CPU time."""
    args = {"stages": STAGE_FUNCS, "opaque": OPAQUE_STAGES, "argv": [str(config), "--out", str(out_dir), *extra]}
    env = dict(env or os.environ, PYTHONPATH=str(src))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", STAGES_CHILD, json.dumps(args)], env=env, capture_output=True,
                          text=True, cwd=ROOT.parent)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if proc.returncode != 0:
        raise RuntimeError(f"demo_stages child failed ({proc.returncode}):\n{proc.stderr[-3000:]}")
    row = json.loads(proc.stdout.strip().splitlines()[-1])
    totals = row["totals"]
    totals["start/exit"] = wall - row["in_process_s"]
    row["cpu"]["start/exit"] = cpu - sum(v for k, v in row["cpu"].items() if k != "start/exit")
    printed = [ln for ln in proc.stdout.strip().splitlines()[:-1] if not ln.startswith("dataset: ")]
    return {"wall_s": wall, "cpu_s": cpu, "stages": totals, "stages_cpu": row["cpu"], "summary_text": printed}


def demo_stages(repeats: int = 7) -> list[dict]:
    """Where the warm demo's time goes (issue 37): ``flexmm run configs/lego_vector_soliton.yaml``
    with its printed summary, in fresh interpreters, numba's cache warm (one warm-up run first).

    Stages: the interpreter's start-up and exit (process wall and CPU time less what the child
    measured; the child ends as the tree's console script does), the
    imports of the run path (the CLI, ``flexmm.api`` and the modules below; an import made later,
    such as the analysis's during the summary, counts for its stage), plan (``make_plan``, less its
    builds), build (``build_system``), step bound (``omega_max``/``top_mode``), pilot (the accuracy
    pilots, with everything they call), integration (``Stepper.advance``/``warm_up``), frames (the
    observer and the dataset's writer), checks (the stepper's blow-up and energy checks, the
    stiffness tracker), the rest of ``run_problem``, the summary (``_print_summary``, with the
    imports it makes) and the rest of the CLI. Each stage's time excludes the timed calls nested
    in it; wall and CPU time of each. Minimum and median over ``repeats``; with ``$FLEXMM_BASELINE`` (a checkout of another
    commit, e.g. ``git worktree add /tmp/base main``) the two trees alternate run by run.
    """
    import tempfile

    trees = {"this": ROOT.parent / "src"}
    if os.environ.get(BASELINE_ENV):
        trees["base"] = Path(os.environ[BASELINE_ENV]) / "src"
    runs: dict[str, list[dict]] = {tag: [] for tag in trees}
    with tempfile.TemporaryDirectory(prefix="flexmm-bench-stages-") as tmp:
        for k in range(repeats + 1):
            for tag in (list(trees) if k % 2 == 0 else list(trees)[::-1]):
                row = _stages_once(trees[tag], Path(tmp) / tag)
                if k:  # the first round warms the numba cache and the file system
                    runs[tag].append(row)
    out = []
    for tag, rows in runs.items():
        print(f"warm demo stages, {tag} ({trees[tag]}), {repeats} runs; {_load()}")
        print(f"  {'stage':<12s} {'min s':>7s} {'median s':>9s}  {'CPU min s':>9s} {'CPU median s':>12s}")
        table = {}
        for stage in STAGE_ORDER:
            vals = [r["stages"].get(stage, 0.0) for r in rows]
            cpus = [r["stages_cpu"].get(stage, 0.0) for r in rows]
            table[stage] = {"min_s": min(vals), "median_s": float(np.median(vals)),
                            "cpu_min_s": min(cpus), "cpu_median_s": float(np.median(cpus))}
            print(f"  {stage:<12s} {min(vals):7.3f} {float(np.median(vals)):9.3f}  {min(cpus):9.3f} "
                  f"{float(np.median(cpus)):12.3f}")
        walls, cpus = [r["wall_s"] for r in rows], [r["cpu_s"] for r in rows]
        print(f"  {'end to end':<12s} {min(walls):7.3f} {float(np.median(walls)):9.3f}   "
              f"(process CPU time: min {min(cpus):.3f}, median {float(np.median(cpus)):.3f} s)")
        out.append({"tree": tag, "src": str(trees[tag]), "repeats": repeats, "stages": table,
                    "wall_min_s": min(walls), "wall_median_s": float(np.median(walls)),
                    "cpu_min_s": min(cpus), "cpu_median_s": float(np.median(cpus)), "runs": rows,
                    "load": os.getloadavg()})
    if len(runs) == 2 and runs["this"][0]["summary_text"] != runs["base"][0]["summary_text"]:
        print("  the two trees print different summaries:")
        for tag in runs:
            print("\n".join(f"    {tag}: {line}" for line in runs[tag][0]["summary_text"]))
    return out


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
                   "--workers", "1", "--quiet", "--keep", "all"]  # kept runs: their integration time is read back
            wall, _, code = _timed(cmd)
            if code != 0:
                raise RuntimeError(f"sweep failed ({code}): {' '.join(cmd)}")
            walls[n].append(wall)
            if n == points[-1]:
                for ds_path in d.glob("points/*/*/dataset.nc"):
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



#: the tiny scene of the sweep-scale benchmark: a 20-unit LEGO chain, 2 ms (about 1 ms of integration)
TINY_SWEEP = ["--set", "lattice.n_units=20", "--set", "solver.duration_s=0.002"]


def _child(cmd: list[str]) -> tuple[float, float, int]:
    """(wall s, peak resident MB, exit code) of one subprocess, its output discarded; the CPU
    seconds it and its worker processes used are in ``_child.cpu_s`` afterwards."""
    t0 = time.perf_counter()
    before = os.times()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    after = os.times()  # children's user + system time: the command and the workers it waited for
    _child.cpu_s = (after.children_user - before.children_user) + (after.children_system - before.children_system)
    return time.perf_counter() - t0, usage.ru_maxrss / 1024, proc.returncode


def _grid_spec(path: Path, n_points: int) -> Path:
    """A sweep file of n_points (a grid of n/1000 x 1000, or n x 1) on the tiny scene."""
    inner = 1000 if n_points >= 1000 else n_points
    path.write_text(
        f"base: {LEGO}\n"
        "set: {lattice.n_units: 20, solver.duration_s: 0.002}\n"
        "vary:\n  grid:\n"
        f"    excitation.velocity_m_s: {{start: 0.5, stop: 3, num: {n_points // inner}}}\n"
        f"    excitation.angular_velocity_rad_s: {{start: 10, stop: 300, num: {inner}}}\n")
    return path


def sweep_dask(sizes=(100, 500), workers: int = 2) -> dict:
    """Sweep throughput on a Dask LocalCluster of ``workers`` workers against one process and
    ``workers`` local processes (docs/sweeps.md, "Clusters").

    For two scenes — the tiny one of ``sweep_scale`` (20 units, 2 ms: the per-point overhead) and
    a medium one (2000 units, 50 ms, about 0.1 s of integration a point) — and each backend,
    ``flexmm sweep`` of ``sizes`` points (whole command) gives the wall and CPU time; the marginal
    rate between the two sizes takes start-up (spawning workers, starting the cluster) out.
    Report it with the load, which distorts wall times on a shared machine.
    """
    import shutil
    import tempfile

    scenes = {"tiny": (TINY_SWEEP, sizes),
              "medium": (["--set", "lattice.n_units=2000", "--set", "solver.duration_s=0.05"],
                         tuple(max(2, n // 10) for n in sizes))}
    backends = {"serial (1 process)": ["--workers", "1"],
                f"{workers} local processes": ["--workers", str(workers)],
                f"Dask LocalCluster, {workers} workers": ["--local-dask", "--workers", str(workers)]}
    root = Path(tempfile.mkdtemp(prefix="flexmm-bench-sweepdask-"))
    out: dict = {"load_before": os.getloadavg()[0], "rows": []}
    try:
        for scene, (args, ns) in scenes.items():
            for name, opts in backends.items():
                walls, cpus = {}, {}
                for n in ns:
                    d = root / f"{scene}-{len(out['rows'])}-{n}"
                    cmd = [FLEXMM, "sweep", str(LEGO), *args, "--vary", f"excitation.velocity_m_s=0.5:3:{n}",
                           "--out", str(d), "--quiet", *opts]
                    walls[n], _, code = _child(cmd)
                    cpus[n] = _child.cpu_s
                    shutil.rmtree(d, ignore_errors=True)
                few, many = ns
                row = {"scene": scene, "backend": name, "points": many, "wall_s": walls[many],
                       "points_per_s": many / walls[many],
                       "marginal_points_per_s": (many - few) / max(1e-9, walls[many] - walls[few]),
                       "marginal_cpu_ms_per_point": 1e3 * (cpus[many] - cpus[few]) / (many - few),
                       "exit": code, "load": os.getloadavg()[0]}
                out["rows"].append(row)
                print(f"{scene:6s} {name:32s} {many:5d} points: {walls[many]:6.1f} s, {row['points_per_s']:6.1f} "
                      f"points/s (marginal {row['marginal_points_per_s']:6.1f} points/s, "
                      f"{row['marginal_cpu_ms_per_point']:6.1f} ms CPU a point; exit {code}, load {row['load']:.1f})",
                      flush=True)
    finally:
        shutil.rmtree(root, ignore_errors=True)
    out["load_after"] = os.getloadavg()[0]
    return out


def sweep_scale(plan_sizes=(10_000, 100_000, 1_000_000), n_points: int = 10_000, workers: int = 2,
                resume_points: int = 100_000) -> dict:
    """Sweeps that outgrow one machine (issue 34): planning, points/s, bytes per point, resume.

    - planning: ``flexmm sweep SPEC --dry-run`` (the spec checked, every point listed with its
      state) of grids of ``plan_sizes`` points: wall time and peak memory of the process
      (targets: 10⁶ points in ≤ 10 s and ≤ 200 MB);
    - points/s: ``flexmm sweep`` of ``n_points`` points of the tiny scene on ``workers`` local
      processes (whole command: start-up, workers, the combined sweep.nc), and the marginal rate
      from a run of n_points/10 (start-up taken out); target ≥ 50 points/s on 2 cores;
    - bytes per point of the store (file sizes, and blocks allocated), target ≤ 2 KB;
    - resume: the same command again (nothing to run) and ``prepare`` on a store of
      ``resume_points`` points (read the status array, list what is pending), target ≤ 2 s.
    """
    import shutil
    import tempfile

    root = Path(tempfile.mkdtemp(prefix="flexmm-bench-sweepscale-"))
    out: dict = {"load_before": os.getloadavg()[0], "planning": [], "workers": workers}
    try:
        for n in plan_sizes:
            spec = _grid_spec(root / f"plan{n}.yaml", n)
            wall, mb, code = _child([FLEXMM, "sweep", str(spec), "--out", str(root / f"plan{n}"), "--dry-run"])
            out["planning"].append({"points": n, "wall_s": wall, "peak_mb": mb, "exit": code})
            print(f"plan + dry-run of {n:>9,d} points: {wall:6.2f} s, peak {mb:6.1f} MB (exit {code}, "
                  f"load {os.getloadavg()[0]:.2f})")
        rates, cpus = {}, {}
        for n in (max(2, n_points // 10), n_points):
            d = root / f"run{n}"
            cmd = [FLEXMM, "sweep", str(LEGO), *TINY_SWEEP, "--vary", f"excitation.velocity_m_s=0.5:3:{n}",
                   "--out", str(d), "--workers", str(workers), "--quiet"]
            wall, mb, code = _child(cmd)
            rates[n], cpus[n] = wall, _child.cpu_s
            print(f"sweep of {n:>6,d} tiny points on {workers} workers: {wall:7.2f} s, {n / wall:6.1f} points/s, "
                  f"{1e3 * cpus[n] / n:5.1f} ms CPU per point (whole command; exit {code}, "
                  f"load {os.getloadavg()[0]:.2f})")
        few, many = sorted(rates)
        out["sweep"] = {"points": many, "wall_s": rates[many], "points_per_s": many / rates[many],
                        "marginal_points_per_s": (many - few) / max(1e-9, rates[many] - rates[few]),
                        "cpu_s_per_point": cpus[many] / many,
                        "marginal_cpu_s_per_point": (cpus[many] - cpus[few]) / (many - few)}
        # on a shared machine the wall time depends on the load; the CPU time per point does not:
        # `workers` cores kept busy would run workers / marginal CPU s per point
        print(f"marginal rate (start-up taken out): {out['sweep']['marginal_points_per_s']:.1f} points/s; "
              f"{1e3 * out['sweep']['marginal_cpu_s_per_point']:.1f} ms CPU per point, i.e. "
              f"{workers / out['sweep']['marginal_cpu_s_per_point']:.1f} points/s on {workers} free cores")
        store = root / f"run{many}" / "store"
        files = [p for p in store.iterdir() if p.is_file()]
        out["bytes_per_point"] = sum(p.stat().st_size for p in files) / many
        out["allocated_bytes_per_point"] = sum(p.stat().st_blocks * 512 for p in files) / many
        print(f"store: {out['bytes_per_point']:.0f} bytes per point ({out['allocated_bytes_per_point']:.0f} allocated)")
        wall, _, code = _child(cmd)
        out["rerun_s"] = wall
        print(f"the same sweep again (all finished): {wall:.2f} s (exit {code})")
        out["resume_prepare_s"] = _resume_prepare(root, resume_points)
        print(f"resume of a {resume_points:,d}-point store (prepare: check, read the status array): "
              f"{out['resume_prepare_s']:.2f} s")
    finally:
        shutil.rmtree(root, ignore_errors=True)
    out["load_after"] = os.getloadavg()[0]
    return out


def _resume_prepare(root: Path, n: int) -> float:
    """Seconds ``prepare`` takes on a laid-out store of n points, 90 % finished."""
    from flexmm.sweep import load_sweep
    from flexmm.sweep.execute import prepare
    from flexmm.sweep.observe import OBSERVABLES

    spec = load_sweep(_grid_spec(root / "resume.yaml", n))
    plan = prepare(spec, root / "resume")
    plan.store.create_or_check(plan.fingerprint, n, list(OBSERVABLES), spec.name)
    status = np.lib.format.open_memmap(plan.store.dir / "status.npy", mode="r+")
    status[: n - n // 10] = 1
    status.flush()
    del status
    t0 = time.perf_counter()
    again = prepare(spec, root / "resume")
    wall = time.perf_counter() - t0
    assert len(again.tasks) == n // 10
    return wall


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


# ------------------------------------------------------------------ this tree against a baseline
#: environment variable naming a checkout of the commit to compare with (``compare``)
BASELINE_ENV = "FLEXMM_BASELINE"
COMPARE_CASES = ([("uniform", n) for n in (1_000, 100_000, 1_000_000, 10_000_000)]
                 + [("graded", n) for n in (100_000, 1_000_000, 10_000_000)]
                 + [("sheet", rc) for rc in SHEET_SIZES])


def _case(what: str, size, repeats: int) -> dict:
    """One contender's timings of one case, in a subprocess whose PYTHONPATH picks the tree: velocity
    Verlet on one thread (whatever kernel that tree picks); only APIs both trees have."""
    from flexmm.integrators import INTEGRATORS

    if what == "sheet":
        system, terms, damp = _sheet(*size)
        system.q0[:] = 0.01 * np.random.default_rng(0).standard_normal(system.ndof)
        steps = max(20, int(3e6 / system.n_sites))
    else:
        system, terms, damp = _chain(size)
        if what == "graded":
            _grade(system)
        steps = max(20, int(3e7 / size))
    return _time_advance(INTEGRATORS["velocity_verlet"], system, terms, damp, 1, steps, repeats)


def _in_tree(src: Path, *argv: str) -> dict:
    env = dict(os.environ, PYTHONPATH=str(src))
    out = subprocess.run([sys.executable, str(Path(__file__).resolve()), *argv], env=env, capture_output=True,
                         text=True, check=True, cwd=ROOT.parent)
    return json.loads(out.stdout.strip().splitlines()[-1])


def _forces(path: str) -> dict:
    """Forces of a graded LEGO chain (every parameter varies, several blocks) and of a 40 × 20
    sheet at a random state, and the state after 200 Verlet steps of each, into ``path`` (.npz)."""
    from flexmm.integrators import INTEGRATORS
    from flexmm.integrators.stepper import Stepper

    out = {}
    for name, (system, terms, damp) in (("chain", _chain(3 * 4096 + 77)), ("sheet", _sheet(20, 40))):
        if name == "chain":
            _grade_all(system)
        rng = np.random.default_rng(11)
        system.q0[:] = 0.05 * rng.standard_normal(system.ndof)
        f = np.zeros(system.ndof)
        system.force(system.q0, system.args, f)
        st = Stepper(INTEGRATORS["velocity_verlet"], system, terms, damp, 0.05, threads=1, check_energy=False)
        st.advance(200)
        out[f"{name}_force"], out[f"{name}_q200"] = f, st.q.copy()
    np.savez(path, **out)
    return {"path": path}


def compare(cases=COMPARE_CASES, rounds: int = 3, repeats: int = 3) -> list[dict]:
    """This tree against a baseline checkout (``$FLEXMM_BASELINE``, e.g. ``git worktree add
    /tmp/base e769862``), one thread: each case runs in fresh processes of either tree, the two
    alternating (ABBA over ``rounds``), ``repeats`` timed advances each; best and median of
    all. Also the forces and a 200-step trajectory of both trees on a graded chain and a sheet
    (max deviation, relative to the largest force or coordinate)."""
    base = os.environ.get(BASELINE_ENV)
    if not base:
        print(f"compare: set {BASELINE_ENV} to a checkout of the commit to compare with")
        return []
    trees = {"this": ROOT.parent / "src", "base": Path(base) / "src"}
    out = []
    with __import__("tempfile").TemporaryDirectory() as tmp:
        res = {tag: dict(np.load(_in_tree(src, "_forces", f"{tmp}/{tag}.npz")["path"])) for tag, src in trees.items()}
    for key in res["this"]:
        a, b = res["this"][key], res["base"][key]
        dev = float(np.max(np.abs(a - b)) / np.max(np.abs(b)))
        print(f"{key:12s}: max |this - base| / max |base| = {dev:.2e}")
        out.append({"what": key, "max_rel_deviation": dev})
    for what, size in cases:
        rates = {"this": [], "base": []}
        cpu = {"this": [], "base": []}
        n = None
        for rnd in range(rounds if size != 10_000_000 else 1):
            order = ("this", "base") if rnd % 2 == 0 else ("base", "this")
            for tag in order:
                row = _in_tree(trees[tag], "_case", json.dumps([what, size, repeats]))
                n = row["n_units"]
                rates[tag] += [row["steps"] * n / w / 1e6 for w in row["walls_s"]]
                cpu[tag] += [row["steps"] * n / c / 1e6 for c in row["cpus_s"]]
                rates[tag + "_kernel"] = row["kernel"]
        best = {tag: max(rates[tag]) for tag in trees}
        med = {tag: float(np.median(rates[tag])) for tag in trees}
        label = f"{what} {size[0]}x{size[1]}" if what == "sheet" else f"{what} N = {size:,d}"
        print(f"{label:24s} this {best['this']:6.1f} M unit-steps/s best, {med['this']:6.1f} median "
              f"({rates['this_kernel']}); base {best['base']:6.1f}, {med['base']:6.1f} ({rates['base_kernel']}): "
              f"{med['this'] / med['base']:.2f}x by medians; per CPU-second {max(cpu['this']):.1f} and "
              f"{max(cpu['base']):.1f} best ({len(rates['this'])} runs each; {_load()})")
        out.append({"what": what, "size": size, "n_units": n, "best": best, "median": med,
                    "best_per_cpu_s": {tag: max(cpu[tag]) for tag in trees},
                    "ratio_median": med["this"] / med["base"], "load": os.getloadavg()})
    return out


def _interleaved_all(runners, repeats: int) -> tuple[list, list]:
    """Wall and CPU seconds of runners called in turn, ``repeats`` rounds: (walls, cpus), a list
    per runner each."""
    wall: list[list] = [[] for _ in runners]
    cpu: list[list] = [[] for _ in runners]
    for _ in range(repeats):
        for k, runner in enumerate(runners):
            t0, c0 = time.perf_counter(), time.process_time()
            runner()
            wall[k].append(time.perf_counter() - t0)
            cpu[k].append(time.process_time() - c0)
    return wall, cpu


def _from_start(stepper, steps: int):
    """A runner of ``steps`` steps of ``stepper`` from its state now, restored before each call:
    every repeat takes the same run (a damped run continued call after call decays into the
    subnormal range, which is far slower on some processors)."""
    start = stepper.q.copy(), stepper.v.copy(), stepper.f.copy(), stepper.t

    def run():
        stepper.q[:], stepper.v[:], stepper.f[:] = start[:3]
        stepper.t = start[3]
        stepper.advance(steps)

    return run


def _interleaved(first, second, repeats: int) -> tuple[list, list, list, list]:
    """Wall and CPU seconds of two runners called alternately: (wall₁, wall₂, cpu₁, cpu₂)."""
    wall, cpu = _interleaved_all((first, second), repeats)
    return wall[0], wall[1], cpu[0], cpu[1]


def gradient(cases=((1_000, 4_000), (10_000, 1_000), (20_000, 1_000), (40_000, 500), (100, 1_000_000)), sheets=((40, 20, 3_000),),
             repeats: int = 5, compare_old: bool = True) -> list[dict]:
    """Cost of an exact gradient (flexmm.design: forward run with checkpoints, replay and reverse
    sweep) as a multiple of one forward run of the engine (the Stepper's velocity Verlet — the
    fused chain or sheet kernel — damped so both take the same scheme), interleaved in the same
    loop, by wall time and by process CPU time (the machine is shared); memory of the stored
    states and the peak traced by tracemalloc during the gradient. Chains: the LEGO impact chain
    (``cases``: units x steps); sheets: configs/sheet_pulse.yaml (``sheets``: rows x cols x
    steps). DifFlexMM's jax.grad on the same-size sheet: ``benchmarks/difflexmm.py`` (a separate
    JAX environment; JAX is not a flexmm dependency). ``compare_old``: also the previous path,
    interleaved (a uniform chain's column sweeps and column forward run: ``Trajectory``'s
    ``uniform_sweeps=False, engine_forward=False``; a uniform sheet's grid-column sweeps), where
    the default path differs from it.
    """
    import tracemalloc

    from flexmm.design.gradient import Trajectory, raw_of
    from flexmm.design.steps import CACHE_MB, UniformChain, UniformSheet
    from flexmm.design.tape import MEMORY_MB, chain_segment, tile_segment
    from flexmm.integrators import INTEGRATORS
    from flexmm.integrators.stepper import Stepper

    objective = _final_square_objective  # ½ Σ θ(T)²

    runs = [("chain", f"{n} units", _chain(n), steps) for n, steps in cases]
    runs += [("sheet", f"{r}x{c} sheet", _sheet(r, c), steps) for r, c, steps in sheets]
    rows = []
    for kind, label, (system, terms, damp), steps in runs:
        damp = damp + 0.01 * system.mass  # light damping: the engine's general Verlet kernel
        st = Stepper(INTEGRATORS["velocity_verlet"], system, terms, damp, 0.1, check_energy=False)
        st.warm_up()
        n_sites = system.n_sites
        obs = np.arange(system.ndof - n_sites, system.ndof)  # every θ, at the last step only
        traj = Trajectory(system.args, terms, 0.1, steps, steps, obs)
        raw = raw_of(system, terms, damp)
        old = dataclasses.replace(traj, uniform_sweeps=False, engine_forward=False)
        runners = [_from_start(st, steps), lambda: traj.gradient(raw, objective)]
        columns, form, path = traj.columns(raw), traj.form(raw), traj.steps(raw)
        uniform = isinstance(path, (UniformChain, UniformSheet))
        tiled = isinstance(path, UniformChain) and path._tiled(tile_segment(steps, system.ndof, MEMORY_MB))
        whole = dataclasses.replace(traj, tiles=False)
        if compare_old and (kind == "chain" or uniform):
            runners.append(lambda: old.gradient(raw, objective))
        if compare_old and tiled:
            runners.append(lambda: whole.gradient(raw, objective))
        for t in (traj, old) + ((whole,) if tiled else ()):
            small = dataclasses.replace(t, nsteps=4, stride=4)
            small.gradient(raw, objective)  # compile
            small.gradient(raw, objective, segment=2)
        walls, cpus = _interleaved_all(runners, repeats)
        fwd, grad, fwd_cpu, grad_cpu = walls[0], walls[1], cpus[0], cpus[1]
        fresh = dataclasses.replace(traj)  # no arrays kept from the gradients above (``_scratch_array``)
        tracemalloc.start()
        fresh.gradient(raw, objective)
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        n = system.ndof
        budget = min(MEMORY_MB, CACHE_MB) if columns else MEMORY_MB  # what Trajectory.gradient does by default
        keep_all = (steps + 1) * (3 * n + 1) * 8 <= budget * 1e6
        # the chain-column replay keeps (q, v) only; a uniform chain's also f and cos/sin of θ0+θ
        per_state = (4 if uniform and columns else 3 if not columns else 2) * n * 8
        seg = chain_segment(steps, n, per_state, MEMORY_MB) if columns else max(1, math.isqrt(steps))
        if tiled:  # checkpoints every TILE_STEPS steps; one window's states at a time
            seg = tile_segment(steps, n, MEMORY_MB)
            length = path.windows(seg)[1]
            per_state = 4 * 2 * length * 8
        if keep_all:
            stored = (steps + 1) * 3 * n * 8
        else:
            stored = (steps // seg + 1) * 3 * n * 8 + (seg + 1) * per_state
        row = {"model": kind, "size": label, "steps": steps, "load": os.getloadavg()[0],
               "forward_min_s": min(fwd), "forward_median_s": float(np.median(fwd)),
               "gradient_min_s": min(grad), "gradient_median_s": float(np.median(grad)),
               "ratio_min": min(grad) / min(fwd), "ratio_median": float(np.median(grad) / np.median(fwd)),
               "cpu_ratio_min": min(grad_cpu) / min(fwd_cpu),
               "cpu_ratio_median": float(np.median(grad_cpu) / np.median(fwd_cpu)),
               "sweeps": ("model's adjoint", "grid sheet columns", "chain columns")[form[0]]
               + (" (uniform)" if uniform else ""),
               "mode": "all states kept" if keep_all else f"checkpoints every {seg} steps"
               + (f", replayed in windows of {length} sites" if tiled else ""),
               "stored_MB": stored / 1e6, "traced_peak_MB": peak / 1e6,
               "all_states_MB": (steps + 1) * 3 * n * 8 / 1e6}
        print(f"  gradient, {label} x {steps} steps ({row['sweeps']} sweeps): forward {row['forward_min_s']:.3g} s, "
              f"gradient {row['gradient_min_s']:.3g} s (wall x{row['ratio_min']:.2f} min, x{row['ratio_median']:.2f} "
              f"median; CPU x{row['cpu_ratio_min']:.2f} min, x{row['cpu_ratio_median']:.2f} median; target <= 4; "
              f"load {row['load']:.1f}); {row['mode']}: {row['stored_MB']:.1f} MB, traced peak "
              f"{row['traced_peak_MB']:.1f} MB (all states would be {row['all_states_MB']:.0f} MB)")
        if tiled and compare_old:
            wh, wh_cpu = walls[3], cpus[3]
            row.update(whole_chain_min_s=min(wh), whole_chain_ratio_median=float(np.median(wh) / np.median(fwd)),
                       whole_chain_cpu_ratio_median=float(np.median(wh_cpu) / np.median(fwd_cpu)))
            print(f"    the same sweeps over the whole chain each step (no windows), interleaved: gradient {min(wh):.3g} s "
                  f"(wall x{row['whole_chain_ratio_median']:.2f} median; CPU x{row['whole_chain_cpu_ratio_median']:.2f} "
                  "median)")
        if len(runners) > 2:
            prev, prev_cpu = walls[2], cpus[2]
            row.update(previous_min_s=min(prev), previous_median_s=float(np.median(prev)),
                       previous_ratio_min=min(prev) / min(fwd), previous_ratio_median=float(np.median(prev) / np.median(fwd)),
                       previous_cpu_ratio_median=float(np.median(prev_cpu) / np.median(fwd_cpu)))
            print(f"    previous path (column sweeps, column forward; a sheet's grid columns), interleaved: gradient {min(prev):.3g} s (wall "
                  f"x{row['previous_ratio_min']:.2f} min, x{row['previous_ratio_median']:.2f} median; CPU "
                  f"x{row['previous_cpu_ratio_median']:.2f} median)")
        rows.append(row)
    print("  DifFlexMM (JAX) comparison: benchmarks/difflexmm.py (needs a separate JAX environment)")
    return rows


def gradient_dashpots(n: int = 1_000, steps: int = 4_000, repeats: int = 5) -> list[dict]:
    """Cost of an exact gradient through dashpots (velocity forces at the predicted velocity) on
    the LEGO impact chain with a dashpot between each pair of neighbours, lightly damped, against
    the engine's forward run of the same problem (its general Verlet kernel: velocity terms keep
    it off the fused chain kernel), from the same state each time; the gradient's default path
    (the general run keeping each state's G, the chain's column form in the reverse step) and the
    previous one (``column_sweeps=False``: the model's own adjoint kernel), and the same chain
    without dashpots (what the velocity terms add), interleaved, process CPU time (min and median
    of ``repeats``)."""
    from flexmm.design.gradient import Trajectory, raw_of
    from flexmm.integrators import INTEGRATORS
    from flexmm.integrators.stepper import Stepper

    system, terms, damp = _chain(n)
    damp = damp + 0.01 * system.mass
    idx = np.arange(n - 1, dtype=np.int64)
    cases = {"dashpots": terms._replace(dash_ij=np.stack([idx, idx + 1], axis=1), dash_c=np.full(n - 1, 0.02)),
             "without dashpots": terms}
    obs = np.arange(system.ndof - n, system.ndof)
    runners, labels = [], []
    for tag, tm in cases.items():
        st = Stepper(INTEGRATORS["velocity_verlet"], system, tm, damp, 0.1, check_energy=False)
        st.warm_up()
        raw = raw_of(system, tm, damp)
        paths = {"default": True, "previous (model's adjoint)": False} if tag == "dashpots" else {"default": True}
        runners.append(_from_start(st, steps))
        labels.append((tag, "engine"))
        for path, columns in paths.items():
            for seg in (None, 2):  # compile both reverse paths
                Trajectory(system.args, tm, 0.1, 4, 4, obs, column_sweeps=columns).gradient(raw, _final_square_objective,
                                                                                              segment=seg)
            traj = Trajectory(system.args, tm, 0.1, steps, steps, obs, column_sweeps=columns)
            runners.append(lambda traj=traj, raw=raw: traj.gradient(raw, _final_square_objective))
            labels.append((tag, path))
    _, cpus = _interleaved_all(runners, repeats)
    rows = []
    fwd = {}
    for (tag, path), cpu in zip(labels, cpus):
        if path == "engine":
            fwd[tag] = cpu
            continue
        f = fwd[tag]
        row = {"case": tag, "path": path, "n_units": n, "steps": steps, "load": os.getloadavg()[0],
               "forward_cpu_min_s": min(f), "forward_cpu_median_s": float(np.median(f)),
               "gradient_cpu_min_s": min(cpu), "gradient_cpu_median_s": float(np.median(cpu)),
               "ratio_min": min(cpu) / min(f), "ratio_median": float(np.median(cpu) / np.median(f))}
        print(f"  gradient, {n} units x {steps} steps, {tag}, {path} path: forward {min(f):.3g} s, gradient "
              f"{min(cpu):.3g} s CPU (x{row['ratio_min']:.2f} min, x{row['ratio_median']:.2f} median; "
              f"load {row['load']:.1f})")
        rows.append(row)
    extra = rows[0]["gradient_cpu_min_s"] / rows[-1]["gradient_cpu_min_s"]
    print(f"  the velocity terms make the gradient x{extra:.2f} (min CPU) of the same chain's without them")
    return rows


def _final_square_objective(rec, raw):
    """½ Σ q(T)² over the observed DOFs (θ of every unit, or every DOF; an ``Objective`` of
    ``design.gradient``). Summed elementwise, not by a BLAS dot product: on 20 000 entries and
    more OpenBLAS hands a dot product to its threads, which then spin-wait beside the gradient
    (~0.1 s of CPU time on a 20 000-unit chain, about a seventh of the gradient's)."""
    dq = np.zeros_like(rec.q)
    dq[-1] = rec.q[-1]
    return 0.5 * float(np.sum(rec.q[-1] * rec.q[-1])), dq, 0.0, 0.0, None


def _gradient_runs(cases, sheets):
    """(label, system, terms, damp, steps, observed rotations, raw) of the LEGO impact chains
    (``cases``: units x steps) and configs/sheet_pulse.yaml's sheets (rows x cols x steps),
    lightly damped (on-site 0.01 m)."""
    from flexmm.design.gradient import raw_of

    runs = [(f"{n} units", _chain(n), steps) for n, steps in cases]
    runs += [(f"{r}x{c} sheet", _sheet(r, c), steps) for r, c, steps in sheets]
    for label, (system, terms, damp), steps in runs:
        damp = damp + 0.01 * system.mass
        obs = np.arange(system.ndof - system.n_sites, system.ndof)
        yield label, system, terms, damp, steps, obs, raw_of(system, terms, damp)


def gradient_splitting(cases=((1_000, 1_000),), sheets=((40, 20, 300),), integrators=("pefrl", "blanes_moan6"),
                       repeats: int = 5) -> list[dict]:
    """Cost of an exact gradient through a splitting (``design.splitting``: forward run with its
    states and stage forces, reverse sweep reading them) as a multiple of one forward run of the
    engine's Stepper with the same integrator, interleaved, wall and CPU time. The LEGO impact
    chain (``cases``: units x steps) and the sheet of configs/sheet_pulse.yaml (rows x cols x
    steps), lightly damped (both take the exact damped kicks); h = 0.1."""
    from flexmm.design.gradient import Trajectory
    from flexmm.integrators import INTEGRATORS
    from flexmm.integrators.stepper import Stepper

    objective = _final_square_objective
    rows = []
    for label, system, terms, damp, steps, obs, raw in _gradient_runs(cases, sheets):
        for name in integrators:
            st = Stepper(INTEGRATORS[name], system, terms, damp, 0.1, check_energy=False)
            st.warm_up()
            traj = Trajectory(system.args, terms, 0.1, steps, steps, obs, integrator=name)
            Trajectory(system.args, terms, 0.1, 4, 4, obs, integrator=name).gradient(raw, objective)  # compile
            fwd, grad, fwd_cpu, grad_cpu = _interleaved(lambda: st.advance(steps),
                                                        lambda: traj.gradient(raw, objective), repeats)
            row = {"integrator": name, "size": label, "steps": steps, "load": os.getloadavg()[0],
                   "forward_min_s": min(fwd), "gradient_min_s": min(grad), "ratio_min": min(grad) / min(fwd),
                   "ratio_median": float(np.median(grad) / np.median(fwd)),
                   "cpu_ratio_min": min(grad_cpu) / min(fwd_cpu),
                   "cpu_ratio_median": float(np.median(grad_cpu) / np.median(fwd_cpu))}
            print(f"  gradient, {name}, {label} x {steps} steps: forward {row['forward_min_s']:.3g} s, gradient "
                  f"{row['gradient_min_s']:.3g} s (wall x{row['ratio_min']:.2f} min, x{row['ratio_median']:.2f} median; "
                  f"CPU x{row['cpu_ratio_min']:.2f} min, x{row['cpu_ratio_median']:.2f} median; {_load()})", flush=True)
            rows.append(row)
    return rows


def gradient_midpoint(cases=((1_000, 1_000),), sheets=((40, 20, 300),), repeats: int = 5) -> list[dict]:
    """Cost of an exact gradient through the implicit midpoint rule (``design.midpoint``: forward
    run with its Newton iteration to round-off, keeping every state, then one reverse sweep with
    one CG solve per step) as a multiple of one forward run of the engine's Stepper with
    ``implicit_midpoint`` (its adaptive Newton tolerance) from the same state; the tight forward
    run alone (``Trajectory.value``) is the third contender, interleaved; wall and CPU time. The
    runs of ``gradient_splitting`` (LEGO impact chain, configs/sheet_pulse.yaml's sheet, lightly
    damped), h = 0.1."""
    from functools import partial

    from flexmm.design.gradient import Trajectory
    from flexmm.integrators import INTEGRATORS
    from flexmm.integrators.common import Accumulators
    from flexmm.integrators.stepper import Stepper

    name, objective = "implicit_midpoint", _final_square_objective
    rows = []
    for label, system, terms, damp, steps, obs, raw in _gradient_runs(cases, sheets):
        st = Stepper(INTEGRATORS[name], system, terms, damp, 0.1, check_energy=False)
        st.warm_up()
        engine = _from_start(st, steps)  # (Newton's work depends on the state)
        traj = Trajectory(system.args, terms, 0.1, steps, steps, obs, integrator=name)
        Trajectory(system.args, terms, 0.1, 4, 4, obs, integrator=name).gradient(raw, objective)  # compile
        wall, cpu = _interleaved_all((engine, partial(traj.value, raw, objective),
                                      partial(traj.gradient, raw, objective)), repeats)
        fwd, tight, grad = (min(w) for w in wall)
        med = [float(np.median(w)) for w in wall]
        counts = Accumulators(st.acc).counters()
        row = {"integrator": name, "size": label, "steps": steps, "load": os.getloadavg()[0],
               "forward_min_s": fwd, "tight_forward_min_s": tight, "gradient_min_s": grad,
               "ratio_min": grad / fwd, "ratio_median": med[2] / med[0], "tight_ratio_median": med[1] / med[0],
               "cpu_ratio_min": min(cpu[2]) / min(cpu[0]),
               "cpu_ratio_median": float(np.median(cpu[2]) / np.median(cpu[0])), "engine_counters": counts}
        print(f"  gradient, {name}, {label} x {steps} steps: engine forward {fwd:.3g} s, tight forward {tight:.3g} s "
              f"(x{med[1] / med[0]:.2f} median), gradient {grad:.3g} s (wall x{row['ratio_min']:.2f} min, "
              f"x{row['ratio_median']:.2f} median; CPU x{row['cpu_ratio_min']:.2f} min, "
              f"x{row['cpu_ratio_median']:.2f} median; engine per step: "
              f"{counts['force_evaluations'] / counts['steps']:.1f} force evaluations; {_load()})", flush=True)
        rows.append(row)
    return rows


#: shipped scenes (configs/ unless a folder is given) of every model kind the general sweeps
#: differentiate, and of a chain with a striker (the impact-mitigation showcase's) (``gradient_models``)
MODEL_SCENES = ("c_buckled_beams_rarefaction", "fpu_second_harmonic_shaker", "hertz_granular_impact",
                "h_raney_transition_wave", "sine_gordon_breather", "f_slinky_friction_locomotion", "l_grid_guide",
                "j_magnets_transition_wave", "k_linkage_transition_wave", "predeformed_rarefaction_pull",
                "rotating_triangles_chain", "rotating_triangles_sheet", "designs/lego_impact_scene")


def gradient_models(names=MODEL_SCENES, steps: int = 2_000, repeats: int = 5) -> list[dict]:
    """Cost of an exact gradient on the shipped scenes of every other model kind (chains of
    masses with bistable, softening, polynomial, on-site and contact laws, ground friction, a
    spring network, magnet and linkage sheets, a loaded chain, rotating triangles; the general
    sweeps: ``sweeps.forward``, ``reverse`` with ``model_adjoint``) as a multiple of one forward
    run of the engine's Stepper on the same problem (the scene's h, ``steps`` steps or the
    scene's duration if shorter), interleaved; objective ½ Σ q(T)² over every DOF; wall and
    CPU time (min and median of ``repeats``)."""
    from flexmm.assemble import build_problem
    from flexmm.config import load_scene
    from flexmm.design.gradient import trajectory_of
    from flexmm.integrators.stepper import make_stepper

    rows = []
    for name in names:
        problem = build_problem(load_scene(ROOT.parent / ("" if "/" in name else "configs") / f"{name}.yaml"))
        n = min(steps, max(1, math.ceil(problem.duration / problem.dt - 1e-9)))
        st = make_stepper(problem, "velocity_verlet", threads=1, check_energy=False)
        engine = _from_start(st, n)
        traj, raw = trajectory_of(problem, n, stride=n, integrator="velocity_verlet")
        small, _ = trajectory_of(problem, 4, stride=4, integrator="velocity_verlet")
        small.gradient(raw, _final_square_objective)  # compile
        small.gradient(raw, _final_square_objective, segment=2)
        wall, cpu = _interleaved_all((engine, lambda traj=traj, raw=raw: traj.gradient(raw, _final_square_objective)),
                                     repeats)
        s = problem.system
        row = {"scene": name, "model": type(s.args).__name__, "ndof": s.ndof, "steps": n, "load": os.getloadavg()[0],
               "forward_min_s": min(wall[0]), "gradient_min_s": min(wall[1]),
               "ratio_min": min(wall[1]) / min(wall[0]), "ratio_median": float(np.median(wall[1]) / np.median(wall[0])),
               "cpu_ratio_min": min(cpu[1]) / min(cpu[0]),
               "cpu_ratio_median": float(np.median(cpu[1]) / np.median(cpu[0])),
               "sweeps": ("model's adjoint", "grid sheet columns", "chain columns")[traj.form(raw)[0]]}
        print(f"  gradient, {name} ({row['model']}, {s.ndof} DOFs) x {n} steps ({row['sweeps']}): forward "
              f"{row['forward_min_s']:.3g} s, gradient {row['gradient_min_s']:.3g} s (wall x{row['ratio_min']:.2f} min, "
              f"x{row['ratio_median']:.2f} median; CPU x{row['cpu_ratio_min']:.2f} min, x{row['cpu_ratio_median']:.2f} "
              f"median; load {row['load']:.1f})", flush=True)
        rows.append(row)
    return rows


def accuracy(names: tuple[str, ...] | None = None, repeats: int = 2, ref_factor: int = 16) -> list[dict]:
    """Issue 14: the default (solver.accuracy) against the old default, over the shipped scenes.

    For each configs/*.yaml (``names``: a subset by stem, or $FLEXMM_BENCH_SCENES, comma-separated):
    the whole ``run_scene`` pipeline (plan, pilots, run, writing; compile excluded by a warm-up
    run) with the new default and with the old one (velocity Verlet at the scene's dt_fraction —
    0.1 unless set — of the stable step at rest, ``solver.accuracy: null``), min and median wall
    of ``repeats`` runs, interleaved. Errors are those of the reported quantities (wave amplitudes
    and arrival times, ``accuracy.quantity_error``) over the window the estimate covers, of both
    against a converged reference (the new method at dt/``ref_factor``), next to the new run's own
    estimate. Target: new error ≤ its target at ≤ 1.5 x the old cost.
    """
    import tempfile

    from flexmm.accuracy import window_grid, quantity_error, trace
    from flexmm.api import run_scene
    from flexmm.assemble import build_problem
    from flexmm.config import load_scene
    from flexmm.integrators import INTEGRATORS
    from flexmm.io.run_dataset import open_run
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
                                   estimate=a.get("accuracy_estimate"), target=a.get("accuracy_requested"),
                                   window_s=a.get("accuracy_window_s"))
            for tag in walls:
                row[f"{tag}_wall_min_s"] = min(walls[tag])
                row[f"{tag}_wall_median_s"] = float(np.median(walls[tag]))
            row["cost_ratio"] = row["new_wall_min_s"] / row["old_wall_min_s"]
            if row.get("window_s"):  # errors over the estimate's window, on the planned (trimmed) scene
                plan = make_plan(new_scene, "auto")
                prob = prepare(plan)
                spec = INTEGRATORS[plan.scene.solver.integrator]
                old = build_problem(replace_section(plan.scene, "solver", integrator="velocity_verlet", dt_s=None,
                                                    accuracy=None, dt_fraction=old_scene.solver.dt_fraction))
                T = row["window_s"] / prob.system.scales.time_s
                n, S, T = window_grid(T, prob.dt)
                ref = trace(prob, spec, n * ref_factor, T, S)
                row["error_new"] = quantity_error(trace(prob, spec, n, T, S), ref).total
                n_old = S * max(1, math.ceil(T / (old.dt * S) - 1e-9))
                row["error_old"] = quantity_error(trace(old, INTEGRATORS["velocity_verlet"], n_old, T, S), ref).total
        except Exception as exc:  # a scene that cannot be measured is reported, not fatal
            row["error"] = f"{type(exc).__name__}: {exc}"
        nan = float("nan")
        print(f"  {row['scene']:38s} {row.get('integrator') or '?':17s} err new {row.get('error_new', nan):9.2e} "
              f"(est {row.get('estimate') or nan:8.2e}) old {row.get('error_old', nan):9.2e}  "
              f"wall new {row.get('new_wall_min_s', nan):7.3f} s old {row.get('old_wall_min_s', nan):7.3f} s "
              f"ratio {row.get('cost_ratio', nan):5.2f}  load {row['load']:.1f} {row.get('error', '')}", flush=True)
        rows.append(row)
    met = [r for r in rows if "cost_ratio" in r]
    over = [r["scene"] for r in met if r["cost_ratio"] > 1.5 or (r.get("error_new") or 0) > (r.get("target") or 1)]
    print(f"  {len(met)} scenes measured; not meeting (error <= target at <= 1.5 x cost): {', '.join(over) or 'none'}")
    return rows


def checkpoints(n_units: int = 1_000_000, steps: int = 400, n_frames: int = 21, every_s: float = 2.0) -> dict:
    """Checkpoint cost on a large chain (velocity Verlet, fused; frames of every 1000th site, so the
    stepping dominates): a run without checkpoints against one checkpointing every ``every_s`` s of
    wall time; the cost per checkpoint gives the overhead at the default cadence (one per
    ``checkpoint.DEFAULT_EVERY_S``). Also the checkpoint's size against the state (q, v: 16 bytes per
    DOF), and a resume's start-up: reading the newest checkpoint, rebuilding nothing, copying the
    frames and restoring the state (``run_problem(resume=...)`` of the finished run's checkpoint)."""
    dt_s = 1e-4
    return _checkpoint_cost(LEGO, [f"lattice.n_units={n_units}", "solver.accuracy=null", "solver.integrator=velocity_verlet",
                                   f"solver.dt_s={dt_s}", f"solver.duration_s={steps * dt_s}", f"output.n_frames={n_frames}",
                                   "output.site_stride=1000"], f"{n_units:,d}-unit chain", steps, every_s)


def checkpoints_sheet(n: int = 400, duration_s: float = 2e-3, n_frames: int = 21, every_s: float = 2.0) -> dict:
    """``checkpoints`` on an n × n rotating-squares sheet (the sheet scene with its default
    integrator and planned step, for ``duration_s``), frames of every 1000th site."""
    return _checkpoint_cost(ROOT.parent / "configs" / "a_sheet_sound_bullet.yaml",
                            [f"lattice.n_rows={n}", f"lattice.n_cols={n}", f"solver.duration_s={duration_s}",
                             f"output.n_frames={n_frames}", "output.site_stride=1000"], f"{n}x{n} sheet", None, every_s)


def _checkpoint_cost(config, overrides: list[str], label: str, steps: int, every_s: float) -> dict:
    import shutil
    import tempfile

    from flexmm import checkpoint as ck
    from flexmm.assemble import build_problem
    from flexmm.config import load_scene
    from flexmm.controller import run_problem

    scene = load_scene(config, overrides)
    problem = build_problem(scene)
    root = Path(tempfile.mkdtemp(prefix="flexmm-bench-ckpt-", dir=RESULTS))
    try:
        run_problem(problem, root / "warm")  # compile (or load) the kernel once
        t0 = time.perf_counter()
        plain = run_problem(problem, root / "plain")
        plain_s = time.perf_counter() - t0
        policy = ck.Checkpointing(root / "ckpt", every_s)
        t0 = time.perf_counter()
        run_problem(problem, root / "ckpt", checkpoints=policy)
        with_s = time.perf_counter() - t0
        per = policy.seconds / max(policy.count, 1)
        state = 16 * problem.system.ndof
        t0 = time.perf_counter()
        found, _ = ck.best([root / "ckpt"])
        read_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        run_problem(problem, root / "resumed", resume=found)  # resumes at the end: start-up and close only
        resume_s = time.perf_counter() - t0
    finally:
        shutil.rmtree(root, ignore_errors=True)
    row = {"lattice": label, "ndof": problem.system.ndof, "steps": steps or round(problem.duration / problem.dt),
           "run_s": plain_s,
           "run_with_checkpoints_s": with_s, "checkpoints": policy.count, "s_per_checkpoint": per,
           "overhead_default_cadence_pct": 100 * per / ck.DEFAULT_EVERY_S,
           "overhead_measured_pct": 100 * (with_s - plain_s) / plain_s, "every_s": every_s,
           "checkpoint_MiB": policy.bytes / 2**20, "size_over_state": policy.bytes / state,
           "read_checkpoint_s": read_s, "resume_startup_s": read_s + resume_s, "load": _load()}
    print(f"checkpoints, {label} ({problem.system.ndof:,d} DOFs): {per:.3f} s per checkpoint of "
          f"{row['checkpoint_MiB']:.1f} MiB ({row['size_over_state']:.2f} x q + v) -> {row['overhead_default_cadence_pct']:.2f} % "
          f"at one per {ck.DEFAULT_EVERY_S:g} s; measured {policy.count} in {with_s:.1f} s against {plain_s:.1f} s without "
          f"({row['overhead_measured_pct']:+.1f} %, every {every_s:g} s); resume start-up {row['resume_startup_s']:.2f} s "
          f"(reading {read_s:.2f} s) ({row['load']})")
    return row


SECTIONS = {"checkpoints": checkpoints, "checkpoints_sheet": checkpoints_sheet, "startup": startup, "sweep": sweep_overhead, "sweep_scale": sweep_scale, "sweep_dask": sweep_dask, "throughput": throughput, "bandwidth": bandwidth,
            "memory": memory, "sheet": sheet, "sheet_throughput": sheet_throughput, "roofline": roofline,
            "contention": contention, "compare": compare, "workprecision": workprecision, "render": render,
            "gradient": gradient, "gradient_dashpots": gradient_dashpots, "gradient_splitting": gradient_splitting,
            "gradient_midpoint": gradient_midpoint,
            "gradient_models": gradient_models, "accuracy": accuracy, "network": network,
            "demo_stages": demo_stages,
            "signal_latency": lambda: __import__("signal_latency").signal_latency()}


def main(argv: list[str]) -> None:
    if argv[:1] == ["_case"]:  # a contender of ``compare`` (its last line is the result)
        print(json.dumps(_case(*json.loads(argv[1]))))
        return
    if argv[:1] == ["_forces"]:
        print(json.dumps(_forces(argv[1])))
        return
    RESULTS.mkdir(exist_ok=True)
    names = argv or ["startup", "sweep", "throughput", "memory", "sheet"]
    print(f"load average {os.getloadavg()}, {os.cpu_count()} CPUs")
    for name in names:
        result = SECTIONS[name]()
        (RESULTS / f"{name}.json").write_text(json.dumps(result, indent=1, default=str))


if __name__ == "__main__":
    main(sys.argv[1:])
