"""Head-on collision of two launched Toda solitons: the measured shifts against the exact
two-soliton phase shifts (docs/physics.md §2), end to end (launch, run, analyze)."""

from __future__ import annotations

import math

import pytest

from flexmm.analysis.report import analyze as report
from flexmm.api import run_scene
from flexmm.config import scene_from_dict
from flexmm.theory.chains import toda_head_on_shifts, toda_speed


def test_equal_solitons_shift_by_ln_cosh_over_kappa():
    """A12 = 1/cosh²κ for equal solitons: Δn = ln(cosh κ)/κ."""
    for k in (0.3, 1.0, 2.0):
        d1, d2 = toda_head_on_shifts(k, k)
        assert d1 == pytest.approx(math.log(math.cosh(k)) / k, rel=1e-12) and d1 == d2


def test_toda_head_on_collision_shifts_match_the_exact_solution(tmp_path):
    """κ = 1 and κ = 0.5: the smaller soliton (28 % of the larger, but 23 % of their sum while they
    overlap, under the default level of 25 % of the largest value) is found at a level of 15 %,
    both speeds match β/κ and both shifts −ln A12/(2κ)."""
    k1, k2, a, m, b = 1.0, 0.5, 0.01, 0.01, 100.0
    sc = scene_from_dict({
        "name": "toda_collision", "solver": {"duration_s": 1.6, "accuracy": 1e-6}, "output": {"n_frames": 1601},
        "lattice": {"kind": "mass_chain", "n_units": 300, "spacing_m": a, "mass_kg": 0.01,
                    "bond": {"law": "toda", "a_n": 1.0, "b_per_m": 100.0}},
        "initial": {"launch": [{"kind": "toda_soliton", "kappa": k1, "center_site": 60, "direction": 1},
                               {"kind": "toda_soliton", "kappa": k2, "center_site": 240, "direction": -1}]}})
    res = report.analyze_run(run_scene(sc, run_dir=tmp_path / "toda").path, threshold_fraction=0.15)
    (c,) = res.collisions
    assert c.outcome == "passed through" and abs(c.amplitude_change_a) < 1e-3 and abs(c.speed_change_a) < 1e-3
    right = "a" if res.pulses[c.pulse_a].direction > 0 else "b"
    left = "b" if right == "a" else "a"
    assert len(res.pulses) == 2
    assert abs(res.pulses[c.pulse_a if right == "a" else c.pulse_b].speed_m_s) == pytest.approx(
        toda_speed(1.0, b, m, k1) * a, rel=1e-4)
    assert abs(res.pulses[c.pulse_b if right == "a" else c.pulse_a].speed_m_s) == pytest.approx(
        toda_speed(1.0, b, m, k2) * a, rel=1e-4)
    d1, d2 = toda_head_on_shifts(k1, k2)  # 0.227 and 0.455 sites forward
    assert getattr(c, f"shift_{right}_m") == pytest.approx(d1 * a, rel=0.02)
    assert getattr(c, f"shift_{left}_m") == pytest.approx(d2 * a, rel=0.02)
    rows = [r for r in res.comparisons if r.item == "collision 0" and r.quantity.startswith("space shift")]
    assert len(rows) == 2 and all(r.predicted is not None and abs(r.rel_diff) < 0.02 for r in rows)
