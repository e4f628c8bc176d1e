"""Ready-made comparisons for chains of masses (PHYSICS.md §2), to wire into ``compare.THEORY``.

Each function takes a measurement plus the chain's SI parameters and returns Comparison rows;
a chain model's ``ModelTheory.pulse``/``front`` reads its parameters from ``ctx.scene()`` and
calls the matching function. Strains in the dataset are bond elongations per spacing, so the
bond elongation is D = strain · a.
"""

from __future__ import annotations

import math

import numpy as np

from flexmm.analysis.compare import Comparison
from flexmm.theory import chains as th


def softening_pulse(p_meas, k1: float, k2: float, m: float, a: float) -> list[Comparison]:
    """sech² solitary wave of T(D) = k1 D + k2 D²: speed and W at the measured strain peak."""
    wave = th.softening_solitary_wave(k1, k2, p_meas.amplitude * a, m, a)
    return [
        Comparison("", "speed", p_meas.speed_m_s, wave.v, "m/s", "v = c0 sqrt(1 + 2k2Dm/(3k1))"),
        Comparison("", "width W (sech² fit)", p_meas.width_sech2_m, wave.W * a, "m", "W = sqrt(k1/(2k2Dm)) sites"),
    ]


def hertz_pulse(p_meas, A: float, m: float, D: float) -> list[Comparison]:
    """Nesterenko solitary wave: speed at the measured compressive strain peak ξ_m = −strain."""
    xi = -p_meas.amplitude
    if not xi > 0:
        raise ValueError("a Hertz solitary wave is compressive")
    return [
        Comparison("", "speed", p_meas.speed_m_s, th.nesterenko_speed(A, m, D, xi), "m/s",
                   "V = (2/√5) c ξm^(1/4)"),
        Comparison("", "FWHM", p_meas.fwhm_m, 2 * 5 * D / math.sqrt(10) * math.acos(0.5 ** 0.25), "m",
                   "FWHM of ξm cos⁴(√10 x/(5D))"),
    ]


def bistable_front(f_meas, alpha: float, beta: float, L: float, k: float, m: float, a: float,
                   eta: float) -> list[Comparison]:
    """Damped bistable front: speed v and 10–90 % width w ln 9 of (L/2)(1 − tanh(x/w))."""
    fr = th.bistable_front(alpha, beta, L, k, m, a, eta)
    return [
        Comparison("", "speed", f_meas.speed_m_s, fr.v, "m/s", "v = c0/sqrt(1 + 2η²/(mαL²(1−2β)²))"),
        Comparison("", "width 10–90 %", f_meas.width_10_90_m, fr.w * math.log(9.0), "m", "w ln 9"),
    ]


def front_kinetic_energy(ds, f_meas, m: float, dphi: float, eta: float, a: float) -> list[Comparison]:
    """K = m v Δφ/(2 η a) against the median kinetic energy while the front crosses its middle half."""
    t = f_meas.track_time_s
    lo, hi = t[0] + 0.25 * (t[-1] - t[0]), t[0] + 0.75 * (t[-1] - t[0])
    time = np.asarray(ds["time"].values)
    sel = (time >= lo) & (time <= hi)
    K = float(np.median(ds["kinetic_energy"].values[sel]))
    return [Comparison("", "kinetic energy", K, th.front_kinetic_energy(m, f_meas.speed_m_s, dphi, eta, a),
                       "J", "K = m v Δφ/(2 η a) at the measured v")]


def linear_chain_bands_hz(k: float, m: float, k_onsite: float = 0.0) -> list[tuple[float, float]]:
    """Pass band of the linear chain (Hz)."""
    lo, hi = th.linear_chain_band(k, m, k_onsite)
    return [(lo / (2 * math.pi), hi / (2 * math.pi))]
