"""Second-harmonic generation in a driven quadratic (FPU-α) chain (docs/physics.md §2).

Chain m ẍ_n = T(x_{n+1} − x_n) − T(x_n − x_{n−1}), T(D) = k1 D + k2 D², site 0 prescribed,
x_0(t) = A sin ωt. To first order a wave x_n = A sin(ωt − qn) runs into the chain with
ω = 2 sqrt(k1/m) sin(q/2). Second-order perturbation theory (*derived*): the quadratic bond force
drives the 2ω response with wavenumber 2q; the free 2ω wave has q2, sin(q2/2) = 2 sin(q/2). With
the second harmonic held at zero at the driven site and radiating into the chain,

    x2_n = P (e^{2iqn} − e^{i q2 n}),   |P| = k2 A² cos(q/2) / (2 k1 sin(q/2)),

so its amplitude 2|P| |sin(Δq n/2)| (Δq = 2q − q2 ≠ 0 by dispersion) grows linearly near the
drive, k2 A² q² n/(4 k1) in the long-wave limit, and beats with period 2π/|Δq| sites
(coherence length π/|Δq|). Needs 2ω < 2 sqrt(k1/m) (otherwise the 2ω wave is evanescent).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class SecondHarmonic:
    """Wavenumbers (rad per site), prefactor |P| (length) of the FPU second harmonic."""

    q: float
    q2: float
    prefactor: float

    @property
    def mismatch(self) -> float:
        """Δq = 2q − q2 (rad per site; negative: the free 2ω wave is slower)."""
        return 2 * self.q - self.q2

    @property
    def coherence_length(self) -> float:
        """Sites from the drive to the first maximum of the second harmonic, π/|Δq|."""
        return math.pi / abs(self.mismatch)

    def amplitude(self, n):
        """Second-harmonic displacement amplitude at sites n (array), 2|P| |sin(Δq n/2)|."""
        return 2 * self.prefactor * np.abs(np.sin(0.5 * self.mismatch * np.asarray(n, float)))


def fpu_second_harmonic(amplitude: float, omega: float, k1: float, k2: float, m: float) -> SecondHarmonic:
    """Second harmonic of the displacement-driven FPU-α chain (module docstring); consistent units."""
    ratio = omega / (2 * math.sqrt(k1 / m))
    if not 0 < ratio < 0.5:
        raise ValueError(f"ω = {omega:g} must lie below half the band edge 2 sqrt(k1/m) = "
                         f"{2 * math.sqrt(k1 / m):g} for a propagating second harmonic")
    q = 2 * math.asin(ratio)
    q2 = 2 * math.asin(2 * ratio)
    prefactor = abs(k2) * amplitude**2 * math.cos(q / 2) / (2 * k1 * math.sin(q / 2))
    return SecondHarmonic(q=q, q2=q2, prefactor=prefactor)
