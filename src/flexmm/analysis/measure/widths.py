"""Spatial and temporal widths of a tracked pulse.

- FWHM: ``analysis.features.peaks.peak_width`` on the spatial profile, median over up to 25 frames;
- shape widths W (sech, sech², §1.3 profile; see ``profiles``): one least-squares fit of all
  usable frames pooled in the frame moving with the pulse, each frame divided by the fitted
  amplitude at its position — pooling averages noise far better than frame-by-frame fits;
- temporal FWHM: ``peak_width`` on the time traces at the fitted sites.
Usable frames have the pulse at least 2 FWHM inside the fitted stretch of chain and no other
pulse within 6 FWHM.
"""

from __future__ import annotations

import numpy as np

from flexmm.analysis.features.peaks import peak_width
from flexmm.analysis.features.profiles import SHAPES, ProfileFit, fit_profile, fit_profiles, shape_fwhm

POOLED_FRAMES = 200  # frames pooled into the co-moving width fit


def _fwhm_at(y: np.ndarray, k: int) -> float:
    """FWHM in samples of the peak of y nearest to index k (NaN at the ends)."""
    lo = max(k - 1, 0)
    k = lo + int(np.argmax(y[lo : k + 2]))
    if not 0 < k < y.size - 1:
        return np.nan
    return peak_width(y, k)[0]


def fwhm_estimate(view, tr_frames, tr_pos, polarity) -> float:
    """Median spatial FWHM (m) over nine frames of the track (3 sites if none measurable)."""
    w = [_fwhm_at(polarity * view.values[tr_frames[j]], int(np.argmin(np.abs(view.x - tr_pos[j]))))
         for j in np.linspace(0, len(tr_frames) - 1, min(9, len(tr_frames))).astype(int)]
    w = [v for v in w if np.isfinite(v) and v > 0]
    return float(np.median(w)) * view.spacing_m if w else 3 * view.spacing_m


def frames_inside(tr_pos, tr_t, fwhm, lo_x, hi_x, others, n_max=POOLED_FRAMES) -> np.ndarray:
    """Indices into the track of up to n_max frames with the pulse inside [lo_x, hi_x] and alone."""
    ok = (tr_pos - 2 * fwhm >= lo_x) & (tr_pos + 2 * fwhm <= hi_x)
    for ot, op in others:
        ok &= np.abs(np.interp(tr_t, ot, op, left=np.inf, right=np.inf) - tr_pos) > 6 * fwhm
    idx = np.flatnonzero(ok)
    return idx[np.linspace(0, idx.size - 1, min(n_max, idx.size)).astype(int)] if idx.size else idx


def frame_fits(view, tr_frames, tr_pos, tr_h, polarity, fwhm, pick, fit: bool = True) -> tuple[float, list, dict]:
    """Median spatial FWHM (m) at frames ``pick``; with ``fit``, the sech fit of each of them
    (their spread is ``spread``; fitted together, ``fit_profiles``) and every shape's fit of the
    middle one {shape: ProfileFit} (the profile the figures draw): what is reported of per-frame
    fits, and nothing more."""
    fw, xs, ys, guesses = [], [], [], []
    for j in pick:
        y = view.values[tr_frames[j]]
        fw.append(_fwhm_at(polarity * y, int(np.argmin(np.abs(view.x - tr_pos[j])))) * view.spacing_m)
        if fit:
            w = np.abs(view.x - tr_pos[j]) <= 3 * fwhm
            xs.append(view.x[w])
            ys.append(y[w])
            guesses.append((tr_h[j], tr_pos[j], fwhm))
    sech_fits, middle = [], {}
    if fit and xs:
        sech_fits = fit_profiles(xs, ys, "sech", [(h, c, w / shape_fwhm("sech", 1.0)) for h, c, w in guesses])
        mid = len(xs) // 2
        h, c, w = guesses[mid]
        for s in SHAPES:
            middle[s] = (sech_fits[mid] if s == "sech"
                         else fit_profile(xs[mid], ys[mid], s, (h, c, w / shape_fwhm(s, 1.0))))
    fw = [v for v in fw if np.isfinite(v)]
    return (float(np.median(fw)) if fw else np.nan), sech_fits, middle


def pooled_fits(view, tr_frames, tr_t, tr_pos, pick, fwhm, amplitude_at) -> dict[str, ProfileFit]:
    """Shape fits of all frames ``pick`` at once in the co-moving frame.

    Frame j contributes (x − X(t_j), value/a(X(t_j))) for |x − X| ≤ 3 FWHM, with X(t) a cubic
    fit of the tracked positions and a(x) the fitted amplitude along the path.
    """
    tc = tr_t[pick] - tr_t[pick].mean()
    center = np.polyval(np.polyfit(tc, tr_pos[pick], min(3, max(0, pick.size - 2))), tc)
    zs, ys = [], []
    for j, c in zip(pick, center):
        w = np.abs(view.x - c) <= 3 * fwhm
        zs.append(view.x[w] - c)
        ys.append(view.values[tr_frames[j], w] / amplitude_at(c))
    z, y = np.concatenate(zs), np.concatenate(ys)
    return {s: fit_profile(z, y, s, (1.0, 0.0, fwhm / shape_fwhm(s, 1.0))) for s in SHAPES}


def spread(fits: list[ProfileFit]) -> float:
    """Standard deviation of W over successful per-frame fits (NaN if none)."""
    W = [f.W for f in fits if f.ok]
    return float(np.std(W)) if W else np.nan


def temporal_fwhm(view, sites, times, polarity, half_window) -> float:
    """Median FWHM (s) of the time traces at (up to 40 of) the fitted sites."""
    half_window = max(half_window, 4 * float(np.median(np.diff(view.time))))
    widths = []
    for i, t_i in list(zip(sites, times))[:: max(1, sites.size // 40)]:
        win = np.flatnonzero(np.abs(view.time - t_i) <= half_window)
        if win.size < 5:
            continue
        y = polarity * view.values[win, i]
        k = int(np.argmax(y))
        if 0 < k < y.size - 1:
            w, left, right = peak_width(y, k)
            if left > 0 and right < y.size - 1:  # a peak on a slope: its width is not used
                widths.append(w * float(np.median(np.diff(view.time[win]))))
    return float(np.median(widths)) if widths else np.nan
