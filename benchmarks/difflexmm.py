"""flexmm's exact gradient against DifFlexMM's ``jax.grad`` on the same 2D problem (issue 17).

    DIFFLEXMM_PYTHON=/tmp/jaxenv/bin/python DIFFLEXMM_SRC=/tmp/difflexmm python benchmarks/difflexmm.py
    python benchmarks/difflexmm.py --python /tmp/jaxenv/bin/python --src /tmp/difflexmm [--repeats 5] [--law difflexmm]

DifFlexMM (github.com/bertoldi-collab/DifFlexMM, JAX) is not a flexmm dependency: it runs in its
own Python environment (``$DIFFLEXMM_PYTHON``, with jax, jaxlib and jax-md installed) from its
source tree (``$DIFFLEXMM_SRC``); see benchmarks/README.md. Without them this script says so and
exits 0.

The problem (issue 4's 2D target, the sheet of DifFlexMM's own pulse example, sized 40 x 20): a
rotating-squares sheet of 40 columns x 20 rows, free edges, θ0 = 0.35, centre spacing 1, ligament
0.1, k_l = 1, k_s = 0.33, k_θ = 0.0075 per hinge (units: k_l, spacing, unit mass), unit mass 1
and rotational inertia a²/12 (a = 0.9/cos θ0, the squares' diagonal: the same numbers in both
codes), pushed along x on its left column by the force 0.02 r(t) sin(ω t), ω = 0.9935, with C²
smooth-step ramps up and down over T = 3.162 each (flexmm's one-cycle shaker burst at 500 Hz),
run to t = 40. Objective: the kinetic energy of the right half (columns 20–39) at t = 40;
gradient with respect to the k_θ of every hinge (1540). Each code builds the problem with its
own API (flexmm: a scene dict, ``assemble.build_problem``, ``design.gradient.Trajectory``;
DifFlexMM: ``RotatedSquareGeometry``, ``ligament_energy``, ``setup_dynamic_solver``).

Differences that remain between the two problems (stated, not removable through either API):
- the hinge law: DifFlexMM's ligament measures the bond's axial strain (L − L0)/L0, its shear as
  the angle between the bond and the reference rotated by the blocks' mean rotation (times L0),
  and k_θ on θ_B − θ_A; flexmm's hinge (docs/physics.md §1.2) is two springs between the hinge
  points (stretch along the hinge axis, shear across it, ℓ cancelling) and k_θ on the staggered
  rotations. They agree to leading order in the motion; the objective values are printed side
  by side, and the two per-hinge gradient fields are compared. With ``--law difflexmm`` flexmm runs
  the same squares as a ``rigid_network`` with DifFlexMM's ligament law (docs/physics.md §1.9), and
  this difference is gone: the converged objectives and gradient fields then measure agreement;
- the integrator: DifFlexMM integrates with ``jax.experimental.ode.odeint`` (adaptive
  Dormand–Prince, rtol = atol = 1e-8 by default) and ``jax.grad`` differentiates it by the
  continuous adjoint (a second adaptive solve backwards of the augmented system); flexmm runs
  velocity Verlet at a fixed step and its gradient is the exact discrete adjoint of that run.
  Each code's objective error is measured against its own tightly converged run (DifFlexMM at
  rtol = atol = 1e-11, flexmm at a quarter of the smallest step); flexmm is timed at the largest
  step of the ladder whose error is at most DifFlexMM's, and at its plain step h = 0.05;
- threads: JAX uses every core it is given, flexmm's numba kernels as configured (the CPU times
  are printed next to the walls).

Each code runs in a persistent worker process (so its peak RSS is its own); forward and gradient
calls alternate between the two workers (min and median of ``--repeats`` each, compile excluded),
with the load average. Memory: each worker's peak RSS after its forward runs and after its
gradients, and for flexmm the peak traced by tracemalloc during one gradient.
"""

from __future__ import annotations

import json
import math
import os
import resource
import subprocess
import sys
import time

