"""flexmm.theory.breathers: the breather solves sine-Gordon; peak, frequency and energy laws."""
import numpy as np
import pytest

from flexmm.theory.breathers import SineGordonBreather, breather_frequency, frenkel_kontorova_scales


@pytest.mark.parametrize("omega", [0.3, 0.6, 0.9])
def test_breather_solves_sine_gordon(omega):
    ell = 4.0
    b = SineGordonBreather(omega, ell)
    h, dt = 1e-3 * ell, 1e-3
    xi = np.linspace(-6 * ell, 6 * ell, 241)[:, None]
    t = np.array([0.37, 1.1, 2.9])[None, :]
    phi_tt = (b.phi(xi, t + dt) - 2 * b.phi(xi, t) + b.phi(xi, t - dt)) / dt**2
    phi_xx = (b.phi(xi + h, t) - 2 * b.phi(xi, t) + b.phi(xi - h, t)) / h**2
    residual = phi_tt - (ell**2 * phi_xx - np.sin(b.phi(xi, t)))
    assert np.max(np.abs(residual)) < 1e-4


@pytest.mark.parametrize("omega", [0.2, 0.8, 0.99])
def test_peak_frequency_and_energy(omega):
    ell = 3.0
    b = SineGordonBreather(omega, ell)
    t_peak = np.pi / (2 * omega)
    assert b.phi(0.0, t_peak) == pytest.approx(b.amplitude, rel=1e-12)
    assert breather_frequency(b.amplitude) == pytest.approx(omega, rel=1e-12)
    # energy in units of A_s: Σ_sites [½ φ_t² + ½ ℓ² φ_ξ² + 1 − cos φ] (time in 1/ω0) as an integral over ξ
    xi = np.linspace(-60 * ell / b.nu, 60 * ell / b.nu, 200001)
    t, dt = 0.41, 1e-5
    phi = b.phi(xi, t)
    phi_t = (b.phi(xi, t + dt) - b.phi(xi, t - dt)) / (2 * dt)
    phi_x = np.gradient(phi, xi)
    density = 0.5 * phi_t**2 + 0.5 * ell**2 * phi_x**2 + 1 - np.cos(phi)
    assert np.trapezoid(density, xi) == pytest.approx(b.energy, rel=1e-5)


def test_frenkel_kontorova_scales_and_bad_amplitude():
    omega0, ell = frenkel_kontorova_scales(k=4.0, m=1.0, amplitude_j=1.0, period=2 * np.pi)
    assert omega0 == pytest.approx(1.0) and ell == pytest.approx(2.0)
    with pytest.raises(ValueError, match="peak"):
        breather_frequency(7.0)
