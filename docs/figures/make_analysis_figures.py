"""Make the README's analysis figures from LEGO-chain runs (docs/physics.md §1.1, §1.3).

    .venv/bin/python docs/figures/make_analysis_figures.py [WORK_DIR]

1. lego_soliton_speed_amplitude.png: exact solitons of amplitude 0.15–0.6 rad launched on a
   400-unit LEGO chain; measured speed against measured amplitude on the exact continuum law,
   and the relative difference.
2. lego_soliton_collision_space_time.png: two solitons of the same rotation sign (0.4 rad moving
   right, 0.3 rad moving left) pass through each other; θ on the (site, time) plane with the
   arrival times of every tracked pulse.
Runs go to WORK_DIR (default runs/figures); takes about a minute on two cores.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

from flexmm.analysis import analyze_run
from flexmm.analysis.report import figures
from flexmm.api import run_scene
from flexmm.assemble import build_problem
from flexmm.config import load_scene, scene_from_dict
from flexmm.controller import run_problem
from flexmm.theory import rotating as rt

HERE = Path(__file__).resolve().parent
CONFIG = HERE.parents[1] / "configs" / "lego_vector_soliton.yaml"
AMPLITUDES = (0.15, 0.175, 0.2, 0.25, 0.3, 0.35, 0.4, 0.45, 0.5, 0.55, 0.6)


def soliton_scene(A: float, n: int, travel: float, name: str):
    """The LEGO scene with an exact soliton of amplitude A at 10 % of an n-unit chain."""
    d = load_scene(CONFIG).model_dump(mode="json")
    lat = d["lattice"]
    lat.update(n_units=n, left="free")
    d.update(name=name, excitation={"kind": "soliton", "amplitude_rad": A, "center_site": n // 10})
    p = rt.lego_parameters()
    time_unit = math.sqrt(lat["mass_kg"] / lat["k_long_n_per_m"])
    d["solver"]["duration_s"] = travel * n / float(rt.soliton_speed(p, A)) * time_unit
    d["output"]["n_frames"] = 1001
    return scene_from_dict(d)


def speed_amplitude(work: Path) -> Path:
    results = []
    for A in AMPLITUDES:
        run = work / f"soliton_A{A:g}"
        run_scene(soliton_scene(A, 400, 0.7, f"soliton_A{A:g}"), run_dir=run)
        res = analyze_run(run)
        results.append(res)
        p = max(res.pulses, key=lambda q: abs(q.amplitude))
        row = next(c for c in res.comparisons if c.item == f"pulse {p.index}" and c.quantity == "speed")
        print(f"A0 = {A:5.3f}: A = {p.amplitude:.4f} rad, v = {p.speed_m_s:.4f} m/s, law {row.predicted:.4f} "
              f"({100 * row.rel_diff:+.2f} %)")
    th = results[0]
    amps = [a / 1000 for a in range(130, 700, 2)]
    from flexmm.analysis.report.theory_comparison import theory_for

    curve = (amps, theory_for(th.ctx).speed_curve(th.ctx, "rad", amps))
    pts = [(p.amplitude, p.speed_m_s, p.speed_stderr_m_s, r.name) for r in results for p in figures.main_pulses(r)]
    import numpy as np

    return figures.speed_amplitude(pts, HERE / "lego_soliton_speed_amplitude.png",
                                   curve=(np.asarray(curve[0]), np.asarray(curve[1])),
                                   title="LEGO chain: soliton speed against amplitude")


def collision(work: Path) -> Path:
    problem = build_problem(soliton_scene(0.4, 400, 0.55, "soliton_collision"))
    s, n = problem.system, problem.system.n_sites
    second = rt.soliton_initial_state(rt.lego_parameters(), 0.3, n, 0.8 * n, -1)
    s.q0[:n] += second.U
    s.q0[n:] += second.theta
    s.v0[:n] += second.U_dot
    s.v0[n:] += second.theta_dot
    run = work / "soliton_collision"
    run_problem(problem, run)
    res = analyze_run(run)
    return figures.space_time(res.view, HERE / "lego_soliton_collision_space_time.png", pulses=res.pulses,
                              title="LEGO chain: two solitons (0.4 and 0.3 rad) pass through each other")


if __name__ == "__main__":
    work = Path(sys.argv[1] if len(sys.argv) > 1 else "runs/figures")
    for path in (speed_amplitude(work), collision(work)):
        print(f"wrote {path} ({path.stat().st_size / 1024:.0f} kB)")
