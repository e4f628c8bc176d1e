"""Harmonic content of a driven run, site by site: amplitude of n ω against distance.

Uses the lock-in amplitude of ``analysis.measure.driven`` over a window of whole drive periods, here an
explicit time window (the steady part before reflections return), for several harmonics at once.
"""
from __future__ import annotations

import numpy as np

from flexmm.analysis.measure.driven import lockin


def harmonic_profiles(time: np.ndarray, values: np.ndarray, frequency_hz: float, t_start: float,
                      t_end: float, orders=(1, 2, 3)) -> np.ndarray:
    """Amplitude of each harmonic order at each site, shape (len(orders), n_sites).

    ``values`` has shape (n_t, n_sites); the window [t_start, t_end] is cut to whole periods
    (ending at t_end).
    """
    period = 1.0 / frequency_hz
    n_per = int((t_end - t_start) / period + 1e-9)
    if n_per < 1:
        raise ValueError(f"window {t_start:g}–{t_end:g} s is shorter than one drive period {period:g} s")
    win = (time >= t_end - n_per * period - 1e-9 * period) & (time <= t_end + 1e-9 * period)
    if win.sum() < 4 * max(orders) + 1:
        raise ValueError(f"{win.sum()} frames in the window cannot resolve harmonic {max(orders)}")
    tw, yw = time[win], values[win]
    return np.array([lockin(yw, tw, k * frequency_hz) for k in orders])
