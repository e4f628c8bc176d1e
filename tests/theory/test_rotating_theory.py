"""Tests for flexmm.theory.rotating against independent oracles (docs/physics.md §1).

Oracles: the ODEs themselves (finite differences), closed forms quoted in docs/physics.md, Taylor
expansions, the exact discrete linear dispersion, a numerical Hessian of the discrete chain, and
short simulations of the discrete equations of motion written here from docs/physics.md §1.1.
"""
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from scipy import integrate, linalg, optimize

from flexmm.theory import rotating as rt
from flexmm.theory.rotating import RotatingChainND

GAP = RotatingChainND(0.0, 0.5, 1e-3, 1.0)                 # theta0 = 0, amplitude gap
NOGAP = RotatingChainND(0.0, 0.5, 1e-3, 0.1)               # alpha2 < Ks/4 - Ktheta
PRE = RotatingChainND(0.3, 0.5, 1e-3, 1.0)                 # predeformed chain
SHEET = RotatingChainND(0.0, 2.0, 1e-2, 0.2, n_v=2, s_v=1)  # planar wave in a wide sheet
LEGO = rt.lego_parameters()
import os

from conftest import LEGO_PARAMETERS

HYP = settings(max_examples=int(os.environ.get("FLEXMM_HYP_EXAMPLES", 40)), deadline=None,
               suppress_health_check=[HealthCheck.too_slow])


# ---------------------------------------------------------------- independent helpers
def G(p, th):
    return math.cos(p.theta0) - np.cos(p.theta0 + th)


def S_of(p, c):
    return c * c / (c * c - p.eta**2) + p.n_v * p.s_v / 2


def D_phys(p, c):
    return p.alpha2 * c * c - (p.eta**2 / 4) * (p.Ks * p.eta**2 - p.s0**2 - 4 * p.Ktheta)


def gam(p):
    return (4 + 2 * p.n_v) * p.Ktheta


def d1(f, h):
    return (-f[4:] + 8 * f[3:-1] - 8 * f[1:-3] + f[:-4]) / (12 * h)


def d2(f, h):
    return (-f[4:] + 16 * f[3:-1] - 30 * f[2:-2] + 16 * f[1:-3] - f[:-4]) / (12 * h * h)


def forces(p, U, th, periodic=False):
    """Nondimensional accelerations (U_TT, alpha2 theta_TT) of docs/physics.md §1.1."""
    if periodic:
        Ur, Ul, Tr, Tl = np.roll(U, -1), np.roll(U, 1), np.roll(th, -1), np.roll(th, 1)
    else:  # pulse far from the ends: zero strain / zero rotation ghosts
        Up, Tp = np.pad(U, 1, mode="edge"), np.pad(th, 1)
        Ur, Ul, Tr, Tl = Up[2:], Up[:-2], Tp[2:], Tp[:-2]
    c, s = np.cos(p.theta0 + th), np.sin(p.theta0 + th)
    cr, cl, sr, sl = (np.cos(p.theta0 + Tr), np.cos(p.theta0 + Tl),
                      np.sin(p.theta0 + Tr), np.sin(p.theta0 + Tl))
    fU = Ur - 2 * U + Ul - 0.5 * (cr - cl)
    fT = (-0.5 * s * (Ur - Ul + 2 * p.eta - 0.5 * (cr + 2 * c + cl))
          + p.Ks / 4 * c * (sr + sl - 2 * s) - p.Ktheta * (Tr + 2 * th + Tl)
          - p.n_v * (p.s_v * 0.5 * (p.eta - c) * s + 2 * p.Ktheta * th))
    return fU, fT


