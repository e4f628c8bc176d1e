"""Envelope (bright) solitons of the rotational branch: the nonlinear Schrödinger limit (docs/physics.md §1.5).

For the chain of docs/physics.md §1.1 with θ0 = 0 and s_v = 0, a slowly modulated carrier
θ_n = A(X, T) e^{i(qn − ΩT)} + c.c. on the rotational branch α²Ω² = K_s sin²(q/2) + 4K_θ cos²(q/2) + 2n_vK_θ
obeys, to cubic order (multiple scales, *derived*),

    i (A_T + c_g A_X) + ½ Ω″ A_XX − δ0 |A|² A = 0,   δ0 = −Γ/(2α²Ω),

    Γ = 1/(1 − c_g²) − (5 + cos 2q)/4 + sin²2q / (8 (sin²q − Ω²)) + 2 K_s sin²(q/2).

The first term of Γ is the longitudinal strain slaved to the envelope (it moves with c_g), the third
the bound 2Ω longitudinal wave, the others the geometric cubic terms of the hinge law. If Ω″ δ0 < 0
the envelope focuses and carries the bright soliton A = a sech((X − c_g T)/L) e^{−iδ0 a² T/2}, i.e. a
rotation θ of peak θ_m = 2a with θ_m L = sqrt(−4Ω″/δ0) (FWHM of the envelope 2 arccosh(2) L).
Nondimensional units of docs/physics.md §1.1 (X in sites, T in sqrt(m/k_l)).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

#: FWHM of sech(x/L) in units of L: 2 arccosh 2
SECH_FWHM = 2.0 * math.acosh(2.0)


@dataclass(frozen=True)
class EnvelopeSoliton:
    """NLS coefficients at carrier q (rad/site) and frequency omega (nondimensional, module docstring)."""

    q: float
    omega: float
    alpha2: float
    group_velocity: float  # sites per time unit
    dispersion: float  # Ω″ = d²Ω/dq²
    gamma: float
    gamma_strain: float  # the slaved-strain part of gamma, 1/(1 − c_g²)

    @property
    def delta0(self) -> float:
        """Cubic frequency shift coefficient of the envelope, −Γ/(2α²Ω)."""
        return -self.gamma / (2.0 * self.alpha2 * self.omega)

    @property
    def delta0_uniform(self) -> float:
        """The same for an unmodulated wave (no slaved strain): Ω → Ω + δ |A|²."""
        return -(self.gamma - self.gamma_strain) / (2.0 * self.alpha2 * self.omega)

    @property
    def focusing(self) -> bool:
        return self.dispersion * self.delta0 < 0

    @property
    def product(self) -> float | None:
        """θ_m L of the bright soliton (θ_m its peak rotation, L its sech width in sites); None if defocusing."""
        return math.sqrt(-4.0 * self.dispersion / self.delta0) if self.focusing else None


def rotational_omega(p, q: float) -> float:
    """Ω(q) of the rotational branch of the θ0 = 0 chain (docs/physics.md §1.4)."""
    s2 = math.sin(q / 2) ** 2
    return math.sqrt((p.Ks * s2 + 4 * p.Ktheta * (1 - s2) + 2 * p.n_v * p.Ktheta) / p.alpha2)


def rotational_wavenumber(p, omega: float) -> float:
    """Carrier q in (0, π) of frequency omega on the rotational branch (ValueError outside the band)."""
    s2 = (p.alpha2 * omega**2 - 4 * p.Ktheta - 2 * p.n_v * p.Ktheta) / (p.Ks - 4 * p.Ktheta)
    if not 0.0 < s2 < 1.0:
        raise ValueError(f"Ω = {omega:g} lies outside the rotational band "
                         f"[{rotational_omega(p, 0.0):g}, {rotational_omega(p, math.pi):g}]")
    return 2.0 * math.asin(math.sqrt(s2))


def envelope_soliton(p, omega: float) -> EnvelopeSoliton:
    """NLS coefficients of the carrier of frequency omega (p: RotatingChainND with θ0 = 0, s_v = 0)."""
    if p.theta0 != 0.0 or p.s_v != 0 or getattr(p, "theta_s", 0.0) != 0.0:
        raise ValueError("the envelope theory covers the unloaded chain with θ0 = 0 and s_v = 0 only")
    q = rotational_wavenumber(p, omega)
    h = 1e-4 * min(q, math.pi - q)
    w_m, w_p = rotational_omega(p, q - h), rotational_omega(p, q + h)
    cg = (w_p - w_m) / (2 * h)
    d2 = (w_p - 2 * omega + w_m) / h**2
    strain = 1.0 / (1.0 - cg**2)
    gamma = (strain - (5.0 + math.cos(2 * q)) / 4.0
             + math.sin(2 * q) ** 2 / (8.0 * (math.sin(q) ** 2 - omega**2)) + 2.0 * p.Ks * math.sin(q / 2) ** 2)
    return EnvelopeSoliton(q, omega, p.alpha2, cg, d2, gamma, strain)
