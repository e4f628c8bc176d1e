"""Split a driven chain's response at one frequency into its left- and right-running waves.

Used for the wave reflected by a boundary (docs/physics.md §1.7): over a window of whole drive
periods, the complex amplitude Y_n of harmonic k at site n (y = Re(Y e^{−ikωt})) is fitted by least
squares to L e^{iqn} + R e^{−iqn} (q the wavenumber of that frequency in rad per site, from the
linear dispersion). R is the left-running wave (e.g. the reflection), L the right-running one.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class RunningWaves:
    """Complex amplitudes of the right- (``right``) and left-running (``left``) waves, and the fit's rms residual."""

    right: complex
    left: complex
    residual: float


def complex_amplitudes(time: np.ndarray, values: np.ndarray, frequency_hz: float, t_start: float,
                       t_end: float) -> np.ndarray:
    """Y per site (values (n_t, n_sites)) at ``frequency_hz`` over whole periods of it ending at t_end."""
    period = 1.0 / frequency_hz
    n_per = int((t_end - t_start) / period + 1e-9)
    if n_per < 1:
        raise ValueError(f"window {t_start:g}–{t_end:g} s is shorter than one period {period:g} s")
    win = (time >= t_end - n_per * period - 1e-9 * period) & (time <= t_end + 1e-9 * period)
    tw, yw = time[win], values[win]
    wt = np.zeros_like(tw)
    wt[1:] += 0.5 * np.diff(tw)
    wt[:-1] += 0.5 * np.diff(tw)
    wt /= wt.sum()
    yc = yw - np.tensordot(wt, yw, axes=(0, 0))
    return 2 * np.tensordot(wt * np.exp(2j * np.pi * frequency_hz * tw), yc, axes=(0, 0))


def running_waves(amplitudes: np.ndarray, sites: np.ndarray, q: float) -> RunningWaves:
    """Least-squares L e^{iqn} + R e^{−iqn} through the complex amplitudes at ``sites``."""
    n = np.asarray(sites, float)
    a = np.stack([np.exp(1j * q * n), np.exp(-1j * q * n)], axis=1)
    y = np.asarray(amplitudes)[np.asarray(sites)]
    coef, *_ = np.linalg.lstsq(a, y, rcond=None)
    res = float(np.sqrt(np.mean(np.abs(a @ coef - y) ** 2)))
    return RunningWaves(right=complex(coef[0]), left=complex(coef[1]), residual=res)
