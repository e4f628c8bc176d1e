"""What the demo's analysis says (issue #32, items 7 and 8): one reflected pulse is one pulse, a
quantity that was not measured is not compared, and summaries only compare with a theory that
applies, only measure what has happened, and say what the scene is."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from conftest import DEMO_AS_LEGO_SCENE_SETS

from flexmm.analysis.report.analyze import analyze_run
from flexmm.analysis.report.summary import summary_lines
from flexmm.api import run_scene
from flexmm.config import load_scene

ROOT = Path(__file__).resolve().parents[2]


def _run(tmp_path, config, overrides):
    sc = load_scene(ROOT / "configs" / config, overrides)
    res = run_scene(sc, run_dir=tmp_path / "run", fidelity="full")
    assert res.status == "finished", res.reason
    return tmp_path / "run"


def test_demo_reflection_is_one_pulse(tmp_path):
    """The demo's impact on a 200-unit chain with a free far end (as the demo was before its
    absorbing end), at the step its accuracy pilots pick there (PEFRL, 1/7 ms) without the pilots: the
    pulse reflected at the free end is one pulse moving left, compared with c(A), in the summary,
    and no row of the table is NaN against a prediction (it was split into 3 pulses, 2 of them
    'formation transients that die out', and printed '+nan %')."""
    run = _run(tmp_path, "lego_vector_soliton.yaml", [*DEMO_AS_LEGO_SCENE_SETS, "solver.accuracy=null",
                                                      "solver.integrator=pefrl", "solver.dt_s=0.00014285714285714287"])
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


def test_localised_push_on_a_sheet_gets_no_planar_theory(tmp_path):
    """configs/a_sheet_sound_bullet.yaml at a reduced size: the push on 11 rows makes a beam, not
    the planar wave the chain theory describes, so nothing is compared (it printed speed +10.8 %
    and width -64.5 % against that theory)."""
    over = ["lattice.n_rows=40", "lattice.n_cols=60", "solver.duration_s=0.012", "output.n_frames=49",
            "excitation.sites=[1200, 1260, 1320, 1380, 1440]", "imperfection.sites=[1200, 1260, 1320, 1380, 1440]"]
    res = analyze_run(_run(tmp_path, "a_sheet_sound_bullet.yaml", over))
    assert res.pulses
    assert all(c.predicted is None for c in res.comparisons), [c for c in res.comparisons if c.predicted]
    assert "theory" not in "\n".join(summary_lines(res))


def test_localised_push_keeps_the_sheet():
    """A drive of listed units is not planar: the plan keeps the sheet (it ran as the strip)."""
    from flexmm.plan.dimension import reduce_dimension

    sc = load_scene(ROOT / "configs" / "a_sheet_sound_bullet.yaml", ["imperfection=null"])
    reduced, note = reduce_dimension(sc)
    assert reduced is None and "listed units" in note


def test_linkage_transition_wave_is_a_front(tmp_path, recwarn):
    """configs/k_linkage_transition_wave.yaml: the bistable linkage's wave is a front in θ (it was
    summarised as 5 pulses with OptimizeWarnings)."""
    res = analyze_run(_run(tmp_path, "k_linkage_transition_wave.yaml", ["solver.duration_s=0.1", "solver.accuracy=null",
                                                                        "output.n_frames=101"]))
    assert res.kind == "front" and res.view.spec == "theta"
    assert res.fronts[0].n_switched > 40 and res.fronts[0].direction > 0
    assert summary_lines(res)[0].startswith("front 0 in theta (right-moving")
    assert not [w for w in recwarn if "Covariance" in str(w.message)]


def test_shaker_far_end_not_reached_is_not_measured(tmp_path):
    """configs/fpu_second_harmonic_shaker.yaml for 0.3 s: the wave covers about half of the 600
    sites, so there is no transmission or far-end spectrum to report (it reported a transmission
    of the precursor), and the decay is fitted over the sites the wave has reached."""
    res = analyze_run(_run(tmp_path, "fpu_second_harmonic_shaker.yaml", ["solver.duration_s=0.3",
                                                                         "output.n_frames=601"]))
    d = res.driven
    assert not d.far_reached and 100 < d.reached_sites < 400
    assert math.isnan(d.transmission) and math.isnan(d.dominant_far_hz) and math.isnan(d.amplitude_far)
    assert abs(d.decay_per_site) < 1e-3  # a pass-band wave: no decay where it has arrived
    assert "far end is not reached" in summary_lines(res)[0]
