"""analysis.measure.breathers.site_oscillation on synthetic signals of known frequency."""
import numpy as np
import pytest

from flexmm.analysis.measure.breathers import site_oscillation
from flexmm.theory.breathers import SineGordonBreather


def test_frequency_of_a_breather_time_series():
    b = SineGordonBreather(0.7, 5.0)
    omega0 = 2 * np.pi * 37.0
    t = np.linspace(0.0, 1.0, 3001)
    y = b.phi(0.0, omega0 * t)  # strongly non-sinusoidal
    osc = site_oscillation(t, y)
    assert osc.frequency_hz == pytest.approx(0.7 * 37.0, rel=1e-5)
    assert osc.peak == pytest.approx(b.amplitude, rel=1e-3)
    assert osc.n_periods >= 24


def test_too_few_crossings():
    t = np.linspace(0, 1, 50)
    with pytest.raises(ValueError, match="too few"):
        site_oscillation(t, np.sin(2 * np.pi * t))
