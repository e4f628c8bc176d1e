"""Transition fronts: sites switching from one well to another (Raney et al. PNAS 2016 method).

Each site's progress is s_i(t) = (u_i(t) − u_i(0))/L, with L the well-to-well jump (given, or
the median final jump of the sites that switched); a site that starts part-way between two wells
(inside a front present at t = 0: a launched kink) is measured from its well instead (``progress``). Front position = where s crosses ½ between
neighbouring sites (linear interpolation), followed through time with the pulse tracker, so two
fronts leaving a trigger in opposite directions are measured separately; crossings between runs
shorter than three sites (ringing behind a front) are ignored. Per front:

- switching time of each site (its first crossing of ½);
- speed from the line through (x, switching time), with its standard error, over the middle
  60 % of the path (the steady part; the whole-path value is kept too);
- 10–90 % width: distance between the 10 % and 90 % crossings next to the front, median over
  the frames before the front has covered 90 % of its path;
- distance travelled, switched sites, and arrest: stopped before reaching the end, i.e. the 95 %
  confidence interval of the speed fitted to the last tenth of its track (``final_speed``)
  contains 0, or that speed would not carry it one more site in a time as long as the run (a
  stopped front still relaxing). A slow front still moving near the pinning threshold is not
  arrested.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from flexmm.analysis.features.detect import link, merge_tracks
from flexmm.errors import FlexmmError


class FrontNotFound(FlexmmError):
    """No site switched state, or no front could be followed."""


@dataclass
class FrontMeasurement:
    """One transition front; SI units; arrays are per switched site (``sites``) or per frame."""

    index: int
    field: str
    direction: int
    jump: float
    speed_m_s: float
    speed_stderr_m_s: float
    speed_whole_path_m_s: float
    width_10_90_m: float
    width_10_90_sites: float
    distance_m: float
    start_m: float
    stop_m: float
    arrested: bool
    final_speed_m_s: float
    final_speed_ci_m_s: float
    n_switched: int
    sites: np.ndarray
    x_m: np.ndarray
    switch_time_s: np.ndarray
    track_time_s: np.ndarray
    track_pos_m: np.ndarray

    def scalars(self) -> dict:
        return {k: v for k, v in asdict(self).items() if not isinstance(v, np.ndarray)}


def _crossings(x: np.ndarray, s: np.ndarray, level: float) -> np.ndarray:
    """Positions where s(x) crosses ``level`` between neighbouring samples."""
    d = s - level
    k = np.flatnonzero(np.sign(d[:-1]) * np.sign(d[1:]) < 0)
    return x[k] + (x[k + 1] - x[k]) * d[k] / (d[k] - d[k + 1])


def _front_crossings(x: np.ndarray, s: np.ndarray, min_run: int = 3) -> np.ndarray:
    """50 % crossings between runs of at least ``min_run`` sites on either side.

    Oscillations behind a front (overshoot past ½ and back) make short runs; removing them by
    a morphological opening and closing (scipy.ndimage) keeps one crossing per front.
    """
    from scipy import ndimage  # here: slow to import, and only fronts need it

    b = s >= 0.5
    st = np.ones(min_run, bool)
    b = ndimage.binary_closing(ndimage.binary_opening(b, st), st)
    edges = np.flatnonzero(b[1:] != b[:-1])
    out = []
    for k in edges:
        lo, hi = max(k - min_run, 0), min(k + min_run + 1, x.size - 1)
        c = _crossings(x[lo : hi + 1], s[lo : hi + 1], 0.5)
        if c.size:
            out.append(c[np.argmin(np.abs(c - 0.5 * (x[k] + x[k + 1])))])
    return np.asarray(out)


def switched_sites(u: np.ndarray, jump: float | None = None, tail: int = 5) -> tuple[np.ndarray, float]:
    """Mask of sites whose last ``tail`` frames sit more than half a jump from their start, and L."""
    final = np.median(u[-tail:], axis=0) - u[0]
    if jump is None:
        mag = np.abs(final)
        big = mag >= 0.5 * np.percentile(mag, 95)
        if not big.any() or np.percentile(mag, 95) == 0:
            return np.zeros(u.shape[1], bool), 0.0
        jump = float(np.median(final[big]))
    return (final / jump) > 0.5, jump


IN_WELL = 0.25  # a site whose net move is within this many jumps of a whole number started in a well


def progress(u: np.ndarray, jump: float, tail: int = 5) -> np.ndarray:
    """Each site's progress s (n_time, n_pos) from the well it started in towards the next, in jumps.

    Normally s = (u − u(0))/L. When the initial state itself holds a front — its two ends lie half
    a jump or more apart (a launched kink) — the sites that start part-way between its two sides
    (by more than ``IN_WELL`` of the difference from either) and move by a part of a jump (not a
    whole number of jumps within ``IN_WELL``) are measured from their well instead, k = round(net/L)
    jumps before their final state: s = (u − u_final + k L)/L, so they cross ½ when the front's
    centre passes them. Measured from their start, the kink's own sites cross ½ early and make a
    second edge that walks back to the launch site: a spurious front. (A front that stops part-way
    through a site, in a lattice that started in its wells, keeps the first convention.)"""
    final = np.median(u[-tail:], axis=0)
    r = (final - u[0]) / jump
    k = np.floor(r + 0.5)
    ends = u[0, -1] - u[0, 0]
    if abs(ends) < 0.5 * abs(jump):
        return (u - u[0]) / jump
    side = (u[0] - u[0, 0]) / ends  # 0 at the first site's initial value, 1 at the last's
    inside = (side > IN_WELL) & (side < 1 - IN_WELL) & (np.abs(r - k) > IN_WELL)
    return (u - np.where(inside, final - k * jump, u[0])) / jump


STEADY_TRIM = 0.2  # fraction of the path left out at each end of the steady-speed fit


def _speed(x: np.ndarray, t: np.ndarray, trim: float) -> tuple[float, float]:
    """Speed and its standard error from the line t(x), leaving out ``trim`` of the path at
    each end (launch and arrival transients) when at least five sites remain."""
    if x.size >= 5 and trim > 0:
        lo, hi = x.min() + trim * np.ptp(x), x.max() - trim * np.ptp(x)
        keep = (x >= lo) & (x <= hi)
        if keep.sum() >= 5:
            x, t = x[keep], t[keep]
    if x.size < 3:
        return np.nan, np.nan
    if x.size == 3:
        return 1.0 / abs(np.polyfit(x, t, 1)[0]), np.nan
    coef, cov = np.polyfit(x, t, 1, cov=True)
    return 1.0 / abs(coef[0]), float(np.sqrt(cov[0, 0])) / coef[0] ** 2


def _width(x, s, pos, spacing):
    """Distance between the 10 % and 90 % crossings nearest to ``pos``."""
    c10, c90 = _crossings(x, s, 0.1), _crossings(x, s, 0.9)
    if not (c10.size and c90.size):
        return np.nan
    return abs(c10[np.argmin(np.abs(c10 - pos))] - c90[np.argmin(np.abs(c90 - pos))])


LATE_FRACTION = 0.1  # the end of a front's track whose speed decides whether it was arrested


def final_speed(t: np.ndarray, pos: np.ndarray, fraction: float = LATE_FRACTION) -> tuple[float, float]:
    """Speed of the last ``fraction`` of a track (at least 5 frames) and the half-width of its
    95 % confidence interval (Student t on the slope's standard error); (0, inf) with fewer than
    three frames."""
    late = t >= t[-1] - fraction * (t[-1] - t[0])
    if late.sum() < 5:
        late = np.zeros(t.size, bool)
        late[-5:] = True
    tt, xx = t[late], pos[late]
    if tt.size < 3 or np.ptp(tt) == 0:
        return 0.0, np.inf
    coef, cov = np.polyfit(tt - tt.mean(), xx, 1, cov="unscaled")
    res = xx - np.polyval(coef, tt - tt.mean())
    dof = tt.size - 2
    se = float(np.sqrt(cov[0, 0] * float(res @ res) / dof)) if dof > 0 else np.inf
    if dof <= 0:
        return float(coef[0]), np.inf
    from scipy import stats  # here: slow to import, and only fronts need it

    return float(coef[0]), float(stats.t.ppf(0.975, dof) * se)


def measure_fronts(view, *, jump: float | None = None, min_travel_sites: float = 3.0) -> list[FrontMeasurement]:
    """Find and measure the transition fronts of a displacement FieldView; FrontNotFound if none."""
    u = view.values
    mask, L = switched_sites(u, jump)
    if L == 0 or not mask.any():
        raise FrontNotFound(f"no site of {view.spec!r} switched state (no persistent jump)")
    s = progress(u, L)
    h = view.spacing_m
    dets = [[(float(p), 1.0) for p in _front_crossings(view.x, s[j])] for j in range(view.n_time)]
    tracks = merge_tracks(link(view.time, dets, gate=4 * h, max_gap=10), 4 * h, rel_speed=0.9)
    tracks = [tr for tr in tracks if tr.travel >= min_travel_sites * h and len(tr.frames) >= 3]
    if not tracks:
        raise FrontNotFound(f"{int(mask.sum())} sites of {view.spec!r} switched but no moving front was found")
    first = np.full(view.n_pos, np.nan)
    for i in np.flatnonzero(mask):
        k = np.flatnonzero(s[:, i] >= 0.5)
        if k.size and k[0] > 0:
            j = k[0]
            first[i] = np.interp(0.5, [s[j - 1, i], s[j, i]], view.time[j - 1 : j + 1])
    out = []
    for tr in sorted(tracks, key=lambda tr: tr.time[0]):
        out.append(_measure(view, tr, len(out), first, mask, s, L, h))
    return out


def _measure(view, tr, index, first, mask, s, L, h) -> FrontMeasurement:
    frames, t, pos, _ = tr.arrays()
    direction = 1 if pos[-1] >= pos[0] else -1
    lo, hi = min(pos[0], pos[-1]), max(pos[0], pos[-1])
    sel = np.flatnonzero(mask & np.isfinite(first) & (view.x >= lo - h) & (view.x <= hi + h))
    speed, err = _speed(view.x[sel], first[sel], STEADY_TRIM)
    speed_all, _ = _speed(view.x[sel], first[sel], 0.0)
    moving = np.abs(pos - pos[0]) <= 0.9 * np.abs(pos[-1] - pos[0])  # not yet arrested
    widths = [_width(view.x, s[j], p, h) for j, p, m in zip(frames, pos, moving)
              if m and view.x.min() + 3 * h < p < view.x.max() - 3 * h]
    w = float(np.nanmedian(widths)) if widths and np.isfinite(widths).any() else np.nan
    end_x = view.x.max() if direction > 0 else view.x.min()
    v_end, ci = final_speed(t, pos)
    # stopped: its final speed is statistically zero, or too slow to cross one more site in a
    # time as long as the whole run (a stopped front still relaxing); not at the end of the line
    creep = h / max(float(view.time[-1] - view.time[0]), 1e-300)
    arrested = bool((abs(v_end) <= ci or abs(v_end) < creep) and abs(pos[-1] - end_x) > 3 * h)
    return FrontMeasurement(
        index=index, field=view.spec, direction=direction, jump=float(L), speed_m_s=float(speed),
        speed_stderr_m_s=float(err), speed_whole_path_m_s=float(speed_all), width_10_90_m=w, width_10_90_sites=w / h,
        distance_m=float(abs(pos[-1] - pos[0])), start_m=float(pos[0]), stop_m=float(pos[-1]),
        arrested=arrested, final_speed_m_s=float(abs(v_end)), final_speed_ci_m_s=float(ci),
        n_switched=int(sel.size), sites=view.site[sel], x_m=view.x[sel],
        switch_time_s=first[sel], track_time_s=t, track_pos_m=pos,
    )
