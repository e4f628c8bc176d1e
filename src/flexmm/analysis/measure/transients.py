"""Formation transients: pulses that form and die out, told apart from the pulses that persist.

An impact often first makes a short lobe (of either polarity) that travels a few widths, fades
and hands over to the steady pulse. Measured alone, such a lobe looks like a pulse, but it is not
a solitary wave and must not be compared with a steady-pulse law. A measured pulse is a
*transient* when its tracked peak

- travels at most ``SHORT_FWHM`` widths (FWHM) — a pulse that runs far and then radiates away
  (a discrete soliton faster than the rotational waves) is a decaying pulse, measured as one
  (its attenuation), not a formation lobe;
- stops before the run ends (more than ``reach``/|v| before the last frame, ``reach`` = 2 FWHM,
  at least 3 spacings) and away from the ends of the analysed line (farther than ``reach``), and
- does not end by colliding (it is not an incoming pulse of a collision), and
- does not live on below the detection threshold: when the field is given, the largest value of
  its polarity within ``reach`` of the line it was travelling on stays below ``PERSISTS`` of its
  amplitude in the frames after its track ends (a pulse breathing around the threshold is
  followed in pieces, and its last piece ends before the pulse does), and
- is not continued by a pulse of the same polarity and direction, and a speed within
  ``SAME_SPEED``, that starts where it stops (the same pulse, cut in two at a change of speed or
  a gap of the tracker) — unless that one is a transient itself.

A transient is reported with its formation distance (the distance its peak travelled) and
formation time (how long it lived), and with the pulse that starts where it stops, if any
(``continues_as``: the pulse it turns into or merges with). It takes no part in theory
comparisons or in the run's headline (``analysis.report.summary``).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

REACH_FWHM = 2.0
SHORT_FWHM = 10.0  # a lobe travels at most this many FWHM (a soliton that radiates away is not one)
SAME_SPEED = 0.25  # pieces of one pulse: speeds within 25 % (a fast precursor is another pulse)
PERSISTS = 0.5  # a pulse still at half its amplitude on its line after its track ends did not die


def _reach(p, spacing_m: float) -> float:
    w = p.fwhm_m if math.isfinite(p.fwhm_m) else 0.0
    return max(REACH_FWHM * w, 3.0 * spacing_m)


def _successor(p, pulses, spacing_m: float) -> int:
    """Index of the pulse that starts where ``p`` stops (within reach in space and time), or -1."""
    t1, x1 = float(p.track_time_s[-1]), float(p.track_pos_m[-1])
    r = _reach(p, spacing_m)
    tau = r / p.speed_m_s
    best, best_d = -1, math.inf
    for q in pulses:
        if q.index == p.index:
            continue
        t0, x0 = float(q.track_time_s[0]), float(q.track_pos_m[0])
        if abs(t0 - t1) <= tau and abs(x0 - x1) <= 2 * r:
            d = abs(x0 - x1) / r + abs(t0 - t1) / tau
            if d < best_d:
                best, best_d = q.index, d
    return best


def _persists(p, view, reach: float) -> bool:
    """Whether pulse ``p`` goes on along its line after its track ends (the median, over the
    frames within 2 reach of travel after the end, of the largest polarity-signed value within
    ``reach`` of the extrapolated peak is at least PERSISTS · |amplitude|)."""
    t1, x1 = float(p.track_time_s[-1]), float(p.track_pos_m[-1])
    v = p.direction * p.speed_m_s
    later = np.flatnonzero((view.time > t1) & (view.time <= t1 + 2 * reach / p.speed_m_s))
    seen = []
    for j in later:
        near = np.abs(view.x - (x1 + v * (view.time[j] - t1))) <= reach
        if near.any():
            seen.append(float(np.max(p.polarity * view.values[j, near])))
    return bool(seen) and float(np.median(seen)) >= PERSISTS * abs(p.amplitude)


def mark_transients(pulses: list, collisions: list, spacing_m: float, t_end: float,
                    x_range: tuple[float, float], view=None) -> list:
    """The pulses with ``transient``, ``continues_as``, and, for transients, the formation
    distance and time of the lobe (see the module docstring; ``view``: the analysed FieldView,
    for the check that a pulse does not live on below the threshold)."""
    colliding = {k for c in collisions for k in (c.pulse_a, c.pulse_b)}
    by_index = {p.index: p for p in pulses}
    successor = {p.index: _successor(p, pulses, spacing_m) for p in pulses}
    ends = {}
    for p in pulses:
        r = _reach(p, spacing_m)
        t1, x1 = float(p.track_time_s[-1]), float(p.track_pos_m[-1])
        w = p.fwhm_m if math.isfinite(p.fwhm_m) else 3.0 * spacing_m
        short = abs(x1 - float(p.track_pos_m[0])) <= SHORT_FWHM * w
        ends[p.index] = (short and t1 < t_end - r / p.speed_m_s and x_range[0] + r < x1 < x_range[1] - r
                         and p.index not in colliding and (view is None or not _persists(p, view, r)))
    transient: dict[int, bool] = {}
    # latest first, so a piece continued by a transient piece is known to be one too
    for p in sorted(pulses, key=lambda q: -float(q.track_time_s[-1])):
        k = successor[p.index]
        q = by_index.get(k)
        same = q is not None and q.polarity == p.polarity and q.direction == p.direction \
            and abs(q.speed_m_s / p.speed_m_s - 1) <= SAME_SPEED
        transient[p.index] = ends[p.index] and (not same or transient.get(k, False))
    out = []
    for p in pulses:
        if transient[p.index]:
            pos, t = np.asarray(p.track_pos_m, float), np.asarray(p.track_time_s, float)
            p = replace(p, transient=True, formation_distance_m=float(abs(pos[-1] - pos[0])),
                        formation_time_s=float(t[-1] - t[0]))
        out.append(replace(p, continues_as=successor[p.index] if ends[p.index] else -1))
    return out
