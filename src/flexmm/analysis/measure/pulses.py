"""Travelling pulses: speed, amplitude, widths, polarity.

``measure_pulses`` detects and tracks every pulse of a field (trains, collisions) and measures
each one (see its docstring; the pieces live in ``detect``, ``arrivals`` and ``widths``).

``leading_pulse`` is a quick single-pulse fit (pilots; ``flexmm run`` prints analyze's
measurement, ``analysis.report.summary``): arrival time at a site = time
of the largest peak of |field(t)| there, refined by a three-point parabola; sites whose largest
peak is below ``threshold_fraction`` of the 90th percentile, or of the minority polarity, are
dropped, and so are outliers of the line fit (> 4 median absolute deviations). Speed = inverse
slope of the least-squares line through (position, arrival time) over the interior sites, with
its standard error. Width = FWHM of |field(x)| at the frame where the pulse is mid-way.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from flexmm.analysis.features.detect import Track, refine_peak, split_reversals, track_peaks
from flexmm.analysis.features.peaks import local_maxima, peak_width
from flexmm.analysis.features.profiles import SHAPES
from flexmm.analysis.measure.arrivals import arrivals, clean, line_fit, segment_fit, segments, speed_groups
from flexmm.analysis.measure.steady import steady_part
from flexmm.analysis.measure.widths import fwhm_estimate, frame_fits, frames_inside, pooled_fits, spread, temporal_fwhm
from flexmm.errors import FlexmmError


class PulseNotFound(FlexmmError):
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
        off, height = refine_peak(y, k)
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
    loc = local_maxima(np.concatenate([[0.0], prof, [0.0]])) - 1
    k = int(loc[np.argmin(np.abs(loc - mid))]) if loc.size else mid
    widths = [peak_width(prof, k)[0]]  # a flat or one-sample profile: width 0, reported as such
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


# ----------------------------------------------------------------------------------------------
# Several pulses: detected frame by frame, tracked, then measured one by one.

POLARITY_LABELS = {
    "angle": {1: "positive rotation", -1: "negative rotation"},
    "strain": {1: "tensile (rarefaction)", -1: "compressive"},
    "length": {1: "positive displacement", -1: "negative displacement"},
}


@dataclass
class PulseMeasurement:
    """One travelling pulse of a field.

    Scalars are SI (amplitude in the field's units); ``sites``, ``x_m``, ``arrival_time_s`` and
    ``peak`` are (n,) arrays over the sites used in the speed fit, ``segment`` the stretch between
    collisions each belongs to, ``steady`` False in the formation transient; ``track_*`` are the tracked
    peak positions per frame; ``profile_*`` one measured spatial profile (for figures).
    ``transient``: the whole pulse is a formation transient, a lobe that dies out or turns into
    another pulse (``analysis.measure.transients``; its formation distance and time are then those of the
    lobe, and it is not compared with theory); ``continues_as``: the pulse that starts where this one
    stops mid-run (-1: none).
    """

    index: int
    field: str
    units: str
    polarity: int
    polarity_label: str
    direction: int
    speed_m_s: float
    speed_stderr_m_s: float
    amplitude: float
    amplitude_spread: float
    amplitude_min: float
    amplitude_max: float
    amplitude_range: float
    breathing: bool
    breathing_period_s: float
    formation_distance_m: float
    formation_time_s: float
    amplitude_first: float
    amplitude_last: float
    attenuation_per_m: float
    attenuation_stderr_per_m: float
    fwhm_m: float
    width_sech_m: float
    width_sech2_m: float
    width_kg_m: float
    kg_b: float
    width_spread_m: float
    temporal_fwhm_s: float
    n_collisions: int
    collision_delay_s: float
    collision_shift_m: float
    n_sites_fitted: int
    first_site: float
    last_site: float
    sites: np.ndarray
    x_m: np.ndarray
    arrival_time_s: np.ndarray
    peak: np.ndarray
    segment: np.ndarray
    steady: np.ndarray
    track_time_s: np.ndarray
    track_pos_m: np.ndarray
    profile_x_m: np.ndarray
    profile_values: np.ndarray
    profile_time_s: float
    profile_fits: dict
    transient: bool = False
    continues_as: int = -1

    def scalars(self) -> dict:
        """The scalar results as a flat dict (JSON/CSV friendly)."""
        return {k: v for k, v in asdict(self).items() if not isinstance(v, (np.ndarray, dict))}


def _trimmed_arrivals(view, tr_t, tr_pos, pol, fwhm, others, edge, min_sites):
    """Arrivals away from the ends, split into segments at collisions, outliers removed."""
    sites, times, peaks, overlap, direction = arrivals(view, tr_t, tr_pos, pol, fwhm, others)
    order = np.argsort(direction * view.x[sites])
    seg = np.empty(sites.size, int)
    seg[order] = segments(overlap[order])
    lo_x, hi_x = view.x.min() + edge, view.x.max() - edge
    keep = np.isfinite(times) & (view.x[sites] >= lo_x) & (view.x[sites] <= hi_x)
    counts = {k: int(np.sum(seg[keep] == k)) for k in np.unique(seg[keep])}
    keep &= np.array([counts.get(k, 0) >= 3 for k in seg], bool)
    sites, times, peaks, seg = sites[keep], times[keep], peaks[keep], seg[keep]
    if sites.size >= min_sites:
        # the formation transient arrives off the steady line: kept (it is measured as such), not
        # taken for outliers of the steady fit
        d = direction * view.x[sites]
        order = np.argsort(d)
        steady = np.zeros(sites.size, bool)
        steady[order[steady_part(d[order] - d.min(), times[order], peaks[order]).start:]] = True
        good = ~steady
        if steady.sum() >= min_sites:
            good[steady] = clean(view.x[sites][steady], times[steady], seg[steady])
        else:
            good = clean(view.x[sites], times, seg)
        sites, times, peaks, seg = sites[good], times[good], peaks[good], seg[good]
    return sites, times, peaks, seg, direction, (lo_x, hi_x)


def _measure_group(view, index, pol, direction, fwhm, bounds, others, track, arr) -> PulseMeasurement:
    """One pulse from its track (frames, t, pos, h) and clean arrivals (sites, times, peaks, seg)."""
    frames, t, pos, h = track
    sites, times, peaks, seg = arr
    x = view.x[sites]
    att, att0, att_err = line_fit(direction * x, np.log(np.abs(peaks)))
    order = np.argsort(direction * x)
    st = steady_part(direction * x[order] - (direction * x).min(), times[order], peaks[order])
    steady = np.zeros(x.size, bool)
    steady[order[st.start:]] = True
    if steady.sum() < 5:  # too short a steady part to fit: use the whole path
        steady[:] = True
    slowness, s_err, intercepts, _ = segment_fit(x[steady], times[steady], seg[steady])
    speed = 1.0 / slowness
    delay = float(intercepts[-1] - intercepts[0])
    pick = frames_inside(pos, t, fwhm, *bounds, others)
    sub = pick[:: max(1, pick.size // 25)]
    fw, sech_fits, middle_fits = frame_fits(view, frames, pos, h, pol, fwhm, sub) if sub.size else (np.nan, [], {})
    if not np.isfinite(fw):  # a short run: no frame well inside the fitted stretch; any frame whose
        # half-maximum lies inside the chain
        whole = np.flatnonzero((pos - fwhm >= view.x.min()) & (pos + fwhm <= view.x.max()))
        whole = whole[:: max(1, whole.size // 25)]
        fw = frame_fits(view, frames, pos, h, pol, fwhm, whole, fit=False)[0] if whole.size else np.nan
    W = {s: (np.nan, np.nan) for s in SHAPES}
    if pick.size:
        pooled = pooled_fits(view, frames, t, pos, pick, fwhm, lambda xc: pol * np.exp(att0 + att * direction * xc))
        W = {s: (f.W, f.b) for s, f in pooled.items()}
    t_fwhm = temporal_fwhm(view, sites, times, pol, 3 * fwhm * abs(slowness))
    # a pulse that crosses a site in fewer than 3 frames is sampled too coarsely in time for its
    # peak to be followed: its apparent amplitude variation is not breathing
    breathing = st.breathing and t_fwhm >= 3 * float(np.median(np.diff(view.time)))
    mid = sub[sub.size // 2] if sub.size else len(frames) // 2
    prof = np.abs(view.x - pos[mid]) <= 4 * fwhm
    kind = view.kind if view.kind in POLARITY_LABELS else "length"
    return PulseMeasurement(
        index=index, field=view.spec, units=view.units, polarity=pol,
        polarity_label=POLARITY_LABELS[kind][pol], direction=int(np.sign(speed)),
        speed_m_s=float(abs(speed)), speed_stderr_m_s=float(s_err * speed**2),
        amplitude=float(np.median(peaks[steady])), amplitude_spread=float(np.std(peaks[steady])),
        amplitude_min=st.amplitude_min, amplitude_max=st.amplitude_max,
        amplitude_range=float(abs(st.amplitude_max - st.amplitude_min)), breathing=breathing,
        breathing_period_s=st.breathing_period_s if breathing else np.nan, formation_distance_m=st.formation_distance_m,
        formation_time_s=st.formation_time_s,
        amplitude_first=float(peaks[np.argmin(direction * x)]),
        amplitude_last=float(peaks[np.argmax(direction * x)]),
        attenuation_per_m=float(-att), attenuation_stderr_per_m=float(att_err),
        fwhm_m=fw, width_sech_m=W["sech"][0], width_sech2_m=W["sech2"][0], width_kg_m=W["kg"][0],
        kg_b=W["kg"][1], width_spread_m=spread(sech_fits),
        temporal_fwhm_s=t_fwhm,
        n_collisions=int(intercepts.size - 1), collision_delay_s=delay,
        collision_shift_m=float(-delay * abs(speed)),
        n_sites_fitted=int(sites.size), first_site=float(view.site[sites].min()),
        last_site=float(view.site[sites].max()), sites=view.site[sites], x_m=x,
        arrival_time_s=times, peak=peaks, segment=seg, steady=steady, track_time_s=t, track_pos_m=pos,
        profile_x_m=view.x[prof], profile_values=view.values[frames[mid], prof],
        profile_time_s=float(view.time[frames[mid]]),
        profile_fits=middle_fits,
    )


def measure_track(view, tr: Track, index: int, others: list, *, edge_sites: float | None = None,
                  min_sites: int = 5) -> list[PulseMeasurement]:
    """Measure one tracked feature: one pulse, or several if its speed changes at a collision."""
    frames, t, pos, h = tr.arrays()
    fwhm = fwhm_estimate(view, frames, pos, tr.polarity)
    edge = (max(2.0, fwhm / view.spacing_m) if edge_sites is None else edge_sites) * view.spacing_m
    sites, times, peaks, seg, direction, bounds = _trimmed_arrivals(
        view, t, pos, tr.polarity, fwhm, others, edge, min_sites)
    if sites.size < min_sites:
        return []
    out = []
    for group in speed_groups(view.x[sites], times, seg, min_sites):
        m = np.isin(seg, group)
        if m.sum() < min_sites:
            continue
        pad = 2 * fwhm * abs(np.polyfit(view.x[sites][m], times[m], 1)[0])  # 2 FWHM in time
        f = (t >= times[m].min() - pad) & (t <= times[m].max() + pad)
        if not f.any():  # the arrivals do not overlap the tracked frames: not this track's pulse
            continue
        out.append(_measure_group(view, index + len(out), tr.polarity, direction, fwhm, bounds, others,
                                  (frames[f], t[f], pos[f], h[f]), (sites[m], times[m], peaks[m], seg[m])))
    return out


NOISE_FACTOR = 6.0


def noise_level(values: np.ndarray) -> float:
    """Robust noise estimate of a field: 1.4826 × the median absolute deviation of all samples
    (a localized pulse occupies few samples, so it hardly moves the median)."""
    v = values[np.isfinite(values)]
    return float(1.4826 * np.median(np.abs(v - np.median(v)))) if v.size else 0.0


def _thresholds(vals: np.ndarray, fraction: float, floor: float, per_sign: bool) -> tuple[float, float]:
    """Detection levels for (positive, negative) peaks; inf switches a polarity off.

    Global: ``fraction`` of the largest |value|, for both signs. Per sign: ``fraction`` of the
    largest value of that sign. Never below ``floor`` (the noise level times NOISE_FACTOR).
    """
    peaks = (float(np.nanmax(vals)), float(-np.nanmin(vals)))
    top = max(peaks)
    return tuple(max(fraction * (p if per_sign else top), floor) if p > floor else np.inf for p in peaks)


def _track(view, thr, gate, min_travel_sites, max_pulses):
    tracks = track_peaks(view.values, view.time, view.x, threshold=thr, gate=gate)
    tracks = [leg for tr in tracks for leg in split_reversals(tr, min_travel_sites * view.spacing_m)]
    tracks = [tr for tr in tracks if len(tr.frames) >= 5 and tr.travel >= min_travel_sites * view.spacing_m]
    tracks.sort(key=lambda tr: (tr.time[0], tr.pos[0]))
    tracks = tracks[:max_pulses]
    out = []
    for tr in tracks:
        others = [(np.asarray(o.time), np.asarray(o.pos)) for o in tracks if o is not tr]
        out.extend(measure_track(view, tr, len(out), others))
    return tracks, out


def measure_pulses(view, *, threshold_fraction: float = 0.25, min_travel_sites: float = 5.0,
                   gate_sites: float | None = None, max_pulses: int = 20) -> list[PulseMeasurement]:
    """Detect, track and measure every travelling pulse of a FieldView; PulseNotFound if none.

    Per pulse (``PulseMeasurement``): arrival time at each crossed site (time of the peak of
    the site's trace, least-squares parabola through its top samples); speed = inverse slope
    of the line through (x, arrival time) with its standard error, after dropping sites within
    max(2, FWHM) sites of the ends, sites where a colliding pulse is near, and outliers
    (> 4 MAD); across a collision the line keeps its slope but gets a new intercept, whose
    change is the collision delay (phase shift, ``collision_shift_m`` > 0: pushed forward),
    and a speed change of more than 2 % starts a new pulse; the sites of the formation transient
    are left out of the speed and amplitude (``steady``: formation distance and time, amplitude
    range, breathing and its period); amplitude = median signed peak of the steady part, its
    first and last values and the attenuation rate α of |peak| ∝ exp(−α · distance); spatial
    FWHM (``peaks.peak_width``) and fits of sech, sech² and the §1.3 profile; temporal FWHM; polarity
    (see ``arrivals`` and ``widths``).

    Peaks above ``threshold_fraction`` of the largest |value| and above NOISE_FACTOR times the
    noise level (``noise_level``) are tracked; if none of them travels, each sign is tried
    against its own largest value (a compressive pulse next to much larger opening gaps, say).
    Tracks that move less than ``min_travel_sites`` are dropped (standing features). Pulses are
    returned in order of first appearance.
    """
    vals = view.values
    peak = float(np.nanmax(np.abs(vals))) if vals.size else 0.0
    if not np.isfinite(peak) or peak == 0:
        raise PulseNotFound(f"field {view.spec!r} is identically zero or not finite")
    noise = noise_level(vals)
    floor = NOISE_FACTOR * noise
    if peak <= floor:
        raise PulseNotFound(f"no pulse in {view.spec!r}: peak |{view.spec}| = {peak:.3g} {view.units} is "
                            f"within {NOISE_FACTOR:g}x the noise level {noise:.3g}")
    gate = None if gate_sites is None else gate_sites * view.spacing_m
    for per_sign in (False, True):
        thr = _thresholds(vals, threshold_fraction, floor, per_sign)
        tracks, out = _track(view, thr, gate, min_travel_sites, max_pulses)
        if out:
            break
    if not out:
        raise PulseNotFound(
            f"no travelling pulse in {view.spec!r}: {len(tracks)} candidate track(s) above "
            f"{threshold_fraction:.0%} of the peak of either sign (largest |{view.spec}| = {peak:.3g} "
            f"{view.units}), none crossing {min_travel_sites:g}+ sites with a consistent arrival"
        )
    return out
