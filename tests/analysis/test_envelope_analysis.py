"""analysis.features.envelope.envelope_track on a synthetic moving sech envelope with a carrier."""
import numpy as np
import pytest

from flexmm.analysis.features.envelope import envelope_track
from flexmm.theory.envelope import SECH_FWHM


def test_envelope_track_recovers_position_amplitude_width_and_speed():
    n = np.arange(800)
    t = np.linspace(0.0, 10.0, 21)
    width, speed, amp = 25.0, 30.0, 0.01
    centre = 200.0 + speed * t[:, None]
    values = amp / np.cosh((n - centre) / width) * np.cos(2.8 * n - 1.3 * t[:, None])
    tr = envelope_track(t, values)
    assert np.allclose(tr.position, centre[:, 0], atol=0.3)
    assert np.allclose(tr.amplitude, amp, rtol=0.01)
    assert np.allclose(tr.fwhm, SECH_FWHM * width, rtol=0.01)
    assert tr.speed(0.0, 10.0) == pytest.approx(speed, rel=1e-3)
