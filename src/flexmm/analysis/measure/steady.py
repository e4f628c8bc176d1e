"""Formation transient and breathing of a measured pulse, from its peak along the path.

The peak |A| of a pulse at the sites it crosses, in travel order, is split into a formation
transient and a steady part:

- the steady band is the range of |A| over the second half of the path, widened by a margin
  of max(2 σ, 1 % of the median), σ the sample noise of |A| (robust spread of its residual
  from a Savitzky–Golay smoothing, ``_noise``);
- the pulse is steady from the site after the last one of the first half outside that band:
  the stretch before it is the formation transient (``formation_distance_m`` along the path,
  ``formation_time_s`` in arrival time from the first fitted site). A pulse that never leaves
  its band has formation distance 0;
- over the steady part, the amplitude range [min, max] is reported; the pulse *breathes* when
  the range exceeds max(6 σ, 2 % of the median) and |A| crosses its mean at least four times
  (two periods; crossings counted with a hysteresis of max(2 σ, 15 % of the range)); the
  period is 2 × (time between the first and last crossing)/(crossings − 1).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from flexmm.analysis.features.peaks import smooth_cubic7


@dataclass(frozen=True)
class Steady:
    start: int  # index (in travel order) of the first steady site
    formation_distance_m: float
    formation_time_s: float
    amplitude_min: float  # of |A| over the steady part, signed like the pulse
    amplitude_max: float
    breathing: bool
    breathing_period_s: float


def _noise(a: np.ndarray) -> float:
    """Sample noise of a series: robust std of its residual from a Savitzky–Golay smoothing (cubic
    over 7 samples, which follows a breathing of 7+ samples per period), scaled by 1/√(1 − 1/3)
    (the filter's central weight is 1/3) to the noise of one sample."""
    if a.size < 7:
        return 0.0
    r = a - smooth_cubic7(a)
    return float(1.4826 * np.median(np.abs(r - np.median(r))) / np.sqrt(2.0 / 3.0))


def _crossings(d: np.ndarray, band: float) -> np.ndarray:
    """Indices where d crosses zero, counted with hysteresis (from below −band to above +band or
    back), so noise around the mean does not count."""
    out, state = [], 0
    for k, v in enumerate(d):
        new = 1 if v > band else -1 if v < -band else state
        if state and new != state:
            out.append(k)
        state = new
    return np.asarray(out, int)


def steady_part(distance: np.ndarray, times: np.ndarray, peaks: np.ndarray) -> Steady:
    """Formation and breathing from (distance along the travel, arrival time, signed peak) per site,
    sorted by distance."""
    a = np.abs(peaks)
    sign = float(np.sign(np.median(peaks))) or 1.0
    n = a.size
    if n < 6:
        return Steady(0, 0.0, 0.0, sign * float(a.min()), sign * float(a.max()), False, np.nan)
    sigma = _noise(a)
    half = a[n // 2:]
    margin = max(2 * sigma, 0.01 * float(np.median(half)))
    lo, hi = float(half.min()) - margin, float(half.max()) + margin
    outside = np.flatnonzero((a[: n // 2] < lo) | (a[: n // 2] > hi))
    start = int(outside[-1] + 1) if outside.size else 0
    s = a[start:]
    amin, amax = float(s.min()), float(s.max())
    crossings = _crossings(s - s.mean(), max(2 * sigma, 0.15 * (amax - amin)))
    breathing = (amax - amin > max(6 * sigma, 0.02 * float(np.median(s)))) and crossings.size >= 4
    period = np.nan
    if breathing:
        tc = times[start:][crossings]
        period = float(2 * (tc[-1] - tc[0]) / (crossings.size - 1))
    return Steady(start, float(distance[start] - distance[0]), float(times[start] - times[0]),
                  sign * amin, sign * amax, bool(breathing), period)
