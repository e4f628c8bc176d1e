"""``flexmm bench`` refuses a chaotic scene (issue 32, item 10): a looser reference ends far from
the tight one, so every method's final-state error would measure the chaos, not the method."""

from __future__ import annotations

import yaml
from typer.testing import CliRunner

from flexmm.assemble import build_problem
from flexmm.cli import app
from flexmm.config import scene_from_dict
from flexmm.diagnostics import workprecision as wp


def ring(k3: float) -> dict:
    """16 masses on a ring, 3 mm of frozen noise: linear (k3 = 0) or a strongly nonlinear FPU-β ring."""
    return {"name": "ring", "solver": {"duration_s": 1.0}, "output": {"n_frames": 11},
            "lattice": {"kind": "mass_chain", "n_units": 16, "spacing_m": 0.01, "mass_kg": 0.01,
                        "left": "periodic", "right": "periodic",
                        "bond": {"law": "polynomial", "k1_n_per_m": 100.0, "k3_n_per_m3": k3}},
            "initial": {"fields": [{"field": "u", "value": "3e-3 * normal(1)"}]}}


def test_a_regular_scene_has_a_reference_that_a_looser_one_reproduces():
    pb = build_problem(scene_from_dict(ring(0.0)))
    spread, scale, _ = wp.reference_spread(pb, wp.reference(pb, 11), 11)
    assert spread < 1e-6 * scale  # measured 2e-9 of the field


def test_bench_refuses_a_chaotic_scene_unless_forced(tmp_path):
    f = tmp_path / "chaos.yaml"
    f.write_text(yaml.safe_dump(ring(1e8), sort_keys=False))
    r = CliRunner().invoke(app, ["bench", str(f), "--methods", "velocity_verlet", "--ivp", "", "--repeats", "1",
                                 "--out", str(tmp_path / "b")])
    assert r.exit_code == 2, r.output
    assert "chaotic" in r.output and "--force" in r.output and "Traceback" not in r.output
    assert not (tmp_path / "b" / "workprecision.csv").exists()
