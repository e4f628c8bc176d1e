"""What the demo's analysis says (issue #32, items 7 and 8): one reflected pulse is one pulse, a
quantity that was not measured is not compared, and summaries only compare with a theory that
applies, only measure what has happened, and say what the scene is."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from flexmm.analysis.report import analyze_run
from flexmm.analysis.summary import summary_lines
from flexmm.api import run_scene
from flexmm.config import load_scene

ROOT = Path(__file__).resolve().parents[2]


def _run(tmp_path, config, overrides):
    sc = load_scene(ROOT / "configs" / config, overrides)
    res = run_scene(sc, run_dir=tmp_path / "run", fidelity="full")
    assert res.status == "finished", res.message
    return tmp_path / "run"


def test_demo_reflection_is_one_pulse(tmp_path):
    """The demo at its own step (PEFRL at the step its accuracy pilots pick, 1/7 ms) without the pilots: the
    pulse reflected at the free end is one pulse moving left, compared with c(A), in the summary,
    and no row of the table is NaN against a prediction (it was split into 3 pulses, 2 of them
    'formation transients that die out', and printed '+nan %')."""
    run = _run(tmp_path, "lego_vector_soliton.yaml", ["solver.accuracy=null", "solver.integrator=pefrl",
                                                      "solver.dt_s=0.00014285714285714287"])
    res = analyze_run(run)
    left = [p for p in res.pulses if p.direction < 0 and p.track_time_s[0] > 0.5]
    assert len(left) == 1, [(p.index, p.track_time_s[0]) for p in left]
    p = left[0]
    assert not p.transient and p.polarity > 0
    assert abs(p.track_pos_m[-1] - p.track_pos_m[0]) > 60 * res.view.spacing_m
    speed = [c for c in res.comparisons if c.item == f"pulse {p.index}" and c.quantity == "speed"]
    assert speed and speed[0].predicted is not None and abs(speed[0].rel_diff) < 0.05
    for c in res.comparisons:
        if c.predicted is not None:
            assert c.measured is not None and math.isfinite(c.measured), c
    text = "\n".join(summary_lines(res))
    assert f"pulse {p.index} (positive rotation, moving left)" in text and "nan" not in text
