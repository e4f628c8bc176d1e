"""Dominant-pulse extraction: arrival times → speed, peak |field| → amplitude, FWHM → width.

Arrival time at a site = time of the largest peak of |field(t)| there (the dominant pulse,
not small precursors), refined by a three-point parabola through the sampled maximum. Sites
whose largest peak is below ``threshold_fraction`` of the 90th percentile, or of the minority
polarity, are dropped, and so are
outliers of the line fit (> 4 median absolute deviations). Speed = inverse slope of the
least-squares line through (position, arrival time) over the interior sites, with its
standard error. Width = full width at half maximum of |field(x)| at the frame where the
pulse is mid-way (scipy.signal.peak_widths), in metres.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy.signal import find_peaks, peak_widths


class PulseNotFound(Exception):
    """No pulse above the threshold crossed enough sites to measure."""


@dataclass
class Pulse:
    field: str
    speed_m_s: float
    speed_stderr_m_s: float
    amplitude: float
    amplitude_units: str
    fwhm_m: float
    fwhm_sites: float
    n_sites_fitted: int
    first_site: int
    last_site: int

    def as_dict(self) -> dict:
        return asdict(self)


def _parabolic_peak(y: np.ndarray, k: int) -> tuple[float, float]:
    """Sub-sample location offset and height of a sampled maximum at index k."""
    if k <= 0 or k >= y.size - 1:
        return 0.0, float(y[k])
    a, b, c = y[k - 1], y[k], y[k + 1]
    den = a - 2 * b + c
    if den >= 0:
        return 0.0, float(b)
    off = 0.5 * (a - c) / den
    return float(off), float(b - 0.25 * (a - c) * off)


def arrival_times(values: np.ndarray, time: np.ndarray):
    """Time of the largest peak of |values[:, i]| per site: (times, signed peaks)."""
    n_t, n_s = values.shape
    times = np.full(n_s, np.nan)
    peaks = np.full(n_s, np.nan)
    dt = np.diff(time)
    for i in range(n_s):
        y = np.abs(values[:, i])
        k = int(np.argmax(y))
        if y[k] == 0:
            continue
        off, height = _parabolic_peak(y, k)
        step = dt[min(k, dt.size - 1)] if dt.size else 0.0
        times[i] = time[k] + off * step
        peaks[i] = np.sign(values[k, i]) * height
    return times, peaks


def leading_pulse(ds, field: str = "theta", *, threshold_fraction: float = 0.5,
                  trim_fraction: float = 0.15, site_range: tuple[int, int] | None = None) -> Pulse:
    """Speed, amplitude and width of the first pulse travelling through ``ds[field]``."""
    values = np.asarray(ds[field].values, float)
    time = np.asarray(ds["time"].values, float)
    x = np.asarray(ds["x"].values, float) if "x" in ds else np.asarray(ds["site"].values, float)
    n_s = values.shape[1]
    peak = np.nanmax(np.abs(values))
    if not np.isfinite(peak) or peak == 0:
        raise PulseNotFound(f"field {field!r} is identically zero or not finite")
    times, peaks = arrival_times(values, time)
    lo, hi = site_range or (int(trim_fraction * n_s), int(np.ceil((1 - trim_fraction) * n_s)))
    sel = np.arange(lo, hi)
    sel = sel[np.isfinite(times[sel])]
    if sel.size:
        ref = np.percentile(np.abs(peaks[sel]), 90)
        sel = sel[np.abs(peaks[sel]) >= threshold_fraction * ref]
        polarity = np.sign(np.median(peaks[sel]))
        sel = sel[np.sign(peaks[sel]) == polarity]
    if sel.size >= 5:
        res = times[sel] - np.polyval(np.polyfit(x[sel], times[sel], 1), x[sel])
        mad = np.median(np.abs(res - np.median(res))) + 1e-300
        sel = sel[np.abs(res - np.median(res)) <= 4 * 1.4826 * mad]
    if sel.size < 5:
        raise PulseNotFound(
            f"no pulse in {field!r}: only {sel.size} interior sites carry a consistent pulse "
            f"(peak |{field}| = {peak:.3g})"
        )
    coef, cov = np.polyfit(x[sel], times[sel], 1, cov=True)
    slowness, s_err = coef[0], float(np.sqrt(cov[0, 0]))
    speed = 1.0 / slowness
    mid = sel[sel.size // 2]
    frame = int(np.argmin(np.abs(time - times[mid])))
    prof = np.abs(values[frame])
    loc, _ = find_peaks(np.concatenate([[0.0], prof, [0.0]]))
    loc = loc - 1
    k = int(loc[np.argmin(np.abs(loc - mid))]) if loc.size else mid
    widths = peak_widths(prof, [k], rel_height=0.5)[0]
    spacing = float(np.median(np.diff(x))) if x.size > 1 else 1.0
    units = ds[field].attrs.get("units", "")
    return Pulse(
        field=field,
        speed_m_s=float(speed),
        speed_stderr_m_s=float(s_err * speed**2),
        amplitude=float(np.median(peaks[sel])),
        amplitude_units=units,
        fwhm_m=float(widths[0] * spacing),
        fwhm_sites=float(widths[0]),
        n_sites_fitted=int(sel.size),
        first_site=int(sel[0]),
        last_site=int(sel[-1]),
    )