def simulate(p, state, T, n_out=11, onsite=None):
    """Integrate the chain of docs/physics.md §1.1 (plus an on-site torque -onsite(theta), if given)."""
    N = state.U.size

    def rhs(t, y):
        U, th, V, W = y.reshape(4, N)
        fU, fT = forces(p, U, th)
        if onsite is not None:
            fT = fT - onsite(th)
        return np.concatenate([V, W, fU, fT / p.alpha2])

    y0 = np.concatenate([state.U, state.theta, state.U_dot, state.theta_dot])
    sol = integrate.solve_ivp(rhs, (0, T), y0, method="DOP853", rtol=1e-9, atol=1e-12,
                              t_eval=np.linspace(T / 2, T, n_out))
    return sol.t, sol.y.reshape(4, N, -1)


def random_params(draw, theta0_zero=False):
    th0 = 0.0 if theta0_zero else draw(st.floats(-0.6, 0.6))
    return RotatingChainND(th0, draw(st.floats(0.2, 3.0)), draw(st.floats(1e-4, 2e-2)),
                           draw(st.floats(0.05, 2.0)), draw(st.sampled_from([0, 1, 2])),
                           draw(st.sampled_from([0, 1])))


# ---------------------------------------------------------------- parameters
def test_lego_and_from_si_agree_with_the_documented_values():
    a, kl, m = (LEGO_PARAMETERS[k] for k in ("a_m", "k_long_n_per_m", "mass_kg"))
    p = RotatingChainND.from_si(a, 0.0, kl, 1.851e-2 * kl, 1.534e-4 / 4 * kl * a**2, m,
                                m * a**2 / (4 * 1.815**2), n_v=1, s_v=0)
    q = rt.lego_parameters()
    for f in ("theta0", "Ks", "Ktheta", "alpha2", "n_v", "s_v"):
        assert getattr(p, f) == pytest.approx(getattr(q, f), rel=1e-12)
    assert q.Ks == 1.851e-2 and q.Ktheta == pytest.approx(3.835e-5)


@pytest.mark.parametrize("bad", [dict(alpha2=0.0), dict(n_v=3), dict(s_v=2), dict(theta0=2.0)])
def test_invalid_parameters_raise(bad):
    kw = dict(theta0=0.0, Ks=0.5, Ktheta=1e-3, alpha2=1.0) | bad
    with pytest.raises(ValueError):
        RotatingChainND(**kw)


