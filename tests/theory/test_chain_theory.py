"""Tests for flexmm.theory.chains (docs/physics.md §2) against ODE residuals and discrete simulations."""
import math
import os

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import integrate

from flexmm.theory import chains as ch

HYP = settings(max_examples=int(os.environ.get("FLEXMM_HYP_EXAMPLES", 40)), deadline=None)


def d1(f, h):
    return (-f[4:] + 8 * f[3:-1] - 8 * f[1:-3] + f[:-4]) / (12 * h)


def d2(f, h):
    return (-f[4:] + 16 * f[3:-1] - 30 * f[2:-2] + 16 * f[1:-3] - f[:-4]) / (12 * h * h)


# ---------------------------------------------------------------- bistable fronts
@HYP
@given(st.floats(0.01, 5.0), st.floats(0.05, 0.45), st.floats(0.2, 3.0), st.floats(0.1, 5.0),
       st.floats(0.1, 3.0), st.floats(0.01, 2.0))
def test_bistable_front_solves_travelling_wave_ode(alpha, beta, L, k, m, eta):
    a = 1.0
    fr = ch.bistable_front(alpha, beta, L, k, m, a, eta)
    h = fr.w / 400
    x = np.arange(-15 * fr.w, 15 * fr.w, h)
    u = fr.profile(x)
    Vp = alpha * u * (u - beta * L) * (u - L)
    res = (k * a * a - m * fr.v**2) * d2(u, h) + eta * fr.v * d1(u, h) - Vp[2:-2]
    assert np.abs(res).max() < 1e-6 * alpha * L**3
    assert 0 < fr.v < fr.c0
    # released energy = V(0) - V(L) by quadrature of the force
    dphi = -integrate.quad(lambda s: alpha * s * (s - beta * L) * (s - L), 0, L)[0]
    assert fr.dphi == pytest.approx(dphi, rel=1e-10)


def test_front_energy_law_matches_profile_kinetic_energy():
    k, m, a, alpha, L, beta, eta = 2.0, 0.5, 0.7, 0.3, 1.5, 0.2, 0.4
    fr = ch.bistable_front(alpha, beta, L, k, m, a, eta)
    x = np.linspace(-40 * fr.w, 40 * fr.w, 200001)
    ut = (fr.profile(x, 1e-6) - fr.profile(x, -1e-6)) / 2e-6
    K = integrate.trapezoid(0.5 * m * ut**2, x) / a  # one mass per spacing a
    assert K == pytest.approx(ch.front_kinetic_energy(m, fr.v, fr.dphi, eta, a), rel=1e-6)
    assert ch.front_kinetic_energy(m, 1.0, 1.0, 0.0, 1.0) == math.inf


def test_discrete_bistable_chain_front_speed_and_energy():
    k, m, a, alpha, L, beta, eta = 1.0, 1.0, 1.0, 0.02, 1.0, 0.25, 0.05
    fr = ch.bistable_front(alpha, beta, L, k, m, a, eta)
    assert fr.w > 10 * a  # wide front: continuum limit applies
    N = 400
    x = np.arange(N) * a - 100
    y0 = np.concatenate([fr.profile(x), (fr.profile(x, 1e-6) - fr.profile(x, -1e-6)) / 2e-6])

    def rhs(t, y):
        u, v = y[:N], y[N:]
        up = np.pad(u, 1, mode="edge")
        return np.concatenate([v, (k * (up[2:] - 2 * u + up[:-2]) - alpha * u * (u - beta * L) * (u - L) - eta * v) / m])

    ts = np.linspace(100, 300, 11)
    sol = integrate.solve_ivp(rhs, (0, 300), y0, method="DOP853", rtol=1e-9, atol=1e-12, t_eval=ts)
    pos, K = [], []
    for j in range(ts.size):
        u = sol.y[:N, j]
        i = np.flatnonzero(u < L / 2)[0]  # 50 % crossing, as in Raney 2016
        pos.append(x[i - 1] + (u[i - 1] - L / 2) / (u[i - 1] - u[i]) * a)
        K.append(0.5 * m * np.sum(sol.y[N:, j] ** 2))
    assert np.polyfit(ts, pos, 1)[0] == pytest.approx(fr.v, rel=2e-3)
    assert np.mean(K) == pytest.approx(ch.front_kinetic_energy(m, fr.v, fr.dphi, eta, a), rel=2e-3)


def test_bistable_front_rejects_bad_parameters():
    with pytest.raises(ValueError):
        ch.bistable_front(1.0, 0.6, 1.0, 1.0, 1.0, 1.0, 0.1)
    with pytest.raises(ValueError):
        ch.bistable_front(-1.0, 0.2, 1.0, 1.0, 1.0, 1.0, 0.1)


# ---------------------------------------------------------------- softening chain
@HYP
@given(st.floats(0.1, 5.0), st.floats(-3.0, 3.0).filter(lambda x: abs(x) > 0.05),
       st.floats(0.005, 0.2), st.floats(0.2, 3.0))
