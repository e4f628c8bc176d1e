"""Steady periodic (cnoidal) waves of a driven run: the numbers flexmm.theory.cnoidal predicts.

Over a window of whole drive periods and a stretch of sites, per site the complex harmonics
H_n = 2 <(y - ybar) e^{-i n omega t}> (analysis.measure.driven.lockin's average) and the mean ybar. The
wavenumber q (radians per site) is the slope of the unwrapped phase of H1 along the sites, so the
phase speed is omega/q sites per unit time. A driven nonlinear wave carries *bound* harmonics,
phase-locked to the fundamental (H_n ~ e^{-i n q site}), and *free* ones launched at the drive at
their own wavenumber; the bound part is the site average of H_n e^{-i n arg H1}, in which the free
part beats and averages out over a few beat lengths. Crest and trough are site averages of the
window's extremes (they include the free harmonics).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class PeriodicWave:
    """Measured steady wave over sites[0]..sites[-1]; amplitudes in the field's units."""

    frequency_hz: float
    sites: np.ndarray  # (n_sites,)
    amplitude: float  # site mean of |H1|
    amplitude_spread: float  # max - min of |H1| over the sites
    mean: float  # mean of the field over window and sites
    wavenumber: float  # rad per site
    sites_per_s: float  # phase speed
    bound_ratios: np.ndarray  # (n_harmonics - 1,) bound |H_n|/|H1|, n = 2..
    crest: float
    trough: float


def measure_periodic_wave(values: np.ndarray, time: np.ndarray, frequency_hz: float, sites,
                          periods: int = 4, n_harmonics: int = 3) -> PeriodicWave:
    """Measure the last `periods` drive periods of values (n_time, n_sites_total) at `sites`."""
    sites = np.asarray(sites, dtype=int)
    sel = time >= time[-1] - periods / frequency_hz - 1e-9 / frequency_hz
    t, y = time[sel], values[sel][:, sites]
    if t.size < 8 * n_harmonics:
        raise ValueError(f"{t.size} frames in the last {periods} periods: too few to resolve {n_harmonics} harmonics")
    w = np.zeros_like(t)  # trapezoid weights: averages over whole periods
    w[1:] += 0.5 * np.diff(t)
    w[:-1] += 0.5 * np.diff(t)
    w /= w.sum()
    ybar = w @ y
    H = np.array([2 * ((w * np.exp(-2j * np.pi * n * frequency_hz * t)) @ (y - ybar))
                  for n in range(1, n_harmonics + 1)])  # (n_harmonics, n_sites)
    phase = np.unwrap(np.angle(H[0]))
    q = -np.polyfit(sites, phase, 1)[0]
    A1 = np.abs(H[0])
    bound = [abs(np.mean(H[n - 1] * np.exp(-1j * n * np.angle(H[0])))) / A1.mean()
             for n in range(2, n_harmonics + 1)]
    return PeriodicWave(float(frequency_hz), sites, float(A1.mean()), float(np.ptp(A1)), float(np.mean(ybar)),
                        float(q), float(2 * np.pi * frequency_hz / q), np.asarray(bound),
                        float(y.max(axis=0).mean()), float(y.min(axis=0).mean()))
