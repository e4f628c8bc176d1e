"""flexmm.theory.cnoidal against independent oracles.

Oracles: the first integral theta'^2 = P(theta) by finite differences, the dn/cn/sn
formulas of docs/physics.md §1.3 (flexmm.theory.rotating.cnoidal_wave), the small-amplitude sinusoid, the exact discrete
linear dispersion (docs/physics.md §1.4) and the Taylor expansion of the reduced hinge force.
"""
import math

import numpy as np
import pytest
from conftest import LEGO_PARAMETERS
from test_rotating_theory import G, d1, gam

from flexmm.theory import cnoidal as cn
from flexmm.theory import rotating as rt
from flexmm.theory.prestressed import prestressed_chain, static_rotation

LEGO = rt.lego_parameters()
F02 = 0.2 / (LEGO_PARAMETERS["k_long_n_per_m"] * LEGO_PARAMETERS["a_m"])  # a 0.2 N end load, nondimensional
PRESTRESSED = prestressed_chain(rt.lego_parameters(theta0=0.05, n_v=1),
                                static_rotation(rt.lego_parameters(theta0=0.05, n_v=1), F02))
OMEGA_10HZ = 2 * math.pi * 10 * math.sqrt(LEGO_PARAMETERS["mass_kg"] / LEGO_PARAMETERS["k_long_n_per_m"])

CASES = [  # (C0, C1, C2, C3), crest, kind
    ((0.0, 1.0, 0.0, -1.0), 1.2, "real"),  # dn
    ((0.0, 1.0, 0.0, -1.0), 1.6, "complex"),  # cn
    ((0.0, -1.0, 0.0, 1.0), 0.5, "inner"),  # sn
    ((0.0, 1.0, 0.0, -1.0), -0.75, "real_reflected"),  # dn of negative polarity
    ((0.0, -1.0, -2.0, -1.0), 0.1, "complex"),
    ((3.0e-3, -0.0154, -0.327, -0.503), 0.136, "real"),  # the scene's driven wave: sharp crests, flat troughs
]


@pytest.mark.parametrize("C,crest,kind", CASES)
def test_profile_satisfies_first_integral(C, crest, kind):
    w = cn.cnoidal_through(C, crest)
    assert w.kind == kind and 0 <= w.m <= 1
    z = np.linspace(-w.wavelength, w.wavelength, 40001)
    th = w.profile(z)
    theta_p = d1(th, z[1] - z[0])
    P = cn.quartic(w.coefficients, w.energy, th[2:-2])
    assert np.abs(theta_p**2 - P).max() < 1e-10 * np.abs(theta_p**2).max()
    assert th.max() == pytest.approx(crest, abs=1e-12) and w.profile(0.0) == pytest.approx(crest, abs=1e-12)
    assert th.min() == pytest.approx(w.trough, abs=1e-9)
    assert np.abs(w.profile(z + w.wavelength) - th).max() < 1e-12
    assert np.abs(w.profile(z + w.wavelength / 2) - th).max() > 1e-3 * (crest - w.trough)  # least period


@pytest.mark.parametrize("kind,c,m", [("dn", 0.15, 0.6), ("cn", 0.15, 0.8), ("sn", 0.5, 0.4)])
def test_matches_documented_dn_cn_sn(kind, c, m):
    """Same wave as the formulas of docs/physics.md §1.3; the sn^2 parameter is theirs after a Landen transformation."""
    C1, _, C3 = rt.continuum_coefficients(LEGO, c)
    _, lam = rt.cnoidal_wave(LEGO, c, m, kind, np.zeros(1))
    P = math.sqrt(-2 * C1 / C3 * {"dn": 1 / (2 - m), "cn": m / (2 * m - 1), "sn": m / (1 + m)}[kind])
    w = cn.cnoidal_through((0.0, C1, 0.0, C3), P)
    s = math.sqrt(1 - m)
    landen = {"dn": ((1 - s) / (1 + s)) ** 2, "cn": m, "sn": 4 * math.sqrt(m) / (1 + math.sqrt(m)) ** 2}[kind]
    assert w.m == pytest.approx(landen, rel=1e-9) and w.wavelength == pytest.approx(lam, rel=1e-9)
    z = np.linspace(0, 2 * lam, 2001)
    shift = lam / 4 if kind == "sn" else 0.0  # P sn peaks a quarter period in
    assert np.allclose(w.profile(z), rt.cnoidal_wave(LEGO, c, m, kind, z + shift)[0], atol=1e-10 * P)


def test_small_orbit_is_a_sinusoid():
    C = (0.0, -0.3, 0.5, -0.2)
    w = cn.cnoidal_through(C, 1e-5)
    assert w.m < 1e-4 and w.wavelength == pytest.approx(2 * math.pi / math.sqrt(0.3), rel=1e-4)
    h = w.harmonics(2)
    assert h[2] < 1e-4 * h[1]


