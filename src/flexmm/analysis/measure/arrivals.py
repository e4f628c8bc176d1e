"""Arrival times of a tracked pulse at each site it crosses, and the speed fit through them.

Arrival time at a site = peak of the site's time trace inside a window around the time the
track predicts, refined by a least-squares parabola through the top samples (peak height by the
three-point parabola). Sites where another pulse moving relative to this one (a collision, not a
lobe of the same packet) is within 3 FWHM are *overlapped*: left out, and they split the path
into segments. A collision delays or advances a pulse without changing
its speed, so the fit t = s·x + b_k keeps one slowness s and gives each segment k its own
intercept; consecutive segments whose own speeds differ by more than ``SPEED_CHANGE`` are
different pulses (e.g. a pulse re-emitted after a repulsive collision) and are measured apart.
"""

from __future__ import annotations

import numpy as np

from flexmm._blas import single_blas_thread
from flexmm.analysis.features.detect import refine_peak

SPEED_CHANGE = 0.02  # relative speed change that ends a pulse at a collision
OVERLAP_FWHM = 3.0  # another pulse closer than this many FWHM overlaps a site


def peak_time(t: np.ndarray, y: np.ndarray, k: int, level: float = 0.6) -> tuple[float, float]:
    """Peak time and height near the sampled maximum y[k].

    Time: vertex of the least-squares parabola through the samples above level·y[k], as many
    on each side of k, which averages noise (a broad peak uses many samples); height: the three-point parabola, least biased
    by the peak's shape.
    """
    lo = hi = k
    while lo > 0 and y[lo - 1] >= level * y[k]:
        lo -= 1
    while hi < y.size - 1 and y[hi + 1] >= level * y[k]:
        hi += 1
    side = min(k - lo, hi - k)  # symmetric about the sampled maximum: no bias when one side is cut
    lo, hi = k - side, k + side
    if hi - lo < 2:
        lo, hi = max(k - 1, 0), min(k + 1, y.size - 1)
    height = refine_peak(y, k)[1]
    if hi - lo < 2:
        return float(t[k]), height
    tt = t[lo : hi + 1] - t[k]
    a, b, _ = np.polyfit(tt, y[lo : hi + 1], 2)
    if not a < 0 or abs(-b / (2 * a)) > (tt[-1] - tt[0]):
        return float(t[k]), height
    return float(t[k] - b / (2 * a)), height


def arrivals(view, tr_t, tr_pos, polarity, fwhm, others):
    """Per site the track crosses: (sites, times, signed peaks, overlapped, direction).

    ``others`` = [(times, positions)] of the other tracks. Times and peaks are NaN where the
    peak is not inside its window or another pulse is near (then ``overlapped`` is True).
    """
    order = np.argsort(tr_t)
    tt, pp = tr_t[order], tr_pos[order]
    direction = 1 if pp[-1] >= pp[0] else -1
    env = np.maximum.accumulate(pp) if direction > 0 else np.minimum.accumulate(pp)
    v = abs(np.polyfit(tt, pp, 1)[0]) if np.ptp(tt) > 0 else 0.0
    sites = np.flatnonzero((view.x >= env.min()) & (view.x <= env.max()))
    times, peaks = np.full(sites.size, np.nan), np.full(sites.size, np.nan)
    overlap = np.zeros(sites.size, bool)
    half = max(3 * float(np.median(np.diff(view.time))), 1.5 * fwhm / max(v, 1e-300))
    env_d, tt_d = (env, tt) if direction > 0 else (env[::-1], tt[::-1])
    for n, i in enumerate(sites):
        win = np.flatnonzero(np.abs(view.time - float(np.interp(view.x[i], env_d, tt_d))) <= half)
        if win.size < 3:
            continue
        y = polarity * view.values[win, i]
        k = int(np.argmax(y))
        if k == 0 or k == win.size - 1 or not y[k] > 0:
            continue
        t_i, h_i = peak_time(view.time[win], y, k)
        if _colliding(t_i, view.x[i], direction * v, others, OVERLAP_FWHM * fwhm):
            overlap[n] = True
            continue
        times[n], peaks[n] = t_i, polarity * h_i
    return sites, times, peaks, overlap, direction


def _colliding(t: float, x: float, v: float, others, distance: float) -> bool:
    """True if another track is within ``distance`` of (t, x) and moving relative to this one
    (|v_other − v| > 25 % of |v|): a collision, not a lobe travelling along in the same packet."""
    for ot, op in others:
        if ot.size < 2 or not ot[0] <= t <= ot[-1]:
            continue
        if abs(np.interp(t, ot, op) - x) < distance:
            k = int(np.searchsorted(ot, t))
            k0, k1 = max(k - 3, 0), min(k + 3, ot.size - 1)
            vo = (op[k1] - op[k0]) / (ot[k1] - ot[k0]) if ot[k1] > ot[k0] else 0.0
            if abs(vo - v) > 0.25 * abs(v):
                return True
    return False


def segments(overlap_in_travel_order: np.ndarray) -> np.ndarray:
    """Segment index of sites ordered along the travel: +1 after each run of overlapped sites."""
    o = overlap_in_travel_order
    return np.cumsum(o & ~np.concatenate([[False], o[:-1]]))


def line_fit(x, y):
    """Slope, intercept and slope standard error of the least-squares line y(x); all NaN when
    the points share one abscissa (arrivals at sites of one column of a sheet, say)."""
    if np.unique(x).size < 2:
        return np.nan, np.nan, np.nan
    if x.size < 3:
        coef = np.polyfit(x, y, 1)
        return coef[0], coef[1], np.nan
    coef, cov = np.polyfit(x, y, 1, cov=True)
    return coef[0], coef[1], float(np.sqrt(cov[0, 0]))


def segment_fit(x, t, seg):
    """Common slope, its standard error, intercepts per segment and residuals of t = s x + b_seg."""
    ids = np.unique(seg)
    A = np.column_stack([x] + [(seg == k).astype(float) for k in ids])
    with single_blas_thread():  # a small least-squares problem: BLAS threads only add overhead
        coef, *_ = np.linalg.lstsq(A, t, rcond=None)
        res = t - A @ coef
        dof = x.size - A.shape[1]
        err = np.nan
        if dof > 0:
            cov = np.linalg.pinv(A.T @ A) * float(res @ res) / dof
            err = float(np.sqrt(max(cov[0, 0], 0.0)))
    return float(coef[0]), err, coef[1:], res


def clean(x, t, seg, n_mad: float = 4.0) -> np.ndarray:
    """Mask of points within n_mad scaled median absolute deviations of the segment fit."""
    res = segment_fit(x, t, seg)[3]
    dev = np.abs(res - np.median(res))
    mad = 1.4826 * np.median(dev) + 1e-12 * (np.ptp(t) + 1e-300)
    return dev <= n_mad * mad


def speed_groups(x, t, seg, min_sites: int = 5) -> list[np.ndarray]:
    """Segments (in travel order) grouped into runs of the same speed (within SPEED_CHANGE).

    A segment with fewer than ``min_sites`` sites joins the current group.
    """
    groups: list[list[int]] = []
    ref = None
    for k in np.unique(seg):
        m = seg == k
        s = np.polyfit(x[m], t[m], 1)[0] if m.sum() >= min_sites else None
        if groups and (s is None or ref is None or abs(ref / s - 1) <= SPEED_CHANGE):
            groups[-1].append(k)
            ref = ref if ref is not None else s
        else:
            groups.append([k])
            ref = s
    return [np.asarray(g) for g in groups]
