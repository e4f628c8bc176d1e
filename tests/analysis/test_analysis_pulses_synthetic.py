"""Pulse extraction on synthetic datasets with known speed, width, amplitude and noise."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from flexmm.analysis import PulseNotFound, field_view, leading_pulse, measure_pulses
from flexmm.analysis.features.profiles import SHAPES, fit_profile, shape_fwhm
from synthetic import SynthPulse, pulse_dataset


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    sites_per_frame=st.floats(0.15, 1.0),
    width_sites=st.floats(1.5, 8.0),
    amplitude=st.floats(0.01, 2.0),
    sign=st.sampled_from([1, -1]),
    direction=st.sampled_from([1, -1]),
    noise=st.floats(0.0, 0.02),
    shape=st.sampled_from(["sech", "sech2"]),
    spacing=st.floats(1e-3, 1.0),
    dt=st.floats(1e-4, 10.0),
    travel_sites=st.floats(80.0, 160.0),
    seed=st.integers(0, 2**16),
)
def test_recovers_speed_and_width_within_half_percent(sites_per_frame, width_sites, amplitude, sign, direction,
                                                       noise, shape, spacing, dt, travel_sites, seed):
    """Random pulse crossing 80-160 of 200 sites, sampled at 0.15-1 site per frame."""
    n_frames = int(travel_sites / sites_per_frame) + 1
    v = direction * sites_per_frame * spacing / dt
    x0 = (20 if direction > 0 else 180) * spacing
    A = sign * amplitude
    ds = pulse_dataset([SynthPulse(A, v, width_sites * spacing, x0, shape)], n_sites=200, spacing_m=spacing,
                       duration_s=dt * (n_frames - 1), n_frames=n_frames, noise=noise * amplitude, seed=seed)
    pulses = measure_pulses(field_view(ds, "theta"))
    assert len(pulses) == 1
    p = pulses[0]
    assert p.direction == direction and p.polarity == sign
    assert p.speed_m_s == pytest.approx(abs(v), rel=5e-3)
    width = p.width_sech_m if shape == "sech" else p.width_sech2_m
    assert width == pytest.approx(width_sites * spacing, rel=5e-3)
    assert p.amplitude == pytest.approx(A, rel=0.02, abs=3 * noise * amplitude)
    assert p.speed_stderr_m_s < 5e-3 * abs(v)


def test_fit_shapes_and_their_fwhm():
    x = np.linspace(-20, 20, 401)
    for shape in ("sech", "sech2"):
        f = fit_profile(x, SHAPES[shape](x, 0.7, 1.3, 2.5), shape, (0.5, 0.0, 2.0))
        assert f.ok and f.W == pytest.approx(2.5, rel=1e-6) and f.center == pytest.approx(1.3, abs=1e-6)
        y = SHAPES[shape](x, 1.0, 0.0, 2.5)
        above = x[y >= 0.5]
        assert shape_fwhm(shape, 2.5) == pytest.approx(above[-1] - above[0], abs=0.2)
    # the §1.3 profile 1/(D1 + D2 cosh z): b = D1 A recovered, b = 0 is sech
    y = SHAPES["kg"](x, 0.4, 0.0, 3.0, -0.6)
    f = fit_profile(x, y, "kg", (0.3, 0.5, 2.0))
    assert f.b == pytest.approx(-0.6, abs=1e-5) and f.W == pytest.approx(3.0, rel=1e-5)
    assert np.allclose(SHAPES["kg"](x, 1.0, 0.0, 2.0, 0.0), SHAPES["sech"](x, 1.0, 0.0, 2.0))


def test_train_of_attenuating_pulses():
    train = [SynthPulse(0.3, 1.0, 3.0, 20.0 - 40 * k, "sech2", attenuation_per_m=0.002) for k in range(4)]
    ds = pulse_dataset(train, duration_s=300, n_frames=1001, noise=0.003)
    pulses = measure_pulses(field_view(ds, "theta"))
    assert len(pulses) == 4
    for p in pulses:
        assert p.speed_m_s == pytest.approx(1.0, rel=2e-3)
        assert p.attenuation_per_m == pytest.approx(0.002, rel=0.05)
        assert p.width_sech2_m == pytest.approx(3.0, rel=0.01)
        assert abs(p.amplitude_last) < abs(p.amplitude_first)


@pytest.mark.parametrize("sign", [1, -1])
def test_two_colliding_pulses_are_followed_through_the_collision(sign):
    pair = [SynthPulse(0.3, 1.5, 3.0, 20.0), SynthPulse(0.3 * sign, -1.2, 4.0, 180.0)]
    pulses = measure_pulses(field_view(pulse_dataset(pair, noise=0.003), "theta"))
    assert len(pulses) == 2
    right, left = sorted(pulses, key=lambda p: -p.direction)
    assert (right.direction, left.direction) == (1, -1)
    assert right.speed_m_s == pytest.approx(1.5, rel=2e-3) and left.speed_m_s == pytest.approx(1.2, rel=2e-3)
    assert right.width_sech_m == pytest.approx(3.0, rel=0.01) and left.width_sech_m == pytest.approx(4.0, rel=0.01)
    assert np.sign(left.amplitude) == sign
    # each pulse crosses the collision point: sites on both sides were fitted
    assert left.first_site < 90 < left.last_site and right.first_site < 90 < right.last_site


def test_strain_and_velocity_fields_and_polarity():
    x0, v, W = 20.0, 0.8, 4.0
    ds = pulse_dataset([SynthPulse(-0.05, v, W, x0, "sech2")], field="u", units="m")
    ds["u"] = ds["u"].cumsum("site")  # u whose bond strain is the (compressive) pulse
    ds["u_dot"] = ds["u"].differentiate("time")
    ds["u"].attrs["units"] = "m"
    p = measure_pulses(field_view(ds, "strain"))[0]
    assert p.polarity == -1 and p.polarity_label == "compressive"
    assert p.speed_m_s == pytest.approx(v, rel=3e-3)
    assert measure_pulses(field_view(ds, "velocity"))[0].speed_m_s == pytest.approx(v, rel=3e-3)


def test_temporal_width_matches_spatial_width_over_speed():
    ds = pulse_dataset([SynthPulse(1.0, 2.0, 3.0, 20.0, "sech")], duration_s=80, n_frames=1601)
    p = measure_pulses(field_view(ds, "theta"))[0]
    assert p.fwhm_m == pytest.approx(shape_fwhm("sech", 3.0), rel=0.02)
    assert p.temporal_fwhm_s == pytest.approx(shape_fwhm("sech", 3.0) / 2.0, rel=0.02)


def test_no_pulse_is_reported():
    ds = pulse_dataset([], noise=0.0)
    with pytest.raises(PulseNotFound):
        measure_pulses(field_view(ds, "theta"))
    standing = pulse_dataset([SynthPulse(0.5, 0.0, 3.0, 100.0)])
    with pytest.raises(PulseNotFound, match="travelling"):
        measure_pulses(field_view(standing, "theta"))


def test_leading_pulse_still_works():
    ds = pulse_dataset([SynthPulse(0.2, 1.0, 3.0, 20.0)])
    p = leading_pulse(ds, "theta")
    assert p.speed_m_s == pytest.approx(1.0, rel=5e-3)
    assert p.fwhm_sites == pytest.approx(2 * 3.0 * math.acosh(2.0), rel=0.05)
