"""Collisions on synthetic datasets with known meeting point, shifts, changes and outcome."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from flexmm.analysis import field_view, measure_pulses
from flexmm.analysis.measure.collisions import find_collisions
from synthetic import SynthLeg, SynthPulse, collision_dataset, pulse_dataset


def _collisions(ds):
    view = field_view(ds, "theta")
    return find_collisions(measure_pulses(view), view.spacing_m, float(view.time[-1]))

# each example analyses a whole dataset (~1 s): report a failure as found rather than shrink it for minutes
NO_SHRINK = (Phase.explicit, Phase.reuse, Phase.generate)


@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.too_slow],
          phases=NO_SHRINK, derandomize=True)
@given(
    va=st.floats(0.6, 1.4), vb=st.floats(0.6, 1.4), wa=st.floats(2.0, 4.0), wb=st.floats(2.0, 4.0),
    amp_a=st.floats(0.3, 1.0), ratio=st.floats(0.45, 0.7), sign_b=st.sampled_from([1, -1]),
    reflect=st.booleans(), shift_a=st.floats(-4.0, 4.0), shift_b=st.floats(-4.0, 4.0),
    da=st.floats(-0.1, 0.1), dv=st.floats(-0.15, 0.15), noise=st.floats(0.0, 0.01), seed=st.integers(0, 999),
)
def test_head_on_collision_is_paired_with_its_shifts_and_changes(va, vb, wa, wb, amp_a, ratio, sign_b, reflect,
                                                                 shift_a, shift_b, da, dv, noise, seed):
    """Pulse a (right-moving) meets pulse b (left-moving, smaller) at t = 100, x = 120; each
    leaves with a known shift, amplitude and speed change, passing through or reflected."""
    amp_b = sign_b * ratio * amp_a
    t_c, x_c = 100.0, 120.0
    d = -1 if reflect else 1
    inc = (SynthLeg(amp_a, va, wa), SynthLeg(amp_b, -vb, wb))
    out = [SynthLeg(amp_a * (1 + da), d * va * (1 + dv), wa, shift_a),
           SynthLeg(amp_b * (1 - da), -d * vb * (1 - dv), wb, shift_b)]
    ds = collision_dataset(inc, out, t_c=t_c, x_c=x_c, n_frames=401, noise=noise * amp_a, seed=seed)
    cols, pulses, _ = _collisions(ds)
    assert len(cols) == 1
    c = cols[0]
    assert c.kind == "head-on"
    assert c.outcome == ("reflected" if reflect else "passed through")
    # a speed change below arrivals.SPEED_CHANGE (2 %) is fitted with one slowness on both sides of
    # the collision, which moves the lines' meeting point by up to about half a site
    assert c.time_s == pytest.approx(t_c, abs=0.6) and c.position_m == pytest.approx(x_c, abs=0.6)
    a = pulses[c.pulse_a]
    if a.direction < 0:  # the pair is unordered: make a the right-moving one
        c_a, c_b = (c.shift_b_m, c.amplitude_change_b, c.speed_change_b), (c.shift_a_m, c.amplitude_change_a, c.speed_change_a)
    else:
        c_a, c_b = (c.shift_a_m, c.amplitude_change_a, c.speed_change_a), (c.shift_b_m, c.amplitude_change_b, c.speed_change_b)
    # noise (a fraction of amp_a) blurs each pulse's fitted track: the shift's tolerance grows with
    # the noise relative to that pulse's own amplitude (0.05 sites when there is none)
    for (shift, damp, dspeed), (s_true, a_true, v_true), rel in ((c_a, (shift_a, da, dv), 1.0),
                                                                  (c_b, (shift_b, -da, -dv), ratio)):
        assert shift == pytest.approx(s_true, abs=0.05 + 5 * noise / rel)
        assert damp == pytest.approx(a_true, abs=0.02)
        assert dspeed == pytest.approx(v_true, abs=0.005)


def test_overtaking_collision_and_time_shift():
    """A fast pulse catches a slow one of the same sign and passes it; the delay is −shift/v."""
    inc = (SynthLeg(0.8, 1.2, 2.5), SynthLeg(0.4, 0.5, 3.5))
    out = [SynthLeg(0.8, 1.2, 2.5, 3.0), SynthLeg(0.4, 0.5, 3.5, -2.0)]
    ds = collision_dataset(inc, out, t_c=100.0, x_c=140.0, n_sites=300, duration_s=200.0)
    (c,), pulses, _ = _collisions(ds)
    assert c.kind == "overtaking" and c.outcome == "passed through"
    fast = "a" if pulses[c.pulse_a].speed_m_s > 1 else "b"
    assert getattr(c, f"shift_{fast}_m") == pytest.approx(3.0, abs=0.05)
    assert getattr(c, f"delay_{fast}_s") == pytest.approx(-3.0 / 1.2, abs=0.05)


def test_pulses_that_never_meet_have_no_collision():
    ds = pulse_dataset([SynthPulse(0.5, 1.0, 3.0, 20.0), SynthPulse(0.3, 1.0, 3.0, 80.0)], n_sites=300)
    cols, pulses, dropped = _collisions(ds)
    assert cols == [] and len(pulses) == 2 and dropped == 0


def test_linear_superposition_passes_with_zero_shift():
    """Two pulses that simply superpose (the synthetic pulse_dataset) pass with no shift."""
    ds = pulse_dataset([SynthPulse(0.3, 1.5, 3.0, 20.0), SynthPulse(-0.3, -1.2, 4.0, 180.0)], noise=0.003)
    cols, pulses, _ = _collisions(ds)
    assert len(cols) == 1 and cols[0].outcome == "passed through"
    assert np.isfinite(cols[0].shift_a_m)
    assert abs(cols[0].shift_a_m) < 0.05 and abs(cols[0].shift_b_m) < 0.05
    assert abs(cols[0].speed_change_a) < 0.005


def test_a_track_that_turns_back_is_split_at_its_turning_point():
    from flexmm.analysis.features.detect import Track, split_reversals

    t = np.arange(40.0)
    pos = np.where(t < 20, 10 + t, 50 - t) + 0.2 * np.sin(3 * t)  # out and back, with jitter
    tr = Track(1, list(range(40)), list(t), list(pos), [1.0] * 40)
    a, b = split_reversals(tr, 3.0)
    assert a.frames[-1] + 1 == b.frames[0] and abs(b.time[0] - 20) <= 1
    assert a.pos[-1] > a.pos[0] and b.pos[-1] < b.pos[0]
    assert split_reversals(Track(1, list(range(40)), list(t), list(10 + t + 0.2 * np.sin(3 * t)), [1.0] * 40),
                           3.0)[0].frames == list(range(40))  # jitter below 3 m is no reversal