def test_sech2_wave_solves_boussinesq_travelling_ode(k1, k2, amp, m):
    Dm = math.copysign(amp, k2)
    sw = ch.softening_solitary_wave(k1, k2, Dm, m)
    assert sw.polarity == (1 if k2 > 0 else -1)
    assert sw.v == pytest.approx(sw.c0 * math.sqrt(1 + 2 * k2 * Dm / (3 * k1)))
    h = sw.W / 300
    n = np.arange(-20 * sw.W, 20 * sw.W, h)
    D = sw.profile(n)
    res = k1 / 12 * d2(D, h) - ((m * sw.v**2 - k1) * D - k2 * D**2)[2:-2]
    assert np.abs(res).max() < 1e-6 * abs(k2) * Dm**2


def test_sech2_wave_requires_matching_polarity():
    with pytest.raises(ValueError, match="sign"):
        ch.softening_solitary_wave(1.0, 1.0, -0.1)


def test_discrete_softening_chain_carries_the_sech2_wave():
    k1, k2, Dm = 1.0, 1.0, 0.03
    sw = ch.softening_solitary_wave(k1, k2, Dm)
    N = 600
    bonds = np.arange(N - 1) + 0.5
    x0 = np.concatenate([[0.0], np.cumsum(sw.profile(bonds - 100))])
    v0 = -sw.v * sw.profile(np.arange(N) - 100)  # x_t = -v X', X' ~ D in the long-wave limit

    def rhs(t, y):
        d = np.diff(y[:N])
        T = k1 * d + k2 * d * d
        acc = np.zeros(N)
        acc[:-1] += T
        acc[1:] -= T
        return np.concatenate([y[N:], acc])

    ts = np.linspace(100, 400, 16)
    sol = integrate.solve_ivp(rhs, (0, 400), np.concatenate([x0, v0]), method="DOP853",
                              rtol=1e-10, atol=1e-13, t_eval=ts)
    pos, amp = [], []
    for j in range(ts.size):
        d = np.diff(sol.y[:N, j])
        i = int(np.argmax(d))
        win = np.abs(bonds - bonds[i]) < 15
        pos.append((bonds[win] * d[win]).sum() / d[win].sum())
        amp.append(d[i])
    v = np.polyfit(ts, pos, 1)[0]
    assert (v - sw.c0) / (sw.v - sw.c0) == pytest.approx(1.0, abs=0.05)  # the nonlinear speed-up
    assert min(amp) > 0.95 * Dm  # tensile pulse survives


# ---------------------------------------------------------------- Hertz / Nesterenko
def test_nesterenko_profile_solves_long_wave_equation():
    A, m, D, xi_m = 2.0, 1.5, 0.7, 0.04
    V = ch.nesterenko_speed(A, m, D, xi_m)
    c2 = A * D**2.5 / m
    half = ch.nesterenko_support(D) / 2
    h = half / 4000
    x = np.arange(-0.97 * half, 0.97 * half, h)
    xi = ch.nesterenko_profile(A, m, D, xi_m, x)
    res = V**2 * xi[2:-2] - c2 * (xi[2:-2] ** 1.5 + D**2 / 10 * xi[2:-2] ** 0.25 * d2(xi**1.25, h))
    assert np.abs(res).max() < 1e-7 * V**2 * xi_m
    assert ch.nesterenko_profile(A, m, D, xi_m, 0.0) == pytest.approx(xi_m)
    assert ch.nesterenko_profile(A, m, D, xi_m, [1.01 * half, -1.01 * half]).tolist() == [0.0, 0.0]
    assert 4.9 * D < ch.nesterenko_support(D) < 5.0 * D
    # the pulse moves at V
    assert ch.nesterenko_profile(A, m, D, xi_m, 0.3 + 2.0 * V, 2.0) == pytest.approx(
        ch.nesterenko_profile(A, m, D, xi_m, 0.3))


def test_nesterenko_speed_force_scaling():
    A, m, D = 3.0, 0.2, 0.01
    F = 0.7
    V1, V2 = ch.nesterenko_speed_from_force(A, m, D, F), ch.nesterenko_speed_from_force(A, m, D, 64 * F)
    assert V2 / V1 == pytest.approx(2.0, rel=1e-12)  # V ~ F^(1/6)
    xi = (F / A) ** (2 / 3) / D
    assert A * (xi * D) ** 1.5 == pytest.approx(F)
    assert V1 == pytest.approx(2 / math.sqrt(5) * math.sqrt(A * D**2.5 / m) * xi**0.25)


def _hertz_pulse(v_strike, A=2.0, m=1.5, D=0.7, N=120):
    def rhs(t, y):
        d = np.maximum(y[: N - 1] - y[1:N], 0.0)
        f = A * d**1.5
        acc = np.zeros(N)
        acc[:-1] -= f
        acc[1:] += f
        return np.concatenate([y[N:], acc / m])

    y0 = np.zeros(2 * N)
    y0[N] = v_strike
    T = 60 * D / ch.nesterenko_speed(A, m, D, (v_strike / math.sqrt(A * D**2.5 / m)) ** 0.8) * 3
    sol = integrate.solve_ivp(rhs, (0, T), y0, method="DOP853", rtol=1e-11, atol=1e-14, dense_output=True)
    ts = np.linspace(0, T, 40001)
    Y = sol.sol(ts)
    tp, pk = [], []
    for j in (50, 90):  # contact between beads j and j+1
        d = np.maximum(Y[j] - Y[j + 1], 0.0)
        i = int(np.argmax(d))
        y = d[i - 1: i + 2]
        off = 0.5 * (y[0] - y[2]) / (y[0] - 2 * y[1] + y[2])
        tp.append(ts[i] + off * (ts[1] - ts[0]))
        pk.append(y[1] - 0.25 * (y[0] - y[2]) * off)
    x = sol.sol(tp[1])[:N]
    return 40 * D / (tp[1] - tp[0]), pk[1] / D, np.maximum(x[:-1] - x[1:], 0.0)


