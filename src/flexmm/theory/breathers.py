"""The sine-Gordon breather (docs/physics.md §2, *Breathers*).

Chain m ẍ_n = k (x_{n+1} − 2x_n + x_{n−1}) − V′(x_n), V = A_s (1 − cos(2π x/λ)) (Frenkel–Kontorova).
With φ = 2π x/λ, ω0² = A_s (2π/λ)²/m and ℓ = sqrt(k/m)/ω0 sites, long waves (ℓ ≫ 1) obey the
sine-Gordon equation φ_tt = ω0² (ℓ² φ_ξξ − sin φ), ξ in sites, whose breather is

    φ(ξ, t) = 4 arctan[(ν/ω) sin(ω ω0 t) / cosh(ν ξ/ℓ)],   ν = sqrt(1 − ω²),  0 < ω < 1,

(ω the frequency in units of ω0). Its peak is A = 4 arctan(ν/ω), i.e. ω = cos(A/4): larger
breathers are slower; its energy is 16 ν A_s ℓ (Rajaraman, Solitons and Instantons, 1982).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class SineGordonBreather:
    """Breather of frequency ``omega`` (units of ω0) in a chain of coherence length ``ell`` sites."""

    omega: float
    ell: float

    @property
    def nu(self) -> float:
        return math.sqrt(1.0 - self.omega**2)

    @property
    def amplitude(self) -> float:
        """Peak φ (rad), 4 arctan(ν/ω)."""
        return 4.0 * math.atan(self.nu / self.omega)

    @property
    def energy(self) -> float:
        """Energy in units of A_s: 16 ν ℓ."""
        return 16.0 * self.nu * self.ell

    def phi(self, xi, t):
        """φ(ξ, t) for sites ξ from the centre and time t in units of 1/ω0 (broadcasts)."""
        xi, t = np.asarray(xi, float), np.asarray(t, float)
        return 4.0 * np.arctan(self.nu / self.omega * np.sin(self.omega * t) / np.cosh(self.nu * xi / self.ell))


def breather_frequency(amplitude: float) -> float:
    """ω/ω0 = cos(A/4) of the breather with peak φ = A (0 < A < 2π)."""
    if not 0.0 < amplitude < 2.0 * math.pi:
        raise ValueError(f"a breather's peak lies in (0, 2π) rad, got {amplitude:g}")
    return math.cos(amplitude / 4.0)


def frenkel_kontorova_scales(k: float, m: float, amplitude_j: float, period: float) -> tuple[float, float]:
    """(ω0 in rad per time unit, ℓ in sites) of the chain with coupling k, mass m and substrate A_s, λ."""
    omega0 = 2.0 * math.pi / period * math.sqrt(amplitude_j / m)
    return omega0, math.sqrt(k / m) / omega0
