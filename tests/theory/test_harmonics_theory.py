"""flexmm.theory.harmonics against the forced recurrence it solves and the continuum limit."""
import math

import numpy as np
import pytest

from flexmm.theory.harmonics import fpu_second_harmonic


def _solve_recurrence(amp, omega, k1, k2, m, n_sites):
    """2ω response of the second-order equation, solved as a banded linear system.

    −4mω² w_n − k1 (w_{n+1} − 2w_n + w_{n−1}) = k2 [B_n² − B_{n−1}²]/2, B_n the complex first-order
    elongation of bond n; w_0 = 0; at the far end the outgoing-wave condition w_N = w_{N−1} e^{i q2}.
    """
    q = 2 * math.asin(omega / (2 * math.sqrt(k1 / m)))
    q2 = 2 * math.asin(omega / math.sqrt(k1 / m))
    n = np.arange(n_sites + 1)
    x1 = amp * np.exp(1j * q * n)  # first order, x_n = Re[x1_n e^{-iωt}]
    b = np.diff(x1)
    rhs_full = 0.5 * k2 * (b[1:] ** 2 - b[:-1] ** 2)  # sites 1..N−1
    size = n_sites - 1  # unknowns w_1..w_{N−1}
    mat = np.zeros((size, size), complex)
    diag = -4 * m * omega**2 + 2 * k1
    for i in range(size):
        mat[i, i] = diag
        if i > 0:
            mat[i, i - 1] = -k1
        if i < size - 1:
            mat[i, i + 1] = -k1
    mat[-1, -1] += -k1 * np.exp(1j * q2)  # w_N = w_{N−1} e^{i q2}, a partially particular tail
    # the forced part also continues past N: put the mismatch of the particular solution into the rhs
    p_part = rhs_full[0] / (np.exp(2j * q) * (diag - 2 * k1 * math.cos(2 * q)))
    rhs = rhs_full.copy()
    rhs[-1] += k1 * p_part * (np.exp(2j * q * n_sites) - np.exp(2j * q * (n_sites - 1) + 1j * q2))
    w = np.linalg.solve(mat, rhs)
    return np.abs(np.concatenate([[0.0], w]))


@pytest.mark.parametrize("ratio", [0.1, 0.25, 0.4])
def test_second_harmonic_solves_forced_recurrence(ratio):
    k1, k2, m, amp = 3.0, 7.0, 0.5, 0.01
    omega = 2 * ratio * math.sqrt(k1 / m)
    n = 300
    numeric = _solve_recurrence(amp, omega, k1, k2, m, n)
    sh = fpu_second_harmonic(amp, omega, k1, k2, m)
    closed = sh.amplitude(np.arange(n))
    assert np.max(np.abs(numeric - closed)) < 1e-9 * np.max(closed)


def test_long_wave_limit_is_the_continuum_growth_law():
    """x2 ≈ k2 A² q² n/(4 k1) for q → 0 and n ≪ coherence length (nondispersive quadratic medium)."""
    k1, k2, m, amp = 1.0, 2.0, 1.0, 0.01
    omega = 0.02
    sh = fpu_second_harmonic(amp, omega, k1, k2, m)
    n = 0.01 * sh.coherence_length
    assert sh.amplitude(n) == pytest.approx(k2 * amp**2 * sh.q**2 * n / (4 * k1), rel=1e-3)
    assert sh.mismatch == pytest.approx(-sh.q**3 / 4, rel=1e-3)


def test_second_harmonic_above_half_band_is_refused():
    with pytest.raises(ValueError, match="half the band edge"):
        fpu_second_harmonic(0.01, 1.1, 1.0, 1.0, 1.0)