def test_discrete_hertz_chain_matches_nesterenko_within_long_wave_accuracy():
    A, m, D = 2.0, 1.5, 0.7
    V1, xi1, prof = _hertz_pulse(0.1)
    V2, xi2, _ = _hertz_pulse(0.4)
    assert V1 == pytest.approx(ch.nesterenko_speed(A, m, D, xi1), rel=0.03)
    assert V2 / V1 == pytest.approx((xi2 / xi1) ** 0.25, rel=2e-3)  # exact scaling of the discrete chain
    assert np.count_nonzero(prof > 0.01 * prof.max()) <= 5  # support ~ 5 diameters


# ---------------------------------------------------------------- Toda lattice
@HYP
@given(st.floats(0.2, 3.0), st.floats(0.2, 3.0), st.floats(0.2, 3.0), st.floats(0.05, 2.0))
def test_toda_soliton_solves_lattice_equations(a, b, m, kappa):
    n = np.arange(-math.ceil(20 / kappa), math.ceil(20 / kappa) + 1)
    beta = math.sqrt(a * b / m) * math.sinh(kappa)
    t0 = 0.37 / beta
    h = 1e-3 / beta
    r = np.array([ch.toda_soliton(a, b, m, kappa, n, t0 + j * h) for j in (-2, -1, 0, 1, 2)])
    rtt = (-r[4] + 16 * r[3] - 30 * r[2] + 16 * r[1] - r[0]) / (12 * h * h)
    Vp = a - a * np.exp(-b * r[2])  # V'(r) for V = (a/b) e^{-br} + a r
    rhs = Vp[2:] - 2 * Vp[1:-1] + Vp[:-2]
    assert np.abs(m * rtt[1:-1] - rhs).max() < 1e-6 * np.abs(rhs).max()
    assert ch.toda_speed(a, b, m, kappa) == pytest.approx(beta / kappa)
    assert np.all(r[2] <= 0) and abs(r[2][0]) < 1e-6 * abs(r[2]).max()


def test_toda_speed_tends_to_sound_speed():
    assert ch.toda_speed(2.0, 0.5, 1.0, 1e-6) == pytest.approx(1.0, rel=1e-10)
    assert ch.toda_speed(2.0, 0.5, 1.0, 1.0) > 1.0  # supersonic


# ---------------------------------------------------------------- linear chain
@HYP
@given(st.floats(0.1, 10.0), st.floats(0.1, 10.0), st.floats(0.0, 5.0), st.floats(0.0, math.pi))
def test_linear_dispersion_solves_discrete_equation(k, m, ks, q):
    w = ch.linear_chain_dispersion(k, m, q, ks)
    n = np.arange(5)
    u = np.cos(q * n)  # standing-wave snapshot of a Bloch mode
    res = -m * w**2 * u[1:-1] - (k * (u[2:] - 2 * u[1:-1] + u[:-2]) - ks * u[1:-1])
    assert np.abs(res).max() < 1e-10 * (k + ks + 1)
    lo, hi = ch.linear_chain_band(k, m, ks)
    assert lo - 1e-12 <= w <= hi + 1e-12


def test_cutoff_frequency():
    assert ch.linear_chain_cutoff_frequency(4.0, 1.0) == pytest.approx(2.0 / math.pi)  # sqrt(k/m)/pi
    assert ch.linear_chain_band(1.0, 1.0, 3.0) == pytest.approx((math.sqrt(3), math.sqrt(7)))


@pytest.mark.parametrize("k,m,ks,w", [(1.0, 1.0, 0.0, 2.5), (2.0, 0.5, 1.0, 5.0), (1.0, 2.0, 3.0, 0.5)])
def test_evanescent_ratio_solves_discrete_equation(k, m, ks, w):
    kappa, r = ch.evanescent_decay(k, m, w, ks)
    assert kappa > 0 and abs(r) == pytest.approx(math.exp(-kappa))
    u = r ** np.arange(6)
    res = -m * w**2 * u[1:-1] - (k * (u[2:] - 2 * u[1:-1] + u[:-2]) - ks * u[1:-1])
    assert np.abs(res).max() < 1e-12
    above = w > ch.linear_chain_band(k, m, ks)[1]
    assert (r < 0) == above


def test_evanescent_rejects_pass_band():
    with pytest.raises(ValueError, match="pass band"):
        ch.evanescent_decay(1.0, 1.0, 1.0)
