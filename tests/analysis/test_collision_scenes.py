"""The shipped LEGO collision scenes report their collision (docs/scenes.md, Fig. 1b).

docs/physics.md has no collision relation for the rotating-squares chain (its solitons are not
those of an integrable equation), so the shifts are measured, not compared: the checks are the
pairing, the outcome, and that each soliton leaves with (nearly) its amplitude and sign.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from flexmm.analysis.report import analyze as report
from flexmm.api import run_scene
from flexmm.config import load_scene

CONFIGS = Path(__file__).resolve().parents[2] / "configs"


def _analysed(tmp_path, name):
    result = run_scene(load_scene(CONFIGS / f"{name}.yaml"), run_dir=tmp_path / name)
    return report.analyze_run(result.path)


@pytest.mark.slow
def test_same_sign_solitons_pass_through(tmp_path):
    res = _analysed(tmp_path, "b_lego_collision_same_sign")
    assert res.overlap_artefacts == 0
    (c,) = res.collisions
    assert c.kind == "head-on" and c.outcome == "passed through"
    amps = sorted([c.amplitude_a, c.amplitude_b])
    assert amps == [pytest.approx(0.4, rel=0.03), pytest.approx(0.6, rel=0.03)]
    for out, change in ((c.out_a, c.amplitude_change_a), (c.out_b, c.amplitude_change_b)):
        assert out >= 0 and abs(change) < 0.08  # each keeps its identity, within 8 % of its amplitude
    assert all(abs(x) < 0.2 for x in (c.shift_a_m, c.shift_b_m))  # within ~12 units (a = 16 mm)
    rows = [r for r in res.comparisons if r.item == "collision 0"]
    assert {r.quantity.split(" of ")[0] for r in rows} == {"space shift", "time shift", "amplitude change",
                                                           "speed change"}


@pytest.mark.slow
def test_opposite_sign_solitons_are_reflected_with_their_sign(tmp_path):
    res = _analysed(tmp_path, "b_lego_collision_opposite_sign")
    (c,) = res.collisions
    assert c.outcome == "reflected"
    for pulse, out, change in ((c.pulse_a, c.out_a, c.amplitude_change_a), (c.pulse_b, c.out_b, c.amplitude_change_b)):
        pre, post = res.pulses[pulse], res.pulses[out]
        assert abs(pre.amplitude) == pytest.approx(0.5, rel=0.03)
        assert post.polarity == pre.polarity and post.direction == -pre.direction
        assert abs(change) < 0.02  # docs/scenes.md: 101 % of the amplitude
    # the chain and the pair are symmetric: both turn back the same distance before meeting
    assert c.shift_a_m == pytest.approx(c.shift_b_m, rel=0.02)
