"""A localised oscillation at one site: its frequency and peak (breathers, docs/physics.md §2).

Frequency from the upward zero crossings of y(t) − mean (linear interpolation between frames,
then a least-squares fit of crossing time against crossing number: the period is the slope);
peak = the largest |y| in the window.
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
    return Oscillation(frequency_hz=float(1.0 / period), peak=float(np.abs(y).max()), n_periods=int(tz.size - 1))
