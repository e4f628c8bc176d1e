"""Second-order reflection theory (flexmm.theory.boundary_harmonics) against closed forms.

A monatomic chain (m = k = 1) whose last site N−1 is held by a wall spring with force
−k_w x − β x². In the chain u_n = I e^{iqn} + ρ I e^{−iqn} at ω; the wall condition at site N−1,
−ω² u_{N−1} = u_{N−2} − u_{N−1} − k_w u_{N−1}, fixes ρ. At 2ω the source −β X1_{N−1}²/2 acts at
site N−1 only and the chain carries the outgoing wave alone, X2_n = X2_{N−1} e^{−iq2 (n − N + 1)}
with X2_{N−1} = s / (1 + k_w − e^{iq2} − 4ω²).
"""
import cmath
import math

import numpy as np
import pytest

from flexmm.theory.boundary_harmonics import boundary_reflection, outgoing_root


def wall_chain(n, kw, beta):
    def force(q):
        f = np.zeros_like(q)
        d = np.diff(q)
        f[:-1] += d
        f[1:] -= d
        f[-1] -= kw * q[-1] + beta * q[-1] ** 2
        return f
    return force


@pytest.mark.parametrize("omega", [0.4, 0.7, 1.2])  # 2ω = 2.4 lies above the band (evanescent)
def test_wall_with_quadratic_spring_matches_closed_form(omega):
    n, kw, beta, inc = 12, 0.3, 0.8, 1e-3
    res = boundary_reflection(wall_chain(n, kw, beta), np.zeros(n), np.ones(n), 0, omega, inc, 1.0, 1.0)
    q = 2 * math.asin(omega / 2)
    z = cmath.exp(1j * q)
    # wall condition on u_n = I (z^n + ρ z^-n): (1 + k_w − ω²) u_{N−1} = u_{N−2}
    a, b = n - 1, n - 2
    rho = -((1 + kw - omega**2) * z**a - z**b) / ((1 + kw - omega**2) * z**-a - z**-b)
    assert abs(res.r1 - rho * inc) < 1e-7 * inc
    assert abs(rho) == pytest.approx(1.0, abs=1e-12)  # lossless wall: total reflection
    x1_end = inc * (z**a + rho * z**-a)
    assert abs(res.x1[-1] - x1_end) < 1e-7 * inc
    z2 = outgoing_root(2 * omega, 1.0, 1.0)
    x2_end = (-beta * x1_end**2 / 2) / (1 + kw - z2 - 4 * omega**2)
    assert abs(res.x2[-1] - x2_end) < 1e-6 * abs(x2_end)
    assert abs(res.r2 - x2_end * z2 ** (n - 1)) < 1e-6 * abs(x2_end)
    # second order: the 2ω reflection scales with the square of the incident amplitude
    twice = boundary_reflection(wall_chain(n, kw, beta), np.zeros(n), np.ones(n), 0, omega, 2 * inc, 1.0, 1.0)
    assert abs(twice.r2) == pytest.approx(4 * abs(res.r2), rel=1e-6)


def test_linear_wall_reflects_no_second_harmonic():
    res = boundary_reflection(wall_chain(8, 0.3, 0.0), np.zeros(8), np.ones(8), 0, 0.5, 1e-3, 1.0, 1.0)
    assert abs(res.r2) < 1e-12


def test_outgoing_root_runs_left_or_decays():
    z = outgoing_root(1.0, 1.0, 1.0)
    assert abs(abs(z) - 1) < 1e-12 and z.imag > 0  # e^{iq}, q in (0, π)
    z = outgoing_root(2.5, 1.0, 1.0)
    assert abs(z) < 1  # above the band edge 2: decays into the chain
