"""Formation transient, breathing and arrest on synthetic datasets with known answers."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from flexmm.analysis import field_view, measure_fronts, measure_pulses
from flexmm.analysis.measure.steady import steady_part
from synthetic import SynthPulse, front_dataset, pulse_dataset

# each example analyses a whole dataset (~1 s): report a failure as found rather than shrink it for minutes
NO_SHRINK = (Phase.explicit, Phase.reuse, Phase.generate)


@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.too_slow],
          phases=NO_SHRINK, derandomize=True)
@given(formation=st.floats(15.0, 60.0), start=st.floats(0.4, 0.8), amp=st.floats(0.1, 1.0),
       width=st.floats(2.0, 4.0), noise=st.floats(0.0, 0.003), seed=st.integers(0, 999))
def test_formation_distance_and_steady_amplitude(formation, start, amp, width, noise, seed):
    """Amplitude rising linearly from start·A to A over ``formation`` sites, then steady."""
    ds = pulse_dataset([SynthPulse(amp, 1.0, width, 10.0, formation_m=formation, start_fraction=start)],
                       n_sites=260, duration_s=220.0, n_frames=881, noise=noise * amp, seed=seed)
    (p,) = measure_pulses(field_view(ds, "theta"))
    # steady once within the band's margin (1 % of A, or 2 noise σ) of its final value: the ramp
    # reaches A − margin at formation·(1 − margin/((1 − start)A)); the peak a site sees comes
    # from the whole pulse, so the end of the ramp is located within about a width W
    assert p.formation_distance_m == pytest.approx(formation, abs=0.05 * formation + width + 1.0)
    assert p.formation_time_s == pytest.approx(p.formation_distance_m, rel=0.05, abs=1.0)  # v = 1
    assert p.amplitude == pytest.approx(amp, rel=0.01)  # the steady value, not the mean over the ramp
    assert not p.breathing


def test_no_formation_for_a_steady_pulse():
    (p,) = measure_pulses(field_view(pulse_dataset([SynthPulse(0.5, 1.0, 3.0, 20.0)], noise=0.002), "theta"))
    assert p.formation_distance_m == 0.0 and not p.breathing


@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.too_slow],
          phases=NO_SHRINK, derandomize=True)
@given(b=st.floats(0.04, 0.2), period=st.floats(12.0, 40.0), amp=st.floats(0.1, 1.0),
       noise=st.floats(0.0, 0.003), seed=st.integers(0, 999))
def test_breathing_range_and_period(b, period, amp, noise, seed):
    ds = pulse_dataset([SynthPulse(amp, 1.0, 3.0, 10.0, breathing=b, breathing_period_s=period)],
                       n_sites=260, duration_s=220.0, n_frames=881, noise=noise * amp, seed=seed)
    (p,) = measure_pulses(field_view(ds, "theta"))
    assert p.breathing
    assert p.amplitude_min == pytest.approx(amp * (1 - b), rel=0.02)
    assert p.amplitude_max == pytest.approx(amp * (1 + b), rel=0.02)
    assert p.breathing_period_s == pytest.approx(period, rel=0.06)


def test_steady_part_is_exact_on_a_clean_series():
    d = np.arange(100.0)
    a = np.where(d < 30, 0.5 + 0.5 * d / 30, 1.0)
    s = steady_part(d, d / 2, -a)
    assert s.start == 30 and s.formation_distance_m == 30.0 and s.formation_time_s == 15.0
    assert s.amplitude_min == s.amplitude_max == -1.0 and not s.breathing


@pytest.mark.parametrize("creep, arrested", [(0.0, True), (0.02, False), (0.01, False), (0.003, True)])
def test_front_is_arrested_only_when_its_speed_is_statistically_zero(creep, arrested):
    """A front that slows at x = 120 to ``creep`` (1–2 % of its speed) is still moving; slower than
    one site per run (150 s, 1 m sites: 0.0067 m/s) it cannot be told from a stopped, relaxing one."""
    ds = front_dataset(speed_m_s=1.0, width_m=3.0, arrest_m=120.0, creep_m_s=creep, noise=1e-4)
    (f,) = measure_fronts(field_view(ds, "u"))
    assert f.arrested is arrested
    if creep:
        assert f.final_speed_m_s == pytest.approx(creep, rel=0.1)
        assert f.final_speed_ci_m_s < f.final_speed_m_s  # statistically non-zero either way
    else:
        assert f.final_speed_m_s <= f.final_speed_ci_m_s