# ---------------------------------------------------------------- cubic Klein-Gordon soliton
def _check_kg(p, c, branch):
    C1, C2, C3 = rt.continuum_coefficients(p, c)
    W = rt.soliton_width(p, c)
    h = W / 200
    z = np.arange(-30 * W, 30 * W, h)
    th = rt.soliton_profile(p, c, z, branch)
    assert np.all(np.isfinite(th)) and np.all(th * th[len(z) // 2] > 0)
    rhs = C1 * th + C2 * th**2 + C3 * th**3
    err = np.abs(d2(th, h) - rhs[2:-2]).max() / np.abs(rhs).max()
    assert err < 1e-5


@pytest.mark.parametrize("p,frac", [(GAP, 0.5), (LEGO, 0.6), (PRE, 0.7), (SHEET, 0.9), (NOGAP, 0.95)])
@pytest.mark.parametrize("branch", [1, -1])
def test_cubic_soliton_satisfies_klein_gordon(p, frac, branch):
    c_lo = p.eta * math.sqrt(0.5 * p.n_v * p.s_v / (1 + 0.5 * p.n_v * p.s_v))
    c = c_lo + frac * (min(rt.rotational_cutoff_speed(p), rt.long_wave_speed(p)) - c_lo)
    _check_kg(p, c, branch)


@HYP
@given(st.data())
def test_cubic_soliton_satisfies_klein_gordon_random(data):
    p = random_params(data.draw)
    c = data.draw(st.floats(0.05, 0.95)) * min(rt.rotational_cutoff_speed(p), rt.long_wave_speed(p))
    assume(c > 1e-3 and abs(c - p.eta) > 1e-3)
    C1, C2, C3 = rt.continuum_coefficients(p, c)
    assume(C1 > 1e-6)
    for branch in (1, -1):
        try:
            rt.soliton_profile(p, c, 0.0, branch)
        except ValueError:
            continue
        _check_kg(p, c, branch)


def test_coefficients_are_the_taylor_expansion_of_the_hinge_force():
    for p, c in [(PRE, 0.12), (SHEET, 0.65), (RotatingChainND(-0.4, 1.0, 2e-3, 0.3, 1, 1), 0.5)]:
        C1, C2, C3 = rt.continuum_coefficients(p, c)
        S, D = S_of(p, c), D_phys(p, c)
        errs = []
        for th in (0.02, 0.01):
            full = -(S * G(p, th) * math.sin(p.theta0 + th) + gam(p) * th) / D
            errs.append(abs(full - (C1 * th + C2 * th**2 + C3 * th**3)))
        expected = 16 if p.theta0 else 32  # O(theta^4) remainder; O(theta^5) when the force is odd
        assert errs[0] / errs[1] == pytest.approx(expected, rel=0.25)


def test_only_the_regular_branch_is_returned():
    p = RotatingChainND(0.8, 2.0, 0.01, 1.0)  # tan^2(theta0) > 3/4: C3/C1 > 0
    c = 0.9 * rt.long_wave_speed(p)
    C1, C2, C3 = rt.continuum_coefficients(p, c)
    assert C1 > 0 and 0 < C3 / (2 * C1) < C2**2 / (9 * C1**2)
    _check_kg(p, c, +1)
    with pytest.raises(ValueError, match="singular"):
        rt.soliton_profile(p, c, 0.0, -1)


def test_no_soliton_raises():
    with pytest.raises(ValueError):
        rt.soliton_width(GAP, 0.5)  # above the rotational cut-off: C1 < 0
    with pytest.raises(ValueError):
        rt.continuum_coefficients(GAP, 1.0)


@pytest.mark.parametrize("p", [GAP, LEGO, NOGAP])
def test_width_theta0_zero_closed_form(p):
    for c in np.linspace(0.05, 0.9, 5) * min(rt.rotational_cutoff_speed(p), 1.0):
        W2 = (p.Ks / 4 - p.Ktheta - p.alpha2 * c * c) / gam(p)
        assert rt.soliton_width(p, c) ** 2 == pytest.approx(W2, rel=1e-12)
        A2 = -2 * rt.continuum_coefficients(p, c)[0] / rt.continuum_coefficients(p, c)[2]
        assert rt.soliton_profile(p, c, 0.0) == pytest.approx(math.sqrt(A2), rel=1e-12)


# ---------------------------------------------------------------- exact speed law
def test_speed_law_closed_forms():
    A = np.linspace(0.01, 2.0, 50)
    g = gam(GAP)
    assert np.allclose(rt.soliton_speed(GAP, A) ** 2, g * A**2 / (g * A**2 + (1 - np.cos(A)) ** 2), rtol=1e-12)
    for p in (PRE, SHEET, RotatingChainND(-0.2, 1.0, 3e-3, 0.5, 1, 1)):
        for a in (-1.3, -0.2, 0.1, 0.9):
            Q = gam(p) * a * a / G(p, a) ** 2 + p.n_v * p.s_v / 2
            assert rt.soliton_speed(p, a) ** 2 == pytest.approx(p.eta**2 * Q / (1 + Q), rel=1e-10)


def test_speed_law_small_amplitude_matches_cubic_truncation_to_order_A4():
    g = gam(GAP)
    ratios = []
    for A in (0.04, 0.02, 0.01):
        approx = 4 * g / (4 * g + A * A)
        lead = A**4 / (24 * g * (1 + A * A / (4 * g)) ** 2)  # derived next-order term
        ratios.append((rt.soliton_speed(GAP, A) ** 2 - approx) / lead)
    dev = np.abs(np.array(ratios) - 1)
    assert dev[-1] < 1e-3 and dev[0] / dev[1] > 3 and dev[1] / dev[2] > 3


@HYP
@given(st.data())
def test_amplitude_inverts_speed(data):
    p = random_params(data.draw)
    sign = data.draw(st.sampled_from([1, -1]))
    branches = ["main"] + (["short"] if sign * p.theta0 < 0 else [])
    branch = data.draw(st.sampled_from(branches))
    lo, hi = rt._branch(p, sign, branch)
    A = sign * (lo + data.draw(st.floats(0.02, 0.98)) * (hi - lo))
    c = float(rt.soliton_speed(p, A))
    assume(abs(np.gradient(rt.soliton_speed(p, A + np.array([-1e-6, 0, 1e-6])))[1]) > 1e-12)
    assert rt.soliton_amplitude(p, c, sign, branch) == pytest.approx(A, rel=1e-8, abs=1e-10)


def test_main_branch_speed_decreases_and_round_trips():
    for p in (GAP, PRE, LEGO):
        lo, hi = rt._branch(p, 1, "main")
        A = np.linspace(lo, hi, 200)[1:-1]
        c = rt.soliton_speed(p, A)
        assert np.all(np.diff(c) < 0)
        assert rt.soliton_amplitude(p, c[50]) == pytest.approx(A[50], rel=1e-10)
    with pytest.raises(ValueError, match="speeds span"):
        rt.soliton_amplitude(GAP, 1.01)


def test_branch_end_theta0_zero_is_tan_half_A_equals_A():
    end = rt._branch(GAP, 1, "main")[1]
    assert math.tan(end / 2) == pytest.approx(end, rel=1e-10)


def test_mirror_symmetry_theta0():
    q = RotatingChainND(-PRE.theta0, PRE.Ks, PRE.Ktheta, PRE.alpha2)
    A = np.array([-1.5, -0.7, 0.3, 1.1])
    assert np.allclose(rt.soliton_speed(PRE, A), rt.soliton_speed(q, -A), rtol=1e-13)
    assert rt.amplitude_gap(PRE, -1) == pytest.approx(rt.amplitude_gap(q, +1), rel=1e-10)


# ---------------------------------------------------------------- gap and cut-off speeds
@pytest.mark.parametrize("p", [GAP, LEGO])
def test_amplitude_gap_theta0_zero(p):
    c_theta = math.sqrt((p.Ks / 4 - p.Ktheta) / p.alpha2)
    assert rt.rotational_cutoff_speed(p) == pytest.approx(c_theta, rel=1e-12)
    Amin = rt.amplitude_gap(p)
    assert rt.soliton_speed(p, Amin) == pytest.approx(c_theta, rel=1e-10)
    assert rt.soliton_exists(p, 1.001 * Amin, "constant")
    assert not rt.soliton_exists(p, 0.999 * Amin, "constant")
    assert rt.amplitude_gap(p, -1) == pytest.approx(Amin, rel=1e-12)


def test_no_gap_and_opposite_polarity_gap():
    assert rt.amplitude_gap(NOGAP) == 0.0
    assert rt.soliton_exists(NOGAP, 1e-3, "constant")
    assert rt.amplitude_gap(PRE, +1) == 0.0
    Amin = rt.amplitude_gap(PRE, -1)
    assert Amin > 2 * PRE.theta0
    assert rt.soliton_exists(PRE, -1.001 * Amin, "constant")
    assert not rt.soliton_exists(PRE, -0.999 * Amin, "constant")


def test_long_wave_speed_is_lower_branch_slope():
    for p in (PRE, SHEET, LEGO, RotatingChainND(0.5, 1.0, 2e-3, 0.4, 1, 1)):
        q = 1e-4
        assert rt.long_wave_speed(p) == pytest.approx(p.eta * rt.dispersion_chain(p, q)[0] / q, rel=1e-6)


# ---------------------------------------------------------------- full first integral
def _profile_grid(p, A, gradient, half_width=25.0, n=20001):
    c = float(rt.soliton_speed(p, A))
    L = 1 / math.sqrt(rt.continuum_coefficients(p, c, gradient)[0])
    z = np.linspace(-half_width * L, half_width * L, n)
    th, Up = rt.exact_soliton(p, A, z, gradient)
    return c, z, z[1] - z[0], th, Up


@pytest.mark.parametrize("p,A", [(GAP, 0.56), (LEGO, 0.3), (PRE, 0.5), (PRE, -1.5), (SHEET, 0.8)])
def test_exact_soliton_constant_gradient_solves_full_ode(p, A):
    c, z, h, th, Up = _profile_grid(p, A, "constant")
    S, D = S_of(p, c), D_phys(p, c)  # S from c: checks the speed law as well
    rhs = -(S * G(p, th) * np.sin(p.theta0 + th) + gam(p) * th) / D
    assert np.abs(d2(th, h) - rhs[2:-2]).max() < 1e-6 * np.abs(rhs).max()
    fi = -(S * G(p, th) ** 2 + gam(p) * th**2) / D
    assert np.abs(d1(th, h) ** 2 - fi[2:-2]).max() < 1e-7 * fi.max()
    assert th[len(z) // 2] == pytest.approx(A, rel=1e-12)
    assert np.allclose(th, th[::-1], rtol=1e-9, atol=1e-14)
    ref = p.eta * G(p, th) / (c * c - p.eta**2)
    assert np.allclose(Up, ref, rtol=1e-10, atol=1e-13 * np.abs(ref).max())


@pytest.mark.parametrize("p,A", [(GAP, 0.56), (LEGO, 0.3), (PRE, 0.5), (SHEET, 0.8)])
def test_exact_soliton_full_solves_euler_lagrange(p, A):
    c, z, h, th, _ = _profile_grid(p, A, "full")
    S = S_of(p, c)
    D, dD = rt.gradient_coefficient(p, c, th, "full")
    tp, tpp = d1(th, h), d2(th, h)
    dV = S * G(p, th) * np.sin(p.theta0 + th) + gam(p) * th
    res = D[2:-2] * tpp + 0.5 * dD[2:-2] * tp**2 + dV[2:-2]
    assert np.abs(res).max() < 1e-6 * np.abs(dV).max()
    V2 = S * G(p, th) ** 2 + gam(p) * th**2
    assert np.abs(D[2:-2] * tp**2 + V2[2:-2]).max() < 1e-7 * np.abs(V2).max()
    # dD/dtheta is the derivative of D
    e = 1e-6
    fd = (rt.gradient_coefficient(p, c, th + e)[0] - rt.gradient_coefficient(p, c, th - e)[0]) / (2 * e)
    assert np.allclose(dD, fd, rtol=1e-6, atol=1e-8 * np.abs(dD).max())


@pytest.mark.parametrize("p", [PRE, RotatingChainND(-0.4, 1.0, 3e-3, 0.5, 1, 1),
                               RotatingChainND(0.2, 1.0, 5e-3, 0.1, 2, 0)])
def test_full_gradient_reproduces_discrete_tail_decay(p):
    """Near the long-wave speed the tail decay rate kappa -> 0 follows from the exact §1.4 dispersion."""
    for frac in (0.999, 0.9999):
        c = frac * rt.long_wave_speed(p)
        v = c / p.eta
        k11 = lambda k: -4 * np.sinh(k / 2) ** 2
        R = lambda k: (p.s0**2 * np.cosh(k / 2) ** 2 - p.Ks * p.eta**2 * np.sinh(k / 2) ** 2
                       + 4 * p.Ktheta * np.cosh(k / 2) ** 2 + p.n_v * (p.s_v * p.s0**2 / 2 + 2 * p.Ktheta))
        det = lambda k: ((k11(k) + v * v * k * k) * (R(k) + p.alpha2 * v * v * k * k)
                         + p.s0**2 * np.sinh(k) ** 2)
        ks = np.linspace(1e-7, 1.0, 200001)
        i = np.flatnonzero(np.sign(det(ks[1:])) != np.sign(det(ks[:-1])))[0]
        kappa = optimize.brentq(det, ks[i], ks[i + 1], xtol=1e-16)
        C1 = rt.continuum_coefficients(p, c, "full")[0]
        assert C1 * p.eta**2 == pytest.approx(kappa**2, rel=kappa**2)  # O(kappa^2) relative error
        C1_md = rt.continuum_coefficients(p, c, "constant")[0]  # constant D(c): wrong tail
        assert abs(C1_md * p.eta**2 / kappa**2 - 1) > 0.05


def test_exact_soliton_tail_and_small_amplitude_limit():
    p = NOGAP
    errs = []
    for A in (0.1, 0.05):
        c, z, h, th, _ = _profile_grid(p, A, "constant")
        errs.append(np.abs(th - rt.soliton_profile(p, c, z)).max() / A)
        C1 = rt.continuum_coefficients(p, c)[0]
        far = z > 10 / math.sqrt(C1)
        rate = -np.diff(np.log(th[far])) / h
        assert np.allclose(rate, math.sqrt(C1), rtol=1e-4)
    assert 3.0 < errs[0] / errs[1] < 5.0  # O(A^2) deviation from the cubic truncation


def test_exact_soliton_raises_below_gap():
    with pytest.raises(ValueError, match="no regular soliton"):
        rt.exact_soliton(GAP, 0.5 * rt.amplitude_gap(GAP), np.zeros(3))


# ---------------------------------------------------------------- initial state
@pytest.mark.parametrize("p,A", [(GAP, 0.56), (PRE, 0.5), (LEGO, -0.3), (SHEET, 0.8)])
@pytest.mark.parametrize("direction", [1, -1])
def test_initial_state_is_an_exact_travelling_wave(p, A, direction):
    N, x0, c = 200, 97.3, float(rt.soliton_speed(p, A))
    s = rt.soliton_initial_state(p, A, N, x0, direction)
    assert all(a.shape == (N,) for a in s)
    dT = 1e-3
    shift = direction * c * dT / p.eta  # sites travelled in dT
    fwd = rt.soliton_initial_state(p, A, N, x0 + shift, direction)
    bwd = rt.soliton_initial_state(p, A, N, x0 - shift, direction)
    for val, f, b in ((s.U_dot, fwd.U, bwd.U), (s.theta_dot, fwd.theta, bwd.theta)):
        assert np.allclose(val, (f - b) / (2 * dT), rtol=1e-5, atol=1e-7 * np.abs(val).max())
    # U = -direction * integral of U' from the site to far ahead (U -> 0 ahead of the pulse)
    for i in (0, 60, 95, 100, 130, N - 1):
        xi = direction * (i - x0) * p.eta
        z = np.linspace(xi, xi + 400.0, 400001)
        tail = integrate.trapezoid(rt.exact_soliton(p, A, z)[1], z)
        assert s.U[i] == pytest.approx(-direction * tail, rel=1e-7, abs=1e-10 * np.abs(s.U).max())


def test_initial_state_directions_are_mirror_images():
    a = rt.soliton_initial_state(PRE, 0.5, 101, 50.0, +1)
    b = rt.soliton_initial_state(PRE, 0.5, 101, 50.0, -1)
    assert np.allclose(b.theta, a.theta[::-1], atol=1e-14)
    assert np.allclose(b.U, -a.U[::-1], atol=1e-14)
    assert np.allclose(b.theta_dot, a.theta_dot[::-1], atol=1e-14)
    assert np.allclose(b.U_dot, -a.U_dot[::-1], atol=1e-14)


def _track(p, A, gradient, N=300, T=150.0, x0=60.0, onsite=None):
    """(measured/predicted speed, max shape error / |A|) of a launched soliton after time T."""
    state = rt.soliton_initial_state(p, A, N, x0, gradient=gradient)
    t, y = simulate(p, state, T, onsite=onsite)
    n = np.arange(N)
    pos = []
    for k in range(t.size):
        w = y[1, :, k] ** 2
        i = int(np.argmax(w))
        win = np.abs(n - i) < 15
        pos.append((n[win] * w[win]).sum() / w[win].sum())
    c = float(rt.soliton_speed(p, A))
    ref = rt.soliton_initial_state(p, A, N, x0 + c * T / p.eta, gradient=gradient)
    speed = np.polyfit(t, pos, 1)[0] * p.eta
    return speed / c, np.abs(y[1, :, -1] - ref.theta).max() / abs(A)


@pytest.mark.parametrize("p,A", [(GAP, 0.56), (LEGO, 0.3), (PRE, 0.5)])
def test_discrete_chain_propagates_initial_soliton(p, A):
    ratio, shape_err = _track(p, A, "full")
    assert abs(ratio - 1) < 0.015
    assert shape_err < 0.06


def test_full_gradient_beats_constant_for_predeformed_chain():
    _, err_full = _track(PRE, 0.5, "full")
    _, err_md = _track(PRE, 0.5, "constant")
    assert err_full < 0.25 * err_md


# ---------------------------------------------------------------- cnoidal waves
@pytest.mark.parametrize("kind,c,m", [("dn", 0.15, 0.6), ("cn", 0.15, 0.8), ("sn", 0.5, 0.4),
                                      ("dn", 0.1, 0.999), ("sn", 0.6, 0.9)])
def test_cnoidal_waves_solve_ode(kind, c, m):
    p = LEGO
    C1, _, C3 = rt.continuum_coefficients(p, c)
    z = np.linspace(0, 100, 40001)
    h = z[1] - z[0]
    th, lam = rt.cnoidal_wave(p, c, m, kind, z)
    rhs = C1 * th + C3 * th**3
    assert np.abs(d2(th, h) - rhs[2:-2]).max() < 1e-6 * np.abs(rhs).max()
    E = d1(th, h) ** 2 - C1 * th[2:-2] ** 2 - 0.5 * C3 * th[2:-2] ** 4
    assert np.ptp(E) < 1e-7 * np.abs(C1 * th**2).max()
    shifted, _ = rt.cnoidal_wave(p, c, m, kind, z + lam)
    assert np.allclose(shifted, th, atol=1e-9 * np.abs(th).max())
    half, _ = rt.cnoidal_wave(p, c, m, kind, z + lam / 2)
    assert not np.allclose(half, th, atol=1e-3 * np.abs(th).max())  # lam is the least period


def test_cnoidal_tends_to_soliton_as_m_to_1():
    c = 0.15
    z = np.linspace(-20, 20, 801)
    sol = rt.soliton_profile(LEGO, c, z)
    errs = [np.abs(rt.cnoidal_wave(LEGO, c, 1 - eps, kind, z)[0] - sol).max()
            for eps in (1e-4, 1e-8) for kind in ("dn", "cn")]
    assert errs[2] < 1e-3 * errs[0] and errs[3] < 1e-3 * errs[1] and max(errs[2:]) < 1e-5


def test_cnoidal_rejects_wrong_signs():
    with pytest.raises(ValueError, match="C1 > 0"):
        rt.cnoidal_wave(LEGO, 0.5, 0.5, "dn", 0.0)
    with pytest.raises(ValueError, match="C1 < 0"):
        rt.cnoidal_wave(LEGO, 0.15, 0.5, "sn", 0.0)
    with pytest.raises(ValueError, match="m > 1/2"):
        rt.cnoidal_wave(LEGO, 0.15, 0.4, "cn", 0.0)
    with pytest.raises(ValueError, match="theta0 = 0"):
        rt.cnoidal_wave(PRE, 0.1, 0.5, "dn", 0.0)
    with pytest.raises(ValueError, match="kind"):
        rt.cnoidal_wave(LEGO, 0.15, 0.5, "tn", 0.0)


# ---------------------------------------------------------------- linear dispersion
@pytest.mark.parametrize("p", [GAP, LEGO, SHEET, RotatingChainND(0.0, 0.1, 5e-3, 0.3, 1, 0)])
def test_dispersion_theta0_zero_closed_form(p):
    q = np.linspace(0, np.pi, 301)
    Ou = 2 * np.abs(np.sin(q / 2))
    Ot = np.sqrt(p.Ks * np.sin(q / 2) ** 2 + 4 * p.Ktheta * np.cos(q / 2) ** 2 + 2 * p.n_v * p.Ktheta) / math.sqrt(p.alpha2)
    lo, hi = rt.dispersion_chain(p, q)
    assert np.allclose(lo, np.minimum(Ou, Ot), rtol=1e-12, atol=1e-14)
    assert np.allclose(hi, np.maximum(Ou, Ot), rtol=1e-12)
    assert np.allclose(rt.dispersion_rotational(p, q), Ot, rtol=1e-12)
    brute = (Ot[1:] / q[1:]).min()
    assert rt.min_phase_speed_rotational(p) <= brute * (1 + 1e-12)
    assert rt.min_phase_speed_rotational(p) == pytest.approx(brute, rel=1e-4)


@HYP
@given(st.data())
def test_dispersion_matches_generalized_eigensolver(data):
    p = random_params(data.draw)
    q = data.draw(st.floats(0.0, math.pi))
    s2, c2 = math.sin(q / 2) ** 2, math.cos(q / 2) ** 2
    R = (p.s0**2 * c2 + p.Ks * p.eta**2 * s2 + 4 * p.Ktheta * c2 + p.n_v * (p.s_v * p.s0**2 / 2 + 2 * p.Ktheta))
    K = np.array([[4 * s2, -1j * p.s0 * math.sin(q)], [1j * p.s0 * math.sin(q), R]])
    lam = linalg.eigh(K, np.diag([1.0, p.alpha2]), eigvals_only=True)
    assert np.allclose(np.array(rt.dispersion_chain(p, q)) ** 2, lam, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("p", [PRE, RotatingChainND(-0.5, 1.0, 2e-3, 0.4, 2, 1), SHEET, LEGO])
def test_dispersion_matches_hessian_of_discrete_chain(p):
    N = 12
    x0 = np.zeros(2 * N)
    H = np.empty((2 * N, 2 * N))
    e = 1e-6
    for j in range(2 * N):
        xp, xm = x0.copy(), x0.copy()
        xp[j] += e
        xm[j] -= e
        fp, fm = np.concatenate(forces(p, xp[:N], xp[N:], True)), np.concatenate(forces(p, xm[:N], xm[N:], True))
        H[:, j] = -(fp - fm) / (2 * e)
    assert np.allclose(H, H.T, atol=1e-8)
    M = np.diag([1.0] * N + [p.alpha2] * N)
    lam = np.sort(linalg.eigh(0.5 * (H + H.T), M, eigvals_only=True))
    q = 2 * np.pi * np.arange(N) / N
    theory = np.sort(np.concatenate(rt.dispersion_chain(p, q)) ** 2)
    assert np.allclose(lam, theory, atol=1e-7)


@pytest.mark.parametrize("p", [PRE, LEGO, SHEET, RotatingChainND(0.5, 0.05, 2e-3, 0.4, 1, 0)])
def test_band_edges_and_omega_max(p):
    q = np.linspace(0, np.pi, 200001)
    lo, hi = rt.dispersion_chain(p, q)
    be = rt.band_edges(p)
    assert be.lower_max == pytest.approx(lo.max(), rel=1e-9)
    assert be.upper_min == pytest.approx(hi.min(), rel=1e-9)
    assert rt.omega_max_chain(p) == pytest.approx(hi.max(), rel=1e-9) and be.upper_max == rt.omega_max_chain(p)
    assert be.gap == pytest.approx(max(hi.min() - lo.max(), 0.0), abs=1e-9)
    rot = rt.dispersion_rotational(p, q[1:])
    assert rt.min_phase_speed_rotational(p) == pytest.approx((p.eta * rot / q[1:]).min(), rel=1e-6)
