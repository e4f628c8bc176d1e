"""Find localized features in every frame and link them into tracks through time.

Per frame, peaks of ±field above a height threshold (``analysis.features.peaks.find_peaks`` with a prominence
criterion) are located to sub-site accuracy by a parabola through the three samples around the
maximum. Peaks are then linked frame to frame by a greedy nearest-neighbour tracker that predicts
each track's position from its recent velocity, keeps a track alive across a few missing frames
(two pulses merging in a collision) and never links opposite polarities. The linker works on any
list of per-frame positions, so front crossings use it too.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from flexmm.analysis.features.peaks import find_peaks, local_maxima_rows


@dataclass
class Track:
    """A feature followed through time: frame indices, times (s), positions (m), signed heights."""

    polarity: int
    frames: list[int] = field(default_factory=list)
    time: list[float] = field(default_factory=list)
    pos: list[float] = field(default_factory=list)
    height: list[float] = field(default_factory=list)

    def add(self, frame: int, t: float, pos: float, height: float) -> None:
        self.frames.append(frame)
        self.time.append(t)
        self.pos.append(pos)
        self.height.append(height)

    def velocity(self, n_last: int = 8) -> float:
        """Slope of the last ``n_last`` positions against time (0 for a single point)."""
        if len(self.pos) < 2:
            return 0.0
        t, x = self.time[-n_last:], self.pos[-n_last:]  # least-squares line, written out: called per frame and track
        n = len(t)
        tm, xm = sum(t) / n, sum(x) / n
        stt = sum((ti - tm) ** 2 for ti in t)
        return float(sum((ti - tm) * (xi - xm) for ti, xi in zip(t, x)) / stt) if max(t) > min(t) else 0.0

    def predict(self, t: float) -> float:
        return self.pos[-1] + self.velocity() * (t - self.time[-1])

    @property
    def travel(self) -> float:
        """Net distance between first and last position (m)."""
        return abs(self.pos[-1] - self.pos[0]) if self.pos else 0.0

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        return (np.asarray(self.frames), np.asarray(self.time), np.asarray(self.pos),
                np.asarray(self.height))


def refine_peak(y: np.ndarray, k: int) -> tuple[float, float]:
    """Offset (in samples, |off| ≤ ½) and height of the parabola through y[k−1], y[k], y[k+1]."""
    if k <= 0 or k >= y.size - 1:
        return 0.0, float(y[k])
    a, b, c = y[k - 1], y[k], y[k + 1]
    den = a - 2 * b + c
    if not den < 0:
        return 0.0, float(b)
    off = float(np.clip(0.5 * (a - c) / den, -0.5, 0.5))
    return off, float(b - 0.25 * (a - c) * off)


def frame_peaks(profile: np.ndarray, x: np.ndarray, height: float | tuple[float, float],
                maxima: tuple[np.ndarray, np.ndarray] | None = None) -> list[tuple[float, float, int]]:
    """Peaks of +profile and −profile above ``height`` (one level, or (positive, negative)) and
    with a prominence of at least half of it: (position, signed height, index). ``maxima``: the
    local maxima of +profile and −profile, if known."""
    out = []
    levels = (height, height) if np.isscalar(height) else height
    for n, (sign, level) in enumerate(zip((1, -1), levels)):
        if not np.isfinite(level):
            continue
        y = sign * profile
        idx = find_peaks(y, height=level, prominence_min=0.5 * level,
                         maxima=maxima[n] if maxima is not None else None)
        for k in idx:
            off, h = refine_peak(y, int(k))
            out.append((float(np.interp(k + off, np.arange(x.size), x)), sign * h, int(k)))
    return out


def link(time: np.ndarray, detections: list[list[tuple[float, float]]], gate: float,
         max_gap: int = 5) -> list[Track]:
    """Link per-frame detections (position, signed height) into tracks.

    A detection joins the live track of the same polarity whose predicted position is nearest,
    if within ``gate`` (plus the distance predicted from the track's velocity); otherwise it
    starts a new track. Tracks unmatched for more than ``max_gap`` frames are closed.
    """
    live: list[Track] = []
    done: list[Track] = []
    for j, (t, dets) in enumerate(zip(time, detections)):
        pairs = []
        for ti, tr in enumerate(live):
            pred = tr.predict(t)
            for di, (pos, h) in enumerate(dets):
                if np.sign(h) == tr.polarity and abs(pos - pred) <= gate:
                    pairs.append((abs(pos - pred), ti, di))
        used_t, used_d = set(), set()
        for _, ti, di in sorted(pairs):
            if ti in used_t or di in used_d:
                continue
            used_t.add(ti)
            used_d.add(di)
            live[ti].add(j, float(t), *dets[di])
        for di, (pos, h) in enumerate(dets):
            if di not in used_d:
                tr = Track(polarity=int(np.sign(h)))
                tr.add(j, float(t), pos, h)
                live.append(tr)
        keep = []
        for tr in live:
            (keep if j - tr.frames[-1] <= max_gap else done).append(tr)
        live = keep
    return done + live


JOIN_POINTS = 32
NEAR = 1.25  # a piece whose median peak is within this factor of the detection level breathes around it


def _joinable(a: Track, b: Track, gate: float, rel_speed: float, k: int = 8) -> float | None:
    """Mismatch (m) of continuing track ``a`` by track ``b``, or None if they cannot be one
    (velocities over the last and first ``k`` positions)."""
    if a.polarity != b.polarity or b.time[0] <= a.time[-1] or len(a.pos) < 3 or len(b.pos) < 3:
        return None
    va, vb = a.velocity(k), Track(b.polarity, b.frames[:k], b.time[:k], b.pos[:k], b.height[:k]).velocity(k)
    if abs(va - vb) > rel_speed * max(abs(va), abs(vb)) or va * vb <= 0:
        return None
    ha, hb = np.median(np.abs(a.height[-8:])), np.median(np.abs(b.height[:8]))
    if not (1 - rel_speed) * ha <= hb <= ha / (1 - rel_speed):
        return None
    gap = b.time[0] - a.time[-1]
    miss = abs(a.pos[-1] + va * gap - b.pos[0])
    return miss if miss <= gate + rel_speed * abs(va) * gap else None


def merge_tracks(tracks: list[Track], gate: float, rel_speed: float = 0.25,
                 levels: tuple[float, float] | None = None) -> list[Track]:
    """Join tracks interrupted by a collision: same polarity, similar velocity and height (within
    ``rel_speed``, velocities over 8 positions), aligned in space-time, the best aligned first.

    With the detection ``levels`` (positive, negative), pieces of a pulse whose peak breathes
    around its level (median height within NEAR of it, both pieces) are joined apart, after the
    others: such a pulse is seen in short, jittery pieces, so their velocities are judged over
    JOIN_POINTS positions, and each piece is continued by the one that starts first (the best
    aligned would strand the pieces between)."""
    if levels is None:
        return _merge(tracks, gate, rel_speed, 8, lambda mb: mb[0])

    seen: dict = {}  # (id, length) -> (track, near): a track changes only by growing; kept, so ids stay unique

    def near(tr: Track) -> bool:
        key = (id(tr), len(tr.height))
        if key not in seen:
            level = levels[0] if tr.polarity > 0 else levels[1]
            seen[key] = (tr, bool(np.median(np.abs(tr.height)) <= NEAR * level))
        return seen[key][1]

    tracks = _merge(tracks, gate, rel_speed, 8, lambda mb: mb[0], lambda a, b: not (near(a) and near(b)))
    return _merge(tracks, gate, rel_speed, JOIN_POINTS, lambda mb: (mb[1].time[0], mb[0]),
                  lambda a, b: near(a) and near(b))


def _merge(tracks: list[Track], gate: float, rel_speed: float, k: int, order, allowed=None) -> list[Track]:
    """Join joinable tracks (``_joinable`` with velocities over ``k`` positions, and ``allowed``),
    the candidate first in ``order`` each time, until none is left."""
    tracks = sorted(tracks, key=lambda tr: tr.time[0])
    changed = True
    while changed:
        changed = False
        for a in tracks:
            cands = [(m, b) for b in tracks if b is not a and (allowed is None or allowed(a, b))
                     and (m := _joinable(a, b, gate, rel_speed, k)) is not None]
            if cands:
                _, b = min(cands, key=order)
                for args in zip(b.frames, b.time, b.pos, b.height):
                    a.add(*args)
                tracks.remove(b)
                changed = True
                break
    return tracks


def split_reversals(tr: Track, min_retreat: float) -> list[Track]:
    """Split a track where it turns back by more than ``min_retreat`` (m) from its running extreme
    (a pulse repelled in a collision keeps its polarity and is followed as one track): one track
    per monotone leg, cut at the turning point."""
    pos = np.asarray(tr.pos)
    cuts, start, direction, ext = [], 0, 0, 0
    for k in range(1, pos.size):
        if direction == 0:
            if abs(pos[k] - pos[start]) > min_retreat:
                direction = 1 if pos[k] > pos[start] else -1
                ext = start + int(np.argmax(direction * pos[start : k + 1]))
            continue
        if direction * pos[k] > direction * pos[ext]:
            ext = k
        elif direction * (pos[ext] - pos[k]) > min_retreat:
            cuts.append(ext)
            start, direction = ext, -direction
            ext = start + int(np.argmax(direction * pos[start : k + 1]))
    if not cuts:
        return [tr]
    return [Track(tr.polarity, tr.frames[a:b], tr.time[a:b], tr.pos[a:b], tr.height[a:b])
            for a, b in zip([0] + cuts, cuts + [pos.size])]


def auto_gate(values: np.ndarray, x: np.ndarray, min_sites: float = 4.0) -> float:
    """Linking gate (m): twice the median frame-to-frame move of the global maximum, ≥ min_sites."""
    h = float(np.median(np.abs(np.diff(x)))) if x.size > 1 else 1.0
    k = np.argmax(np.abs(values), axis=1)
    step = np.abs(np.diff(k))
    moving = step[step > 0]
    typical = float(np.median(moving)) if moving.size else 0.0
    return h * max(min_sites, min(2.0 * typical, x.size / 4))


def track_peaks(values: np.ndarray, time: np.ndarray, x: np.ndarray, *, threshold: float | tuple[float, float],
                gate: float | None = None, max_gap: int = 5) -> list[Track]:
    """Peaks of every frame of ``values`` (n_time, n_pos) above ``threshold`` (one level, or one
    per polarity), linked into tracks."""
    gate = auto_gate(values, x) if gate is None else gate
    up, down = local_maxima_rows(values), local_maxima_rows(-values)
    dets = [[(p, h) for p, h, _ in frame_peaks(values[j], x, threshold, (up[j], down[j]))]
            for j in range(values.shape[0])]
    levels = (threshold, threshold) if np.isscalar(threshold) else tuple(threshold)
    return merge_tracks(link(time, dets, gate, max_gap), gate, levels=levels)
