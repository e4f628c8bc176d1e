"""Real LEGO-chain runs analysed against the continuum theory (docs/physics.md §1.3), marked slow.

The exact speed law holds where the continuum applies: the pulse is several sites wide and
slower than the minimum phase speed of the rotational branch (faster discrete pulses resonate
with rotational waves and radiate, docs/physics.md §1.3). Measured numbers are in the test ids.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest
from typer.testing import CliRunner

from flexmm.analysis import analyze_run
from flexmm.api import run_scene
from flexmm.assemble import build_problem
from flexmm.cli import app
from flexmm.config import scene_from_dict
from flexmm.controller import run_problem
from flexmm.theory import rotating as rt

pytestmark = pytest.mark.slow

P = rt.lego_parameters()  # n_v = 1, s_v = 0, θ0 = 0: the LEGO scene
C_RAD = rt.min_phase_speed_rotational(P)
AMPLITUDES = [0.15, 0.175, 0.2, 0.25, 0.3, 0.4, 0.5, 0.6]


def soliton_scene(lego_config, A: float, n: int = 400, travel: float = 0.7, name: str = "soliton"):
    """LEGO chain of n units, exact soliton of amplitude A launched at 10 % of its length."""
    cfg = copy.deepcopy(lego_config)
    cfg["name"] = name
    cfg["lattice"].update(n_units=n, left="free")
    cfg["excitation"] = {"kind": "soliton", "amplitude_rad": A, "center_site": n // 10}
    T = (cfg["lattice"]["mass_kg"] / cfg["lattice"]["k_long_n_per_m"]) ** 0.5
    cfg["solver"]["duration_s"] = travel * n / float(rt.soliton_speed(P, A)) * T
    cfg["output"]["n_frames"] = 1001
    return scene_from_dict(cfg)


def _row(res, quantity, item="pulse 0"):
    return next(c for c in res.comparisons if c.item == item and c.quantity == quantity)


@pytest.mark.parametrize("A", AMPLITUDES)
def test_soliton_speed_law_and_width(tmp_path, lego_config, A):
    run_scene(soliton_scene(lego_config, A), run_dir=tmp_path)
    res = analyze_run(tmp_path)
    main = max(res.pulses, key=lambda p: abs(p.amplitude))
    assert main.index == 0 and main.direction == 1
    speed, width = _row(res, "speed"), _row(res, "width W (sech fit)")
    h = 0.016
    print(f"A={A}: measured A={main.amplitude:.4f}, v={speed.measured:.4f} m/s, law {speed.predicted:.4f} "
          f"({100 * speed.rel_diff:+.2f} %), W={width.measured / h:.3f} vs {width.predicted / h:.3f} sites")
    if float(rt.soliton_speed(P, A)) < C_RAD:  # continuum regime: no radiation
        assert abs(speed.rel_diff) < 0.01
        assert abs(width.measured - width.predicted) < h
        assert abs(main.amplitude_last / main.amplitude_first - 1) < 0.01
    else:  # faster than the slowest rotational phase: the discrete pulse radiates
        assert main.attenuation_per_m > 0 or abs(speed.rel_diff) > 0.005


def test_same_sign_collision_is_tracked_through(tmp_path, lego_config):
    problem = build_problem(soliton_scene(lego_config, 0.4, n=300, travel=0.5))
    s = problem.system
    n = s.n_sites
    second = rt.soliton_initial_state(P, 0.3, n, 0.85 * n, -1)
    s.q0[:n] += second.U
    s.q0[n:] += second.theta
    s.v0[:n] += second.U_dot
    s.v0[n:] += second.theta_dot
    run_problem(problem, tmp_path)
    res = analyze_run(tmp_path)
    incoming = [p for p in res.pulses if p.first_site < 0.3 * n or p.last_site > 0.7 * n]
    right = next(p for p in incoming if p.direction == 1)
    left = next(p for p in incoming if p.direction == -1)
    for p in (right, left):
        row = next(c for c in res.comparisons if c.item == f"pulse {p.index}" and c.quantity == "speed")
        assert abs(row.rel_diff) < 0.01
    # same rotation sign: both pass through and keep most of their amplitude
    after = [p for p in res.pulses if p not in (right, left)]
    for d in (1, -1):
        out = [p for p in res.pulses if p.direction == d and p.last_site * d > 0.5 * n * d]
        assert out and max(abs(p.amplitude) for p in out) > 0.8 * (0.4 if d == 1 else 0.3)
    assert all(np.sign(p.amplitude) == 1 for p in after)


def test_shipped_scene_is_analysed(tmp_path):
    res = CliRunner().invoke(app, ["run", "configs/lego_vector_soliton.yaml", "-o", str(tmp_path), "-q",
                                   "--set", "solver.duration_s=0.4"])
    assert res.exit_code == 0, res.output
    res = CliRunner().invoke(app, ["analyze", str(tmp_path), "--plot", "--json", str(tmp_path / "a.json")])
    assert res.exit_code == 0, res.output
    import json

    rows = json.loads((tmp_path / "a.json").read_text())["runs"][0]["comparisons"]
    assert any(r["quantity"] == "speed" and r["note"].startswith("exact law") for r in rows)
    assert (tmp_path / "analysis.nc").is_file() and (tmp_path / "space_time_theta.png").is_file()


def test_shaker_sweep_finds_the_longitudinal_cutoff(tmp_path, lego_config):
    """θ0 = 0: u is a linear chain below its cut-off 1268 Hz and evanescent above (docs/physics.md §1.4)."""
    runs = []
    for f in (400.0, 1000.0, 1500.0, 2500.0):
        cfg = copy.deepcopy(lego_config)
        cfg["name"] = f"shaker_{f:g}"
        cfg["lattice"].update(n_units=60)
        cfg["excitation"] = {"kind": "shaker", "end": "left", "frequency_hz": f, "amplitude_m": 1e-5,
                             "ramp_cycles": 5}
        cfg["damping"] = {"viscous": {"damping_ratio": 0.01}}
        cfg["solver"]["duration_s"] = 0.1
        cfg["output"]["n_frames"] = 2001
        run_scene(scene_from_dict(cfg), run_dir=tmp_path / cfg["name"])
        runs.append(str(tmp_path / cfg["name"]))
    res = CliRunner().invoke(app, ["analyze", *runs, "--plot", "--plot-dir", str(tmp_path),
                                   "--json", str(tmp_path / "s.json")])
    assert res.exit_code == 0, res.output
    import json

    data = json.loads((tmp_path / "s.json").read_text())
    trans = {r["driven"]["frequency_hz"]: r["driven"]["transmission"] for r in data["runs"]}
    assert min(trans[400.0], trans[1000.0]) > 0.1 and max(trans[1500.0], trans[2500.0]) < 1e-3
    assert data["bands"]["measured_hz"] == [[400.0, 1000.0]]
    assert data["bands"]["predicted_hz"][-1][1] == pytest.approx(1267.7, rel=1e-3)
    assert (tmp_path / "transmission.png").is_file()


def test_damped_bistable_front_against_theory(tmp_path):
    """Mass chain, cubic bistable on-site force (β = 0.3), front 15 sites wide at v = c0/2."""
    cfg = {
        "name": "bistable_front",
        "lattice": {"kind": "mass_chain", "n_units": 300, "spacing_m": 0.01, "mass_kg": 0.01,
                    "bond": {"law": "linear", "k_n_per_m": 100.0},
                    "onsite": [{"law": "bistable_cubic", "alpha_n_per_m3": 26667.0, "beta": 0.3, "jump_m": 0.01}],
                    "left": "driven"},
        "excitation": {"kind": "boundary_displacement", "end": "left", "shape": "smooth_step",
                       "amplitude_m": 0.01, "duration_s": 0.05},
        "damping": {"viscous": {"coefficient_n_s_per_m": 0.08}},
        "solver": {"duration_s": 5.0},
        "output": {"n_frames": 601},
    }
    run_scene(scene_from_dict(cfg), run_dir=tmp_path)
    res = analyze_run(tmp_path)
    assert res.kind == "front" and len(res.fronts) == 1
    rows = {c.quantity: c for c in res.comparisons}
    print({q: f"{100 * rows[q].rel_diff:+.2f} %" for q in ("speed", "width 10–90 %", "kinetic energy")})
    assert abs(rows["speed"].rel_diff) < 0.01
    assert abs(rows["width 10–90 %"].rel_diff) < 0.02
    assert abs(rows["kinetic energy"].rel_diff) < 0.02
    assert res.fronts[0].n_switched > 250 and not res.fronts[0].arrested