N_ROWS, N_COLS = 20, 40
THETA0 = 0.35
SPACING, LIGAMENT = 1.0, 0.1
K_L, K_S, K_ROT = 1.0, 0.33, 0.0075
AMP, FREQ_HZ, T_UNIT_S = 0.02, 500.0, math.sqrt(1e-3 / 1e4)  # flexmm's SI scene: m = 1 g, k_l = 1e4 N/m
OMEGA = 2 * math.pi * FREQ_HZ * T_UNIT_S
T_RAMP = 0.5 / FREQ_HZ / T_UNIT_S
T_STOP = 1.0 / FREQ_HZ / T_UNIT_S
DURATION = 40.0
A_DIAG = (SPACING - LIGAMENT) / math.cos(THETA0)  # diagonal of a square: hinge points at ±a/2
INERTIA = A_DIAG**2 / 12
REGION_COLS = range(N_COLS // 2, N_COLS)
STEPS_LADDER = (0.1, 0.05, 0.025, 0.0125, 0.00625, 0.003125)


def _rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _timed(fn):
    w, c = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.perf_counter() - w, time.process_time() - c


def _region_blocks() -> list[int]:
    return [r * N_COLS + c for r in range(N_ROWS) for c in REGION_COLS]


# ------------------------------------------------------------------ DifFlexMM worker (JAX env)
def difflexmm_worker(src: str) -> None:
    sys.path.insert(0, src)
    import jax
    import jax.numpy as jnp
    from jax import config

    config.update("jax_enable_x64", True)
    from difflexmm.dynamics import setup_dynamic_solver
    from difflexmm.energy import build_strain_energy, ligament_energy
    from difflexmm.geometry import RotatedSquareGeometry
    from difflexmm.utils import (
        ControlParams,
        GeometricalParams,
        LigamentParams,
        MechanicalParams,
    )

    geom = RotatedSquareGeometry(n1_cells=N_COLS // 2, n2_cells=N_ROWS // 2, spacing=SPACING, bond_length=LIGAMENT)
    centroids, node_vectors, connectivity, reference = geom.get_parametrization()
    energy = build_strain_energy(bond_connectivity=connectivity(), bond_energy_fn=ligament_energy)
    loaded = jnp.array([[geom.n1_blocks * r, 0] for r in range(geom.n2_blocks)])

    def smoothstep(x):
        x = jnp.clip(x, 0.0, 1.0)
        return x**3 * (10.0 + x * (-15.0 + 6.0 * x))

    def force(state, t):  # flexmm's harmonic drive with its ramps (integrators.common.waveform)
        r = smoothstep(t / T_RAMP) * smoothstep((T_STOP - t) / T_RAMP)
        return AMP * r * jnp.sin(OMEGA * t) * jnp.ones(geom.n2_blocks)

    inertia = jnp.tile(jnp.array([1.0, 1.0, INERTIA]), (geom.n_blocks, 1))
    region = jnp.array(_region_blocks())
    times = jnp.array([0.0, DURATION])
    state0 = jnp.zeros((2, geom.n_blocks, 3))
    n_bonds = int(connectivity().shape[0])

    def make(tol):
        solve = setup_dynamic_solver(geometry=geom, energy_fn=energy, loaded_block_DOF_pairs=loaded,
                                     loading_fn=force, rtol=tol, atol=tol)

        def objective(k_rot):
            params = ControlParams(
                geometrical_params=GeometricalParams(block_centroids=centroids(THETA0),
                                                     centroid_node_vectors=node_vectors(THETA0)),
                mechanical_params=MechanicalParams(
                    bond_params=LigamentParams(k_stretch=K_L, k_shear=K_S, k_rot=k_rot, reference_vector=reference()),
                    density=1.0, inertia=inertia))
            vel = solve(state0, times, params)[-1, 1]
            return 0.5 * jnp.sum(inertia[region] * vel[region] ** 2)

        return jax.jit(objective), jax.jit(jax.grad(objective))

    k0 = jnp.full((n_bonds,), K_ROT)
    fwd, grad = make(1e-8)
    _serve(lambda: float(fwd(k0).block_until_ready()), lambda: grad(k0).block_until_ready().tolist(),
           lambda: float(make(1e-11)[0](k0)), {"n_hinges": n_bonds, "n_blocks": geom.n_blocks,
                                                "jax": jax.__version__, "threads": os.cpu_count()})


# ------------------------------------------------------------------ flexmm worker
def flexmm_scene(law: str = "sheet") -> dict:
    """The problem as a flexmm scene (SI: spacing 1 cm, unit mass 1 g, k_l = 1e4 N/m): the
    rotating-squares sheet with its hinge law (``law="sheet"``), or the rigid-unit network of the
    same squares with DifFlexMM's own ligament law (``law="difflexmm"``: the same geometry — unit
    (r, c) turned by (−1)^(r+c) θ0, vertices right, top, left, bottom, ligaments from the right
    vertex to the neighbour's left one and from the top to the bottom one, rest bond ℓ along x or
    y — the same law, masses and drive as DifFlexMM's problem)."""
    a_unit = 0.01  # m per spacing
    kl = 1e4
    law_fields = {"kind": "rotating_squares_sheet", "mass_kg": 1e-3, "inertia_kg_m2": 1e-3 * INERTIA * a_unit**2}
    if law != "sheet":  # a square of diagonal a has mass ρa²/2 and polar inertia m a²/12 = INERTIA
        law_fields = {"kind": "rigid_network", "ligament_law": law,
                      "areal_density_kg_m2": 1e-3 / (0.5 * (A_DIAG * a_unit) ** 2)}
    return {"name": "difflexmm_pulse", "lattice": {
        **law_fields, "n_rows": N_ROWS, "n_cols": N_COLS,
        "a_m": A_DIAG * a_unit, "ligament_length_m": LIGAMENT * a_unit, "theta0_rad": THETA0,
        "k_long_n_per_m": K_L * kl, "k_shear_n_per_m": K_S * kl, "k_rot_n_m_per_rad": K_ROT * kl * a_unit**2,
        "left": "driven"},
        "excitation": {"kind": "shaker", "end": "left", "frequency_hz": FREQ_HZ, "amplitude_n": AMP * kl * a_unit,
                       "ramp_cycles": 0.5, "duration_s": 1.0 / FREQ_HZ},
        "solver": {"duration_s": DURATION * T_UNIT_S}}


def flexmm_worker(law: str = "sheet") -> None:
    import tracemalloc

    import numpy as np

    from flexmm.assemble import build_problem
    from flexmm.config import scene_from_dict
    from flexmm.design.gradient import Trajectory, raw_of
    from flexmm.models.hinge import H_KT
    from flexmm.models.ligaments import L_KT

    problem = build_problem(scene_from_dict(flexmm_scene(law)))
    k_column = H_KT if law == "sheet" else L_KT
    s = problem.system
    sc = s.scales
    blocks = _region_blocks()
    obs = np.array([s.dof(f.name, b) for f in s.fields for b in blocks])
    mass = s.mass[obs]
    raw = raw_of(s, problem.terms, problem.damp)
    e_unit = 1e4 * 0.01**2  # DifFlexMM's energy unit k_l · spacing² (J)
    step = {"h": 0.05}

    def traj(h):  # h in DifFlexMM's time unit sqrt(m/k_l): flexmm's is the same (m = 1 g, k_l = 1e4 N/m)
        n = max(1, round(DURATION / h))
        return Trajectory(s.args, problem.terms, DURATION * T_UNIT_S / sc.time_s / n, n, n, obs)

    def objective(rec, raw):
        dv = np.zeros_like(rec.v)
        dv[-1] = mass * rec.v[-1]
        return 0.5 * float(mass @ rec.v[-1] ** 2), 0.0, dv, 0.0, None

    def value(h):
        return traj(h).value(raw, objective) * sc.energy / e_unit

    def gradient():
        _, g, _ = traj(step["h"]).gradient(raw, objective)
        return g.t1[:, k_column].tolist()  # dJ/dk_θ: J and k_θ share the energy unit, so the ratio is unit-free

    def memory():
        tracemalloc.start()
        traj(step["h"]).gradient(raw, objective)
        peak = tracemalloc.get_traced_memory()[1] / 1e6
        tracemalloc.stop()
        return peak

    traj(0.5).gradient(raw, objective)  # compile
    extra = {"n_hinges": int(raw.t1.shape[0]), "n_blocks": s.n_sites}
    _serve(lambda: value(step["h"]), gradient, lambda: value(STEPS_LADDER[-1] / 4), extra,
           ladder=lambda: {str(h): value(h) for h in STEPS_LADDER}, set_step=step, memory=memory)


def _serve(forward, gradient, reference, info, ladder=None, set_step=None, memory=None) -> None:
    """Answer JSON commands on stdin, one JSON line each on stdout."""
    out = sys.stdout
    sys.stdout = sys.stderr  # library chatter must not corrupt the protocol
    out.write(json.dumps({"ready": True, "rss_mb": _rss_mb(), **info}) + "\n")
    out.flush()
    for line in sys.stdin:
        cmd = json.loads(line)
        op = cmd["op"]
        if op == "forward":
            val, wall, cpu = _timed(forward)
            reply = {"value": val, "wall": wall, "cpu": cpu, "rss_mb": _rss_mb()}
        elif op == "gradient":
            val, wall, cpu = _timed(gradient)
            reply = {"grad": val, "wall": wall, "cpu": cpu, "rss_mb": _rss_mb()}
        elif op == "reference":
            reply = {"value": reference()}
        elif op == "ladder":
            reply = {"values": ladder()}
        elif op == "step":
            set_step["h"] = cmd["h"]
            reply = {"h": cmd["h"]}
        elif op == "memory":
            reply = {"traced_mb": memory() if memory else None, "rss_mb": _rss_mb()}
        else:
            break
        out.write(json.dumps(reply) + "\n")
        out.flush()


# ------------------------------------------------------------------ orchestrator
class Worker:
    def __init__(self, argv: list[str], env: dict | None = None):
        self.proc = subprocess.Popen(argv, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env)
        self.info = self._read()

    def _read(self) -> dict:
        line = self.proc.stdout.readline()
        if not line:
            raise RuntimeError(f"worker {self.proc.args[:3]} exited (code {self.proc.wait()})")
        return json.loads(line)

    def __call__(self, op: str, **kw) -> dict:
        self.proc.stdin.write(json.dumps({"op": op, **kw}) + "\n")
        self.proc.stdin.flush()
        return self._read()

    def close(self) -> None:
        self.proc.stdin.write('{"op": "quit"}\n')
        self.proc.stdin.close()
        self.proc.wait()


def _stats(xs: list[float]) -> tuple[float, float]:
    xs = sorted(xs)
    return xs[0], xs[len(xs) // 2] if len(xs) % 2 else 0.5 * (xs[len(xs) // 2 - 1] + xs[len(xs) // 2])


def _compare_fields(a: list[float], b: list[float]) -> dict:
    """The two per-hinge gradient fields: their sums (the derivative along a uniform change of
    every k_θ), cosine and relative L2 difference."""
    import numpy as np

    a, b = np.asarray(a), np.asarray(b)
    return {"sum_flexmm": float(a.sum()), "sum_difflexmm": float(b.sum()),
            "cosine": float(a @ b / np.linalg.norm(a) / np.linalg.norm(b)),
            "relative_l2": float(np.linalg.norm(a - b) / np.linalg.norm(b))}


def main(argv: list[str]) -> int:
    import argparse

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--python", default=os.environ.get("DIFFLEXMM_PYTHON"), help="Python with jax + jax-md")
    p.add_argument("--src", default=os.environ.get("DIFFLEXMM_SRC"), help="DifFlexMM source tree")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--worker", choices=["flexmm", "difflexmm"])
    p.add_argument("--law", choices=["sheet", "difflexmm"], default="sheet",
                   help="flexmm's model: the rotating-squares sheet's hinge law (leading-order agreement), or the "
                   "rigid-unit network with DifFlexMM's ligament law (the same model in both codes)")
    args = p.parse_args(argv)
    if args.worker == "flexmm":
        flexmm_worker(args.law)
        return 0
    if args.worker == "difflexmm":
        difflexmm_worker(args.src)
        return 0
    if not args.python or not args.src:
        print("DifFlexMM comparison not run: set DIFFLEXMM_PYTHON (a Python with jax, jaxlib, jax-md) and "
              "DIFFLEXMM_SRC (DifFlexMM's source tree), or pass --python/--src; see benchmarks/README.md.")
        return 0
    if not os.path.isdir(os.path.join(args.src, "difflexmm")):
        print(f"DifFlexMM comparison not run: {args.src} has no difflexmm/ package directory.")
        return 0
    here = os.path.abspath(__file__)
    print(f"load average at start: {os.getloadavg()}")
    t0 = time.perf_counter()
    jx = Worker([args.python, here, "--worker", "difflexmm", "--src", args.src])
    fx = Worker([sys.executable, here, "--worker", "flexmm", "--law", args.law])
    print(f"workers ready in {time.perf_counter() - t0:.1f} s: DifFlexMM (jax {jx.info['jax']}) "
          f"{jx.info['n_blocks']} blocks, {jx.info['n_hinges']} hinges; flexmm {fx.info['n_blocks']} units, "
          f"{fx.info['n_hinges']} hinges")
    # accuracy: each code against its own converged run
    j_ref = jx("reference")["value"]
    j_val = jx("forward")["value"]
    j_err = abs(j_val - j_ref) / abs(j_ref)
    f_ref = fx("reference")["value"]
    ladder = {float(h): v for h, v in fx("ladder")["values"].items()}
    print(f"objective (kinetic energy of columns 20-39 at t = 40, units k_l spacing^2): DifFlexMM {j_val:.10g} "
          f"(rtol = atol = 1e-8; converged {j_ref:.10g}, relative error {j_err:.2e}); flexmm converged {f_ref:.10g} "
          f"(relative difference of the converged values {abs(f_ref - j_ref) / abs(j_ref):.2e})")
    for h, v in ladder.items():
        print(f"  flexmm velocity Verlet h = {h:g} ({round(DURATION / h)} steps): relative error {abs(v - f_ref) / abs(f_ref):.2e}")
    ok = [h for h, v in ladder.items() if abs(v - f_ref) / abs(f_ref) <= j_err]
    equal = max(ok) if ok else min(ladder)
    rows = []
    rss = {}
    for label, h in (("at DifFlexMM's error", equal), ("h = 0.05", 0.05)):
        fx("step", h=h)
        rss.setdefault("ff", fx("forward")["rss_mb"])  # warm (and RSS before any gradient)
        rss.setdefault("jf", jx("forward")["rss_mb"])
        fx("gradient"), jx("gradient")
        t = {k: [] for k in ("jf", "jg", "ff", "fg")}
        c = {k: [] for k in t}
        for r in range(args.repeats):
            pairs = (("ff", fx, "forward"), ("jf", jx, "forward"), ("fg", fx, "gradient"), ("jg", jx, "gradient"))
            for key, w, op in (pairs if r % 2 == 0 else pairs[::-1]):
                rep = w(op)
                t[key].append(rep["wall"])
                c[key].append(rep["cpu"])
                if op == "gradient":
                    if key == "fg":
                        fgrad = rep["grad"]
                    else:
                        jgrad = rep["grad"]
        s = {k: _stats(v) for k, v in t.items()}
        cmp = _compare_fields(fgrad, jgrad)
        traced = fx("memory")["traced_mb"]
        row = {"label": label, "h": h, "steps": round(DURATION / h), "load": os.getloadavg(),
               **{f"{k}_min_s": s[k][0] for k in s}, **{f"{k}_median_s": s[k][1] for k in s},
               **{f"{k}_cpu_min_s": min(c[k]) for k in c}, "gradient_fields": cmp,
               "flexmm_gradient_traced_mb": traced}
        rows.append(row)
        print(f"flexmm {label} (h = {h:g}, {row['steps']} steps; load {os.getloadavg()[0]:.1f}):")
        print(f"  forward:  flexmm {s['ff'][0]:.3g} s min / {s['ff'][1]:.3g} median (CPU {min(c['ff']):.3g}); "
              f"DifFlexMM {s['jf'][0]:.3g} / {s['jf'][1]:.3g} (CPU {min(c['jf']):.3g}): DifFlexMM/flexmm "
              f"x{s['jf'][0] / s['ff'][0]:.1f} min, x{s['jf'][1] / s['ff'][1]:.1f} median, x{min(c['jf']) / min(c['ff']):.1f} CPU")
        print(f"  gradient: flexmm {s['fg'][0]:.3g} s / {s['fg'][1]:.3g} (CPU {min(c['fg']):.3g}); DifFlexMM "
              f"{s['jg'][0]:.3g} / {s['jg'][1]:.3g} (CPU {min(c['jg']):.3g}): DifFlexMM/flexmm x{s['jg'][0] / s['fg'][0]:.1f} "
              f"min, x{s['jg'][1] / s['fg'][1]:.1f} median, x{min(c['jg']) / min(c['fg']):.1f} CPU")
        print(f"  gradient / forward: flexmm x{s['fg'][1] / s['ff'][1]:.1f}, DifFlexMM x{s['jg'][1] / s['jf'][1]:.1f} (medians)")
        print(f"  flexmm gradient memory: tracemalloc peak {traced:.1f} MB (its stored states; the reverse sweep "
              f"keeps every state up to 256 MB, checkpoints beyond)")
        print(f"  per-hinge dJ/dk_theta fields: sums {cmp['sum_flexmm']:.5g} (flexmm) and {cmp['sum_difflexmm']:.5g} "
              f"(DifFlexMM), cosine {cmp['cosine']:.3f}, relative L2 difference {cmp['relative_l2']:.0%}")
    fm, jm = fx("memory"), jx("memory")
    print(f"memory (peak RSS of each worker process, compiled code included): flexmm {fx.info['rss_mb']:.0f} MB "
          f"after compiling, {rss['ff']:.0f} MB after forward runs, {fm['rss_mb']:.0f} MB after gradients; DifFlexMM "
          f"{jx.info['rss_mb']:.0f} MB after setup, {rss['jf']:.0f} MB after (jit-compiled) forward runs, "
          f"{jm['rss_mb']:.0f} MB after gradients")
    fx.close()
    jx.close()
    out = os.path.join(os.path.dirname(here), "results")
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, "difflexmm.json" if args.law == "sheet" else f"difflexmm_{args.law}.json"), "w") as fh:
        json.dump({"rows": rows, "difflexmm_error": j_err, "objective": {"difflexmm": j_val, "flexmm": f_ref},
                   "rss_mb": {"flexmm": fm["rss_mb"], "difflexmm": jm["rss_mb"]}}, fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
