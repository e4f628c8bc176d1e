"""analysis.measure.harmonics on synthetic signals with known harmonic amplitudes."""
import numpy as np
import pytest

from flexmm.analysis.measure.harmonics import harmonic_profiles


def test_harmonic_profiles_recover_known_amplitudes():
    f = 50.0
    t = np.linspace(0.0, 0.4, 2001)
    n = np.arange(40)
    a1 = 1e-3 * np.ones_like(n, float)
    a2 = 2e-5 * np.sin(0.1 * n) ** 2
    a3 = 3e-6 * np.ones_like(n, float)
    w = 2 * np.pi * f
    y = (a1 * np.sin(w * t[:, None] - 0.3 * n) + a2 * np.cos(2 * w * t[:, None] - 0.7 * n)
         + a3 * np.sin(3 * w * t[:, None]) + 5e-4)
    h = harmonic_profiles(t, y, f, 0.1, 0.4)
    assert h.shape == (3, n.size)
    np.testing.assert_allclose(h[0], a1, rtol=1e-6)
    np.testing.assert_allclose(h[1], a2, atol=1e-9 * a1[0])
    np.testing.assert_allclose(h[2], a3, atol=1e-9 * a1[0])


def test_harmonic_profiles_window_shorter_than_a_period():
    t = np.linspace(0.0, 1.0, 101)
    with pytest.raises(ValueError, match="shorter than one drive period"):
        harmonic_profiles(t, np.zeros((101, 3)), 1.0, 0.5, 1.0)