def test_no_orbit_raises():
    with pytest.raises(ValueError, match="no periodic wave"):
        cn.cnoidal_through((0.0, 1.0, 0.0, -1.0), 1.0)  # the fixed point itself
    with pytest.raises(ValueError, match="no periodic wave"):
        cn.cnoidal_through((0.0, -1.0, 0.0, 1.0), 2.0)  # beyond the sn band: no oscillation
    with pytest.raises(ValueError, match="amplitude"):
        cn.driven_wave(PRESTRESSED, OMEGA_10HZ, 0.0)


def test_wave_coefficients_are_the_taylor_expansion_with_mean_force():
    """theta'' = -V'/D with V' = (S G - sigma G-bar) G' + gamma theta + W' (wave_coefficients docstring)."""
    p, c, gbar = PRESTRESSED, 0.07, 4e-3
    C0, C1, C2, C3 = cn.wave_coefficients(p, c, gbar)
    sigma = c * c / (c * c - p.eta**2)
    D = float(rt.gradient_coefficient(p, c, 0.0, "full")[0])
    k = gam(p) * p.theta_s
    errs = []
    for th in (0.02, 0.01):
        dW = k * (1 - math.sin(p.theta0 + th) / p.s0)
        full = -((sigma * G(p, th) - sigma * gbar) * math.sin(p.theta0 + th) + gam(p) * th + dW) / D
        errs.append(abs(full - (C0 + C1 * th + C2 * th**2 + C3 * th**3)))
    assert errs[0] / errs[1] == pytest.approx(16, rel=0.25)


def test_linear_speed_matches_exact_discrete_dispersion():
    c = cn.linear_speed(PRESTRESSED, OMEGA_10HZ)
    q = OMEGA_10HZ * PRESTRESSED.eta / c  # rad per site
    assert rt.dispersion_chain(PRESTRESSED, q)[0] == pytest.approx(OMEGA_10HZ, rel=2e-3)


def test_driven_wave_family():
    """Small: the linear wave; larger: slower, mean shifted, sharper crests, m growing."""
    small = cn.driven_wave(PRESTRESSED, OMEGA_10HZ, 1e-3)
    big = cn.driven_wave(PRESTRESSED, OMEGA_10HZ, 0.07)
    c_lin = cn.linear_speed(PRESTRESSED, OMEGA_10HZ)
    assert small.c == pytest.approx(c_lin, rel=1e-3) and small.wave.m < 0.02
    for w in (small, big):
        assert w.wave.harmonics(1)[1] == pytest.approx(1e-3 if w is small else 0.07, rel=1e-8)
        assert w.wave.wavelength == pytest.approx(2 * math.pi * w.c / OMEGA_10HZ, rel=1e-8)
        th = w.wave.profile(np.arange(512) * w.wave.wavelength / 512)
        assert np.mean(rt.hinge_stretch(PRESTRESSED, th)) == pytest.approx(w.mean_stretch, rel=1e-6)
    assert big.c < 0.93 * c_lin and 0.2 < big.wave.m < 0.4
    assert big.wave.crest > 3 * abs(big.wave.trough) and big.wave.harmonics(1)[0] > 0.03


def test_wave_with_mean_recovers_the_force_driven_wave():
    """Closed by the force-driven wave's own mean rotation, the free-mean family returns that wave;
    closed by another mean it returns another wave of the same amplitude and frequency."""
    from flexmm.theory.cnoidal import driven_wave, wave_with_mean
    from flexmm.theory.rotating import RotatingChainND

    p = RotatingChainND.from_si(0.016, 0.15, 71690, 1326.98, 7.038e-4, 4.52e-3, 8.7814e-8, n_v=1)
    omega = 2 * math.pi * 10 * math.sqrt(4.52e-3 / 71690)
    forced = driven_wave(p, omega, 0.03)
    mean, h1 = forced.wave.harmonics(1)[:2]
    free = wave_with_mean(p, omega, 0.03, mean)
    assert free.c == pytest.approx(forced.c, rel=1e-7)
    assert free.mean_stretch == pytest.approx(forced.mean_stretch, rel=1e-5, abs=1e-12)
    assert free.wave.crest == pytest.approx(forced.wave.crest, rel=1e-7)
    other = wave_with_mean(p, omega, 0.03, mean + 0.003)
    m2, a2 = other.wave.harmonics(1)[:2]
    assert a2 == pytest.approx(0.03, rel=1e-8) and m2 == pytest.approx(mean + 0.003, abs=1e-9)
    assert abs(other.c / forced.c - 1) > 1e-3
