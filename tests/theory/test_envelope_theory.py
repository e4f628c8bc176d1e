"""flexmm.theory.envelope: the rotational branch, the focusing windows and the cubic frequency shift."""
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from flexmm.theory.envelope import envelope_soliton, rotational_omega, rotational_wavenumber
from flexmm.theory.rotating import dispersion_chain, lego_parameters


@pytest.fixture
def lego():
    return lego_parameters(0.0)


def test_rotational_branch_is_the_exact_dispersion(lego):
    q = np.linspace(0.1, 3.0, 12)
    lower, upper = dispersion_chain(lego, q)
    acoustic = 2 * np.abs(np.sin(q / 2))
    rot = np.where(np.isclose(lower, acoustic), upper, lower)
    assert np.allclose([rotational_omega(lego, x) for x in q], rot, rtol=1e-12)
    assert [rotational_wavenumber(lego, rotational_omega(lego, x)) for x in q] == pytest.approx(q, rel=1e-10)
    with pytest.raises(ValueError, match="outside the rotational band"):
        rotational_wavenumber(lego, 1.1 * rotational_omega(lego, math.pi))


def test_focusing_windows_of_the_lego_chain(lego):
    def focusing(q):
        return envelope_soliton(lego, rotational_omega(lego, q)).focusing
    assert focusing(0.3) and focusing(2.8) and not focusing(1.5)
    sol = envelope_soliton(lego, rotational_omega(lego, 2.8))
    assert sol.dispersion < 0 < sol.delta0 and sol.product == pytest.approx(0.2107, rel=1e-3)
    with pytest.raises(ValueError, match="θ0 = 0"):
        envelope_soliton(lego_parameters(0.1), 0.3)


def _ring_rhs(p, n_sites):
    """The chain equations of docs/physics.md §1.1 (θ0 = 0, s_v = 0) on a ring, written out in numpy."""
    def rhs(_t, y):
        u, th, ud, tdot = np.split(y, 4)
        up, um, tp, tm = np.roll(u, -1), np.roll(u, 1), np.roll(th, -1), np.roll(th, 1)
        uacc = up - 2 * u + um - 0.5 * (np.cos(tp) - np.cos(tm))
        bracket = up - um + 2 - 0.5 * (np.cos(tp) + 2 * np.cos(th) + np.cos(tm))
        tacc = (-0.5 * np.sin(th) * bracket + p.Ks / 4 * np.cos(th) * (np.sin(tp) + np.sin(tm) - 2 * np.sin(th))
                - p.Ktheta * (tp + 2 * th + tm) - 2 * p.n_v * p.Ktheta * th) / p.alpha2
        return np.concatenate([ud, tdot, uacc, tacc])
    return rhs


@pytest.mark.parametrize("mode", [6, 28])
def test_cubic_frequency_shift_of_a_uniform_wave(lego, mode):
    """A travelling wave θ = 2a cos(qn − Ωt) on a ring shifts its frequency by δ0_uniform a²."""
    n_sites, a = 64, 0.003
    q = 2 * math.pi * mode / n_sites
    omega = rotational_omega(lego, q)
    sol = envelope_soliton(lego, omega)
    n = np.arange(n_sites)
    bound = 0.5j * math.sin(2 * q) * a**2 / (4 * (math.sin(q) ** 2 - omega**2))  # the 2Ω strain wave
    y0 = np.concatenate([2 * np.real(bound * np.exp(2j * q * n)), 2 * a * np.cos(q * n),
                         2 * np.real(-2j * omega * bound * np.exp(2j * q * n)), 2 * a * omega * np.sin(q * n)])
    t = np.linspace(0, 30 * 2 * math.pi / omega, 1201)
    out = solve_ivp(_ring_rhs(lego, n_sites), (0, t[-1]), y0, t_eval=t, rtol=1e-10, atol=1e-13, method="DOP853")
    amp = (out.y[n_sites:2 * n_sites] * np.exp(-1j * q * n)[:, None]).sum(axis=0) / n_sites
    measured = -np.polyfit(t, np.unwrap(np.angle(amp)), 1)[0] - omega
    assert measured == pytest.approx(sol.delta0_uniform * a**2, rel=0.02)
