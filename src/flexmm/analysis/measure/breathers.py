"""A localised oscillation at one site: its frequency and peak (breathers, docs/physics.md §2).

Frequency from the upward zero crossings of y(t) − mean (linear interpolation between frames,
then a least-squares fit of crossing time against crossing number: the period is the slope);
peak = the largest |y| in the window, refined by the parabola through it and its two neighbours.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Oscillation:
    """Frequency (Hz, if t is in s), peak |y| and the number of periods the fit used."""

    frequency_hz: float
    peak: float
    n_periods: int


def site_oscillation(time: np.ndarray, y: np.ndarray) -> Oscillation:
    """Frequency and peak of the oscillation y(t) (n_t,) sampled at ``time`` (n_t,)."""
    yc = y - y.mean()
    up = np.flatnonzero((yc[:-1] < 0) & (yc[1:] >= 0))
    if up.size < 3:
        raise ValueError(f"{up.size} upward zero crossings: too few to measure a frequency")
    tz = time[up] - yc[up] * (time[up + 1] - time[up]) / (yc[up + 1] - yc[up])
    period = np.polyfit(np.arange(tz.size), tz, 1)[0]
    return Oscillation(frequency_hz=float(1.0 / period), peak=_peak(np.abs(y)), n_periods=int(tz.size - 1))


def _peak(a: np.ndarray) -> float:
    """Largest value of a sampled curve: vertex of the parabola through the top sample and its neighbours."""
    k = int(np.argmax(a))
    if k == 0 or k == a.size - 1:
        return float(a[k])
    y0, y1, y2 = a[k - 1], a[k], a[k + 1]
    den = y0 - 2 * y1 + y2
    return float(y1 - 0.125 * (y0 - y2) ** 2 / den) if den < 0 else float(y1)
