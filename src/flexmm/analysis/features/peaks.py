"""Peaks of a sampled signal: local maxima, prominence, width at a fraction of it, smoothing.

What the pulse analysis needs of peak finding, in numpy (importing ``scipy.signal`` costs more
than a whole small run's analysis). The definitions are the usual ones (those of
``scipy.signal.find_peaks``/``peak_prominences``/``peak_widths``/``savgol_filter``, which the
tests compare against):

- a local maximum is a sample higher than its left neighbour and than the first different
  sample on its right; a flat top counts once, at its middle (the left one of two middles);
  the first and last samples are never maxima;
- the prominence of a peak is its height above the higher of the two lowest points reached
  before the signal rises above the peak on either side (or the signal ends);
- the width at ``rel_height`` is measured at ``x[k] - rel_height * prominence`` between the
  first crossings on either side (within the bases), linearly interpolated between samples;
- ``smooth_cubic7``: the Savitzky–Golay smoothing of degree 3 over 7 samples, the end samples
  taken from the cubic fitted to the first (last) seven.
"""

from __future__ import annotations

import numpy as np


def local_maxima(x: np.ndarray) -> np.ndarray:
    """Indices of the local maxima of ``x`` (flat tops at their middle, ends excluded)."""
    x = np.asarray(x, float)
    if x.size < 3:
        return np.zeros(0, np.intp)
    change = np.flatnonzero(np.diff(x) != 0)  # sample i differs from sample i + 1
    if change.size < 2:
        return np.zeros(0, np.intp)
    # runs of equal values: [change[j] + 1, change[j + 1]] for consecutive changes
    start, end = change[:-1] + 1, change[1:]
    up = x[start] > x[start - 1]
    down = x[end + 1] < x[end]
    keep = up & down
    return ((start[keep] + end[keep]) // 2).astype(np.intp)


def prominence(x: np.ndarray, k: int) -> tuple[float, int, int]:
    """(prominence, left base, right base) of the peak at index ``k`` of ``x``."""
    top = x[k]
    higher = np.flatnonzero(x[:k] > top)  # the walk to either side stops before a higher sample
    lo = int(higher[-1]) + 1 if higher.size else 0
    higher = np.flatnonzero(x[k + 1 :] > top)
    hi = k + int(higher[0]) if higher.size else x.size - 1
    # the lowest sample on each side, the one nearest the peak on ties
    left = k - int(np.argmin(x[lo : k + 1][::-1]))
    right = k + int(np.argmin(x[k : hi + 1]))
    return float(top - max(x[left], x[right])), left, right


def local_maxima_rows(values: np.ndarray) -> list[np.ndarray]:
    """``local_maxima`` of every row of a 2D array, at once where no two neighbours are equal."""
    v = np.asarray(values, float)
    if v.shape[1] < 3:
        return [np.zeros(0, np.intp) for _ in range(v.shape[0])]
    strict = (v[:, 1:-1] > v[:, :-2]) & (v[:, 1:-1] > v[:, 2:])
    flat = np.any(v[:, 1:] == v[:, :-1], axis=1)  # a flat top: the row's own search
    rows, cols = np.nonzero(strict)
    split = np.searchsorted(rows, np.arange(1, v.shape[0]))
    out = np.split((cols + 1).astype(np.intp), split)
    for j in np.flatnonzero(flat):
        out[j] = local_maxima(v[j])
    return out


def find_peaks(x: np.ndarray, height: float | None = None, prominence_min: float | None = None,
               maxima: np.ndarray | None = None) -> np.ndarray:
    """Local maxima at least ``height`` high and at least ``prominence_min`` prominent
    (``maxima``: ``local_maxima(x)``, if known)."""
    x = np.asarray(x, float)
    idx = local_maxima(x) if maxima is None else maxima
    if height is not None:
        idx = idx[x[idx] >= height]
    if prominence_min is not None and idx.size:
        idx = idx[np.array([prominence(x, int(k))[0] >= prominence_min for k in idx], bool)]
    return idx


def peak_width(x: np.ndarray, k: int, rel_height: float = 0.5) -> tuple[float, float, float]:
    """(width, left, right) of the peak at index ``k`` at ``rel_height`` of its prominence, in
    samples (left and right interpolated crossing positions)."""
    x = np.asarray(x, float)
    prom, lb, rb = prominence(x, k)
    h = x[k] - prom * rel_height
    i = k
    while lb < i and h < x[i]:
        i -= 1
    left = float(i)
    if x[i] < h:
        left += (h - x[i]) / (x[i + 1] - x[i])
    i = k
    while i < rb and h < x[i]:
        i += 1
    right = float(i)
    if x[i] < h:
        right -= (h - x[i]) / (x[i - 1] - x[i])
    return right - left, left, right


def _cubic7_hat() -> np.ndarray:
    """The 7 × 7 least-squares projection onto cubics over 7 equally spaced samples."""
    z = np.arange(7.0) - 3.0
    V = np.vander(z, 4)
    return V @ np.linalg.solve(V.T @ V, V.T)


_HAT7 = _cubic7_hat()


def smooth_cubic7(a: np.ndarray) -> np.ndarray:
    """Savitzky–Golay smoothing of ``a`` (at least 7 samples): degree 3, window 7."""
    a = np.asarray(a, float)
    if a.size < 7:
        raise ValueError("smooth_cubic7 needs at least 7 samples")
    out = np.empty_like(a)
    w = _HAT7[3]
    out[3:-3] = np.convolve(a, w[::-1], mode="valid")
    out[:3] = _HAT7[:3] @ a[:7]
    out[-3:] = _HAT7[4:] @ a[-7:]
    return out
