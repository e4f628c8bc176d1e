"""flexmm.theory.prestressed and the prestress terms of flexmm.theory.rotating, against independent oracles.

Oracles: the energy of a periodic ring of the loaded chain written here from docs/physics.md §1.1 (its
compression held by the ring's closure), finite differences, the numerical Hessian of that ring,
and a short simulation of the discrete equations (test_rotating_theory.simulate).
"""
import math

import numpy as np
import pytest
from conftest import LEGO_PARAMETERS
from scipy import linalg
from test_rotating_theory import D_phys, G, S_of, _track, d1, d2, gam

from flexmm.theory import rotating as rt
from flexmm.theory.prestressed import (
    equilibrium_force,
    prestressed_chain,
    soliton_window,
    static_rotation,
)
from flexmm.theory.rotating import RotatingChainND

LEGO05 = rt.lego_parameters(theta0=0.05, n_v=1)
F02 = 0.2 / (LEGO_PARAMETERS["k_long_n_per_m"] * LEGO_PARAMETERS["a_m"])  # the scene's 0.2 N end load, nondimensional
STRETCH = RotatingChainND(0.1, 0.5, 2e-3, 0.3, n_v=1, s_v=1)


def ring_energy(p: RotatingChainND, f: float, theta_s: float, U, th) -> float:
    """Energy of a periodic ring of the chain p about its uniform state under hinge force -f.

    U, th are displacements from that state; the static hinge stretch -f sets the spacing increment
    s = -f - G(theta_s), so Delta x_i = U_{i+1} - U_i + s + cos theta0 - (cos_i + cos_{i+1})/2.
    """
    t = theta_s + np.asarray(th)
    c, sn = np.cos(p.theta0 + t), np.sin(p.theta0 + t)
    s = -f - G(p, theta_s)
    dx = np.roll(U, -1) - U + s + p.eta - 0.5 * (c + np.roll(c, -1))
    dy = 0.5 * (np.roll(sn, -1) - sn)
    lateral = p.n_v * (0.25 * p.s_v * (p.eta - c) ** 2 + p.Ktheta * t**2)
    return float(np.sum(0.5 * dx**2 + 0.5 * p.Ks * dy**2 + 0.5 * p.Ktheta * (t + np.roll(t, -1)) ** 2 + lateral))


def W(p_pre: RotatingChainND, phi):
    """Prestress potential gamma theta_s [phi - G_t0'(phi)/sin t0'] (prestressed module docstring)."""
    return gam(p_pre) * p_pre.theta_s * (phi - G(p_pre, phi) / p_pre.s0)


def W_prime(p_pre: RotatingChainND, phi):
    return gam(p_pre) * p_pre.theta_s * (1 - np.sin(p_pre.theta0 + phi) / p_pre.s0)


@pytest.mark.parametrize("p,f", [(LEGO05, F02), (STRETCH, 3e-3), (RotatingChainND(-0.2, 0.3, 1e-3, 0.5, 2, 0), 2e-3)])
def test_static_rotation_is_the_ring_equilibrium(p, f):
    th_s = static_rotation(p, f)
    assert th_s * p.theta0 > 0 and abs(th_s) > 1e-3
    e = 1e-6
    N = 8
    for k in (0, N):  # dE/dU_0 and dE/dtheta_0 at the uniform state
        x = np.zeros(2 * N)
        x[k] = e
        plus = ring_energy(p, f, th_s, x[:N], x[N:])
        minus = ring_energy(p, f, th_s, -x[:N], -x[N:])
        assert abs(plus - minus) / (2 * e) < 1e-10
    assert equilibrium_force(prestressed_chain(p, th_s)) == pytest.approx(f, rel=1e-10)


def test_static_rotation_straight_chain_buckles_at_gamma():
    p = rt.lego_parameters(theta0=0.0, n_v=1)
    assert static_rotation(p, 0.99 * p.gamma) == 0.0
    th = static_rotation(p, 1.1 * p.gamma)
    assert 1.1 * p.gamma * math.sin(th) == pytest.approx(p.gamma * th, rel=1e-12) and th > 0.3
    with pytest.raises(ValueError, match="compressive"):
        static_rotation(p, -1e-3)
    with pytest.raises(ValueError, match="stress-free"):
        static_rotation(prestressed_chain(LEGO05, 0.1), 1e-4)


@pytest.mark.parametrize("p,f", [(LEGO05, F02), (STRETCH, 3e-3)])
def test_prestressed_energy_is_shifted_chain_plus_onsite_W(p, f):
    """The derivation: loaded ring(theta_s + phi) = stress-free ring at theta0 + theta_s + sum W(phi)."""
    p_pre = prestressed_chain(p, static_rotation(p, f))
    shifted = RotatingChainND(p_pre.theta0, p.Ks, p.Ktheta, p.alpha2, p.n_v, p.s_v)
    rng = np.random.default_rng(1)
    for scale in (0.01, 0.3):
        U, phi = rng.normal(scale=scale, size=(2, 16))
        lhs = ring_energy(p, f, p_pre.theta_s, U, phi) - ring_energy(p, f, p_pre.theta_s, 0 * U, 0 * phi)
        rhs = ring_energy(shifted, 0.0, 0.0, U, phi) + np.sum(W(p_pre, phi))
        assert lhs == pytest.approx(rhs, rel=1e-11, abs=1e-15)


