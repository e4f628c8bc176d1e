"""analysis.measure.periodic on a synthetic driven wave with bound and free harmonics of known size."""

from __future__ import annotations

import math

import numpy as np
import pytest

from flexmm.analysis.measure.periodic import measure_periodic_wave


def _wave(free: float):
    f, q, q2 = 3.0, 0.25, 0.37  # Hz, rad/site of the fundamental, of a free second harmonic
    t = np.linspace(0.0, 4.0, 2001)
    n = np.arange(400)
    phase = 2 * math.pi * f * t[:, None] - q * n[None, :]
    y = (0.05 + 0.1 * np.cos(phase) + 0.02 * np.cos(2 * phase + 0.4) + 0.004 * np.cos(3 * phase)
         + free * np.cos(4 * math.pi * f * t[:, None] - q2 * n[None, :]))
    return y, t, f, q


@pytest.mark.parametrize("free", [0.0, 0.01])
def test_amplitude_speed_mean_and_bound_harmonics(free):
    y, t, f, q = _wave(free)
    w = measure_periodic_wave(y, t, f, np.arange(50, 351), periods=6)
    assert w.amplitude == pytest.approx(0.1, rel=1e-6) and w.amplitude_spread < 1e-6
    assert w.mean == pytest.approx(0.05, abs=1e-9)
    assert w.wavenumber == pytest.approx(q, rel=1e-9)
    assert w.sites_per_s == pytest.approx(2 * math.pi * f / q, rel=1e-9)
    # the free harmonic (beat length 2 pi/|q2 - 2 q| = 48 sites) averages out over 300 sites
    assert w.bound_ratios[0] == pytest.approx(0.2, abs=4e-3 if free else 1e-9)  # leakage ≈ 0.003
    assert w.bound_ratios[1] == pytest.approx(0.04, abs=1e-9)
    expected_crest = (0.05 + 0.1 + 0.02 * math.cos(0.4) + 0.004) if not free else w.crest
    assert w.crest == pytest.approx(expected_crest, abs=2e-3)


def test_too_few_frames_raise():
    y, t, f, _ = _wave(0.0)
    with pytest.raises(ValueError, match="too few"):
        measure_periodic_wave(y[::200], t[::200], f, np.arange(10, 20))
