"""Running-wave split (flexmm.analysis.measure.reflection) on synthetic signals with known waves."""
import numpy as np
import pytest

from flexmm.analysis.measure.reflection import complex_amplitudes, running_waves


def test_split_recovers_left_and_right_waves_at_one_harmonic():
    f, q, q2 = 50.0, 0.4, 0.9
    t = np.linspace(0.0, 0.2, 2001)
    n = np.arange(60)
    # y = Re(R e^{i(qn − ωt)}) + Re(L e^{−i(qn + ωt)}) at f, plus a wave at 2f and an offset
    right, left = 1.0e-3 * np.exp(0.3j), 2.5e-4 * np.exp(-1.1j)
    ph = 2 * np.pi * f * t[:, None]
    y = (np.real(right * np.exp(1j * (q * n - ph))) + np.real(left * np.exp(-1j * (q * n + ph)))
         + 3e-5 * np.cos(q2 * n - 2 * ph) + 0.01)
    w = running_waves(complex_amplitudes(t, y, f, 0.02, 0.2), n, q)
    assert w.right == pytest.approx(right, abs=1e-9)
    assert w.left == pytest.approx(left, abs=1e-9)
    assert w.residual < 1e-9
    w2 = running_waves(complex_amplitudes(t, y, 2 * f, 0.02, 0.2), n, q2)
    assert abs(w2.right) == pytest.approx(3e-5, rel=1e-6) and abs(w2.left) < 1e-10