@pytest.mark.parametrize("p,f", [(LEGO05, F02), (STRETCH, 3e-3)])
def test_prestressed_dispersion_matches_ring_hessian(p, f):
    p_pre = prestressed_chain(p, static_rotation(p, f))
    N, e = 12, 1e-4
    H = np.empty((2 * N, 2 * N))
    E = lambda x: ring_energy(p, f, p_pre.theta_s, x[:N], x[N:])
    I = np.eye(2 * N) * e
    for i in range(2 * N):
        for j in range(i, 2 * N):
            H[i, j] = H[j, i] = (E(I[i] + I[j]) - E(I[i] - I[j]) - E(I[j] - I[i]) + E(-I[i] - I[j])) / (4 * e * e)
    M = np.diag([1.0] * N + [p.alpha2] * N)
    lam = np.sort(linalg.eigh(H, M, eigvals_only=True))
    q = 2 * np.pi * np.arange(N) / N
    theory = np.sort(np.concatenate(rt.dispersion_chain(p_pre, q)) ** 2)
    assert np.allclose(lam, theory, atol=1e-7)
    c_lw = rt.long_wave_speed(p_pre)  # softened: far below the stress-free chain's
    assert c_lw == pytest.approx(rt.dispersion_chain(p_pre, 1e-4)[0] / 1e-4 * p_pre.eta, rel=1e-6)
    assert c_lw < rt.long_wave_speed(p)


def test_prestressed_coefficients_are_the_taylor_expansion():
    p_pre = prestressed_chain(LEGO05, static_rotation(LEGO05, F02))
    c = 0.3
    C1, C2, C3 = rt.continuum_coefficients(p_pre, c)
    S, D = S_of(p_pre, c), D_phys(p_pre, c)
    errs = []
    for th in (0.02, 0.01):
        full = -(S * G(p_pre, th) * math.sin(p_pre.theta0 + th) + gam(p_pre) * th + W_prime(p_pre, th)) / D
        errs.append(abs(full - (C1 * th + C2 * th**2 + C3 * th**3)))
    assert errs[0] / errs[1] == pytest.approx(16, rel=0.25)


@pytest.mark.parametrize("A", [-0.36, -0.38, 0.2])
def test_prestressed_exact_soliton_solves_euler_lagrange(A):
    p = prestressed_chain(LEGO05, static_rotation(LEGO05, F02))
    assert rt.soliton_exists(p, A)
    c = float(rt.soliton_speed(p, A))
    L = 1 / math.sqrt(rt.continuum_coefficients(p, c, "full")[0])
    z = np.linspace(-25 * L, 25 * L, 20001)
    h = z[1] - z[0]
    th, Up = rt.exact_soliton(p, A, z)
    S = S_of(p, c)  # from c: checks the speed law as well
    D, dD = rt.gradient_coefficient(p, c, th, "full")
    dV = S * G(p, th) * np.sin(p.theta0 + th) + gam(p) * th + W_prime(p, th)
    res = D[2:-2] * d2(th, h) + 0.5 * dD[2:-2] * d1(th, h) ** 2 + dV[2:-2]
    assert np.abs(res).max() < 1e-6 * np.abs(dV).max()
    V2 = S * G(p, th) ** 2 + gam(p) * th**2 + 2 * W(p, th)
    assert np.abs(D[2:-2] * d1(th, h) ** 2 + V2[2:-2]).max() < 1e-7 * np.abs(V2).max()
    ref = p.eta * G(p, th) / (c * c - p.eta**2)
    assert np.allclose(Up, ref, rtol=1e-10, atol=1e-13 * np.abs(ref).max())
    assert np.sign(Up.max() if A < 0 else Up.min()) == -np.sign(A)  # A < 0: tensile; A > 0: compressive


def test_prestressed_rarefaction_branch():
    """Tensile pulses need -2 theta0' < A < 0; here they lie in a window near the fully re-opened state."""
    p = prestressed_chain(LEGO05, static_rotation(LEGO05, F02))
    small, large = soliton_window(p, -1, n=400)
    assert -2 * p.theta0 < large < small < -0.3
    assert not rt.soliton_exists(p, small + 2e-3) and not rt.soliton_exists(p, large - 2e-3)
    A = np.linspace(small, large, 50)
    assert all(rt.soliton_exists(p, a) for a in A)
    c = rt.soliton_speed(p, A) / p.eta
    assert np.all(np.diff(c) > 0)  # faster with amplitude
    assert c.min() > rt.long_wave_speed(p) / p.eta  # and faster than linear long waves
    with pytest.raises(ValueError, match="stress-free"):
        rt.soliton_amplitude(p, 0.4, -1, "short")
    assert not rt.soliton_exists(p, -0.1)  # a nan speed is no soliton


def test_discrete_prestressed_chain_propagates_initial_soliton():
    """The theta0' chain plus the on-site W (equal to the loaded chain, test above) carries the soliton."""
    p = prestressed_chain(LEGO05, static_rotation(LEGO05, F02))
    ratio, shape_err = _track(p, -0.38, "full", N=200, T=50.0, x0=40.0, onsite=lambda th: W_prime(p, th))
    assert abs(ratio - 1) < 0.015  # measured +0.5 %
    assert shape_err < 0.04  # mostly the 0.5 % phase drift
