"""Envelope of a modulated carrier along a chain: peak position, peak amplitude and FWHM per frame.

The envelope of one frame θ_n (n_sites,) is the modulus of its analytic signal along the sites
(scipy.signal.hilbert), valid for a carrier well inside (0, π) rad/site and an envelope many
carrier periods wide. The FWHM is interpolated between the half-maximum crossings on either side
of the peak.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class EnvelopeTrack:
    """Per frame: peak site (interpolated), peak envelope amplitude, FWHM (sites); plus the times."""

    time: np.ndarray
    position: np.ndarray
    amplitude: np.ndarray
    fwhm: np.ndarray

    def speed(self, t_start: float, t_end: float) -> float:
        """Sites per time unit of the peak, least squares over frames in [t_start, t_end]."""
        w = (self.time >= t_start) & (self.time <= t_end)
        return float(np.polyfit(self.time[w], self.position[w], 1)[0])


def _half_crossing(env: np.ndarray, k: int, step: int) -> float:
    half = 0.5 * env[k]
    j = k
    while 0 < j < env.size - 1 and env[j + step] > half:
        j += step
    nxt = j + step
    if not 0 <= nxt < env.size or env[j] <= env[nxt]:
        return float(j)
    return j + step * (env[j] - half) / (env[j] - env[nxt])


def envelope_track(time: np.ndarray, values: np.ndarray) -> EnvelopeTrack:
    """Track the largest envelope in each frame of ``values`` (n_t, n_sites)."""
    from scipy.signal import hilbert  # here: scipy.signal is slow to import

    env = np.abs(hilbert(values, axis=1))
    pos, amp, width = [], [], []
    for row in env:
        k = int(np.argmax(row))
        lo, hi = _half_crossing(row, k, -1), _half_crossing(row, k, 1)
        if 0 < k < row.size - 1:  # parabola through the top three samples
            y0, y1, y2 = row[k - 1], row[k], row[k + 1]
            den = y0 - 2 * y1 + y2
            pos.append(k + (0.5 * (y0 - y2) / den if den < 0 else 0.0))
        else:
            pos.append(float(k))
        amp.append(row[k])
        width.append(hi - lo)
    return EnvelopeTrack(np.asarray(time, float), np.asarray(pos), np.asarray(amp), np.asarray(width))
