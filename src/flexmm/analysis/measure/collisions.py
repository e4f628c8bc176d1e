"""Collisions between measured pulses: which pulses met, what came out, and how they changed.

Every measured pulse (``pulses.PulseMeasurement``) is cut into *legs*, its stretches between
collisions (the segments of its arrival fit), each a straight line t = s·x + b_k in space-time
with the pulse's slowness s. Two legs of different pulses *collide* when

- their lines cross at (t_c, x_c) with both legs ending before t_c, no further than ``reach``
  (``REACH_FWHM`` widths of the wider pulse) from x_c — i.e. they stopped being measurable
  because they met, not because the run ended — and having approached x_c by at least a width
  (FWHM); pairs of longer legs are taken first;
- they approach each other there (head-on: opposite directions; overtaking: the faster behind),
  were under way at the same time, and meet inside the analysed line before the run ends.

The pulses leaving the collision are the legs that start after t_c − reach/|v| and whose lines,
extended back to t_c, pass within ``reach`` of x_c, and that move at least a width away from it;
two incoming legs with no outgoing one are not counted as a collision. A leg's line, amplitude
and own speed are taken over its steady sites (after a formation transient, ``steady``). Each incoming leg is matched to one outgoing
leg of the same polarity, choosing the pairing whose amplitudes change least (ties: keep the
direction). An incoming pulse whose match keeps its direction *passed through*; one whose match
moves back *was reflected* (repelled); one without a match was *absorbed* (merged, or too weak
to follow). For each incoming pulse:

- space shift Δx = d_out · (x_out(t_c) − x_c): where its outgoing line, extended back to t_c,
  lies relative to the collision point, positive when pushed forward along its outgoing motion
  (for a pulse that passes at unchanged speed this is the usual phase shift); time shift
  Δt = −Δx/|v_out| (a delay is positive);
- amplitude change A_out/A_in − 1 and speed change |v_out|/|v_in| − 1, from the median peaks
  of the two legs and the speeds of lines fitted to each leg alone.

A pulse measured only inside a collision's neighbourhood (the overlapping peak of two pulses,
which can move faster than either) is not a pulse: ``find_collisions`` drops it and counts it.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace
from itertools import combinations, permutations

import numpy as np

REACH_FWHM = 5.0  # a collision's neighbourhood: this many FWHM of the wider pulse
MIN_LEG_SITES = 5  # a stretch of fewer fitted sites (the overlapping peak itself) is not a leg


@dataclass(frozen=True)
class Leg:
    """One stretch of a pulse between collisions: t = slowness · x + intercept."""

    pulse: int
    segment: int
    polarity: int
    direction: int
    speed_m_s: float
    amplitude: float
    fwhm_m: float
    t0: float
    t1: float
    x0: float
    x1: float
    intercept_s: float
    own_speed_m_s: float  # of this leg alone (the pulse's speed is fitted over all its legs)

    def x_at(self, t: float) -> float:
        return (t - self.intercept_s) * self.direction * self.speed_m_s

    @property
    def slowness(self) -> float:
        return self.direction / self.speed_m_s


def legs_of(p) -> list[Leg]:
    """The legs of one PulseMeasurement (one per segment with at least MIN_LEG_SITES fitted sites)."""
    out = []
    fwhm = p.fwhm_m if math.isfinite(p.fwhm_m) else np.nan
    for k in np.unique(p.segment):
        m = p.segment == k
        if m.sum() < MIN_LEG_SITES:
            continue
        x, t, pk = p.x_m[m], p.arrival_time_s[m], p.peak[m]
        slow = p.direction / p.speed_m_s
        order = np.argsort(t)
        st = p.steady[m] if p.steady[m].sum() >= MIN_LEG_SITES else np.ones(x.size, bool)  # past its formation
        out.append(Leg(p.index, int(k), p.polarity, p.direction, p.speed_m_s, float(np.median(pk[st])), fwhm,
                       float(t[order[0]]), float(t[order[-1]]), float(x[order[0]]), float(x[order[-1]]),
                       float(np.median(t[st] - slow * x[st])), float(abs(1.0 / np.polyfit(x[st], t[st], 1)[0]))))
    return out


@dataclass
class Collision:
    """Two incoming pulses, what left the collision, and the change of each incoming pulse.

    Per incoming pulse (a, b): the index of the outgoing pulse it continues as (-1: none),
    outcome ('passed', 'reflected', 'absorbed'), space shift (m), time shift (s), relative
    amplitude and speed changes (NaN without an outgoing pulse).
    """

    index: int
    kind: str  # 'head-on' or 'overtaking'
    time_s: float
    position_m: float
    pulse_a: int
    pulse_b: int
    out_a: int
    out_b: int
    outcome_a: str
    outcome_b: str
    amplitude_a: float
    amplitude_b: float
    shift_a_m: float
    shift_b_m: float
    delay_a_s: float
    delay_b_s: float
    amplitude_change_a: float
    amplitude_change_b: float
    speed_change_a: float
    speed_change_b: float

    def scalars(self) -> dict:
        return asdict(self)

    @property
    def outcome(self) -> str:
        """'passed through', 'reflected', or the two outcomes when they differ."""
        o = {self.outcome_a, self.outcome_b}
        if o == {"passed"}:
            return "passed through"
        if o == {"reflected"}:
            return "reflected"
        return f"{self.outcome_a}/{self.outcome_b}"

    def describe(self) -> str:
        def one(name, pulse, amp, out, outcome, dx, dt, da, dv):
            if out < 0:
                return f"pulse {pulse} ({amp:+.4g}) {outcome}"
            return (f"pulse {pulse} ({amp:+.4g}) {outcome} as pulse {out}: shift {dx * 1e3:+.4g} mm "
                    f"({dt:+.3g} s), amplitude {100 * da:+.2f} %, speed {100 * dv:+.2f} %")

        return (f"collision {self.index} ({self.kind}) at t = {self.time_s:.4g} s, x = {self.position_m:.4g} m: "
                f"{self.outcome}; "
                + one("a", self.pulse_a, self.amplitude_a, self.out_a, self.outcome_a, self.shift_a_m,
                      self.delay_a_s, self.amplitude_change_a, self.speed_change_a)
                + "; "
                + one("b", self.pulse_b, self.amplitude_b, self.out_b, self.outcome_b, self.shift_b_m,
                      self.delay_b_s, self.amplitude_change_b, self.speed_change_b))


def _meeting(a: Leg, b: Leg) -> tuple[float, float] | None:
    """(t_c, x_c) where the lines of two legs cross, or None if parallel."""
    ds = a.slowness - b.slowness
    if abs(ds) < 1e-12 * (abs(a.slowness) + abs(b.slowness)):
        return None
    x = (b.intercept_s - a.intercept_s) / ds
    return a.slowness * x + a.intercept_s, x


def _width(leg: Leg, spacing: float) -> float:
    return leg.fwhm_m if math.isfinite(leg.fwhm_m) else 3 * spacing


def _reach(*legs: Leg, spacing: float) -> float:
    w = [leg.fwhm_m for leg in legs if math.isfinite(leg.fwhm_m)]
    return REACH_FWHM * max(max(w) if w else 3 * spacing, 3 * spacing)


def _incoming(a: Leg, b: Leg, spacing: float, t_end: float, x_range: tuple[float, float]):
    """(t_c, x_c, kind) if legs a, b end by colliding with each other, else None."""
    if a.pulse == b.pulse:
        return None
    hit = _meeting(a, b)
    if hit is None:
        return None
    tc, xc = hit
    r = _reach(a, b, spacing=spacing)
    gap = r / max(a.speed_m_s, b.speed_m_s)
    if tc > t_end or not x_range[0] <= xc <= x_range[1] or max(a.t0, b.t0) > min(a.t1, b.t1) + gap:
        return None  # no meeting inside the run, or the two were never under way together
    for leg in (a, b):
        # ends before the meeting, close to it, having come from at least a width further away
        if leg.t1 > tc + r / leg.speed_m_s or abs(leg.x1 - xc) > r or leg.direction * (xc - leg.x0) <= 0 \
                or abs(leg.x0 - xc) - abs(leg.x1 - xc) < _width(leg, spacing):
            return None
    kind = "head-on" if a.direction != b.direction else "overtaking"
    return tc, xc, kind


def _outgoing(legs: list[Leg], tc: float, xc: float, r: float, exclude: set, spacing: float) -> list[Leg]:
    """Legs that leave the collision at (t_c, x_c): starting soon after it, near it, on lines
    through it, and moving at least a width away from it."""
    out = []
    for leg in legs:
        if (leg.pulse, leg.segment) in exclude:
            continue
        soon = tc - r / leg.speed_m_s <= leg.t0 <= tc + 2 * r / leg.speed_m_s
        away = abs(leg.x1 - xc) - abs(leg.x0 - xc) >= _width(leg, spacing)
        if soon and away and abs(leg.x_at(tc) - xc) <= r and abs(leg.x0 - xc) <= 2 * r:
            out.append(leg)
    return out


def _match(pre: tuple[Leg, Leg], post: list[Leg]) -> tuple[Leg | None, Leg | None]:
    """Outgoing leg of each incoming one: same polarity, least amplitude change, keep direction on ties."""
    best, best_cost = (None, None), math.inf
    cands = post + [None, None]
    for pa, pb in permutations(range(len(cands)), 2):
        ca, cb = cands[pa], cands[pb]
        cost = 0.0
        for inc, o in ((pre[0], ca), (pre[1], cb)):
            if o is None:
                cost += 10.0
                continue
            if o.polarity != inc.polarity:
                cost = math.inf
                break
            cost += abs(math.log(abs(o.amplitude) / abs(inc.amplitude))) + (1e-6 if o.direction != inc.direction else 0)
        if cost < best_cost:
            best, best_cost = (ca, cb), cost
    return best


def _changes(inc: Leg, out: Leg | None, tc: float, xc: float) -> tuple[str, float, float, float, float]:
    if out is None:
        return "absorbed", math.nan, math.nan, math.nan, math.nan
    dx = out.direction * (out.x_at(tc) - xc)
    return ("passed" if out.direction == inc.direction else "reflected", dx, -dx / out.speed_m_s,
            out.amplitude / inc.amplitude - 1.0, out.own_speed_m_s / inc.own_speed_m_s - 1.0)


def find_collisions(pulses: list, spacing_m: float, t_end: float,
                    x_range: tuple[float, float] = (-math.inf, math.inf)) -> tuple[list[Collision], list, int]:
    """Collisions among measured pulses: (collisions, pulses without overlap artefacts, dropped).
    A collision happens before ``t_end`` and inside ``x_range`` (the analysed line).

    Pulses are re-indexed in order after dropping, and the collisions refer to the new indices.
    """
    legs = [leg for p in pulses for leg in legs_of(p)]
    found = []
    for a, b in combinations(legs, 2):
        hit = _incoming(a, b, spacing_m, t_end, x_range)
        if hit is not None:
            found.append((hit[0], a, b, hit[1], hit[2]))
    # the longest legs first: the overlapping peak of two pulses, measured over a few sites near
    # their meeting point, must not take the place of one of them
    found.sort(key=lambda f: -(abs(f[1].x1 - f[1].x0) + abs(f[2].x1 - f[2].x0)))
    used: set = set()
    events = []
    for tc, a, b, xc, kind in found:
        if (a.pulse, a.segment) in used or (b.pulse, b.segment) in used:
            continue
        r = _reach(a, b, spacing=spacing_m)
        post = _outgoing(legs, tc, xc, r, used | {(a.pulse, a.segment), (b.pulse, b.segment)}, spacing_m)
        post = [p for p in post if p.t0 >= min(a.t1, b.t1) - r / p.speed_m_s]
        oa, ob = _match((a, b), post)
        if oa is None and ob is None:  # nothing left the meeting point: no evidence of a collision
            continue
        used |= {(a.pulse, a.segment), (b.pulse, b.segment)}
        events.append((tc, xc, kind, a, b, oa, ob))
    # overlap artefacts: pulses all of whose legs lie inside a collision's neighbourhood
    taking_part = {leg.pulse for e in events for leg in e[3:] if leg is not None}
    drop = set()
    for p in pulses:
        if p.index in taking_part:
            continue
        for tc, xc, _, a, b, _, _ in events:
            r = _reach(a, b, spacing=spacing_m)
            v = max(a.speed_m_s, b.speed_m_s)
            if np.all(np.abs(p.x_m - xc) <= r) and np.all(np.abs(p.arrival_time_s - tc) <= r / v):
                drop.add(p.index)
    keep = [p for p in pulses if p.index not in drop]
    new = {p.index: k for k, p in enumerate(keep)}
    keep = [replace(p, index=new[p.index]) for p in keep]
    out = []
    for k, (tc, xc, kind, a, b, oa, ob) in enumerate(events):
        ca, cb = _changes(a, oa, tc, xc), _changes(b, ob, tc, xc)
        out.append(Collision(
            index=k, kind=kind, time_s=float(tc), position_m=float(xc),
            pulse_a=new[a.pulse], pulse_b=new[b.pulse],
            out_a=new[oa.pulse] if oa is not None else -1, out_b=new[ob.pulse] if ob is not None else -1,
            outcome_a=ca[0], outcome_b=cb[0], amplitude_a=a.amplitude, amplitude_b=b.amplitude,
            shift_a_m=ca[1], shift_b_m=cb[1], delay_a_s=ca[2], delay_b_s=cb[2],
            amplitude_change_a=ca[3], amplitude_change_b=cb[3], speed_change_a=ca[4], speed_change_b=cb[4]))
    return out, keep, len(drop)
