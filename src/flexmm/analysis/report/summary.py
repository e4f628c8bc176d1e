"""The headline of a run: which measured feature the scene is about, as a few printable lines.

``principal(res)`` picks, from a ``RunAnalysis``, the feature the scene is about, the same way
for ``flexmm run``, ``flexmm analyze`` and sweeps:

- pulses: the largest |amplitude| among the persistent pulses (formation transients,
  ``analysis.measure.transients``, only when nothing else was measured) fitted over at least
  ``MIN_TRACK_SITES`` sites (all of them if none is), so a small fast precursor never hides the
  soliton behind it;
- fronts: the front that switched the most sites;
- oblique plane waves: the fastest group; driven runs: the steady response.

``summary_lines(res)`` turns it into text with the theory's prediction where one applies, plus
one line per other persistent pulse (speed and amplitude), one per formation transient (distance
and time; no theory) and per collision (``analysis.measure.collisions``).
"""

from __future__ import annotations

import math

MIN_TRACK_SITES = 10


def principal(res):
    """(item label, measurement) of the feature the run is about, or None if nothing was measured."""
    if res.kind == "pulse" and res.pulses:
        persistent = [p for p in res.pulses if not getattr(p, "transient", False)] or res.pulses
        long = [p for p in persistent if p.n_sites_fitted >= MIN_TRACK_SITES] or persistent
        p = max(long, key=lambda q: (abs(q.amplitude), q.n_sites_fitted))
        return f"pulse {p.index}", p
    if res.kind == "front" and res.fronts:
        f = max(res.fronts, key=lambda q: (q.n_switched, q.distance_m))
        return f"front {f.index}", f
    if res.kind == "modes" and res.groups:
        return "group 1", res.groups[0]
    if res.kind == "driven" and res.driven is not None:
        return "driven", res.driven
    return None


def _num(x, digits: int = 4) -> str:
    return "—" if x is None or not math.isfinite(x) else f"{x:.{digits}g}"


def _theory(res, item: str, quantity: str, scale: float = 1.0) -> str:
    """' (theory P, +d %)' for a compared quantity (P times ``scale``, the printed unit), '' without
    a prediction."""
    for c in res.comparisons:
        if c.item == item and c.quantity == quantity and c.predicted is not None and math.isfinite(c.predicted):
            rel = c.rel_diff
            return f" (theory {_num(c.predicted * scale)}" + (f", {100 * rel:+.2f} %)" if rel is not None else ")")
    return ""


WIDTHS = (("width W (sech fit)", "width_sech_m"), ("width W (sech² fit)", "width_sech2_m"),
          ("width W (§1.3 fit)", "width_kg_m"), ("FWHM", "fwhm_m"))


def _width(res, item: str, p) -> tuple[str, float]:
    """The width the theory predicts (if any), else the sech fit, else the FWHM: (name, m)."""
    predicted = {c.quantity for c in res.comparisons if c.item == item and c.predicted is not None}
    finite = [(q, getattr(p, a)) for q, a in WIDTHS if math.isfinite(getattr(p, a))]
    for q, w in finite:
        if q in predicted:
            return q, w
    return finite[0] if finite else ("FWHM", math.nan)


def _pulse_lines(res, item, p) -> list[str]:
    h = res.view.spacing_m
    n = len(res.pulses)
    which = f"{item} of {n}" if n > 1 else item
    wname, width = _width(res, item, p)
    units = "" if p.units == "1" else f" {p.units}"
    lines = [
        f"{which} in {p.field} ({p.polarity_label}, moving {'right' if p.direction > 0 else 'left'}): "
        f"speed {_num(p.speed_m_s, 5)} ± {_num(p.speed_stderr_m_s, 2)} m/s{_theory(res, item, 'speed')}, "
        f"amplitude {_num(p.amplitude)}{units}{_theory(res, item, 'amplitude')}, "
        f"{wname} {_num(width * 1e3)} mm ({_num(width / h, 3)} sites){_theory(res, item, wname, 1e3)}, "
        f"fitted over sites {p.first_site:g}-{p.last_site:g}"
    ]
    form = getattr(p, "formation_distance_m", math.nan)
    if math.isfinite(form) and form > 0:
        lines.append(f"  formation: steady after {_num(form)} m ({_num(form / h, 3)} sites), "
                     f"{_num(p.formation_time_s)} s")
    rng = getattr(p, "amplitude_range", math.nan)
    if getattr(p, "breathing", False):
        period = getattr(p, "breathing_period_s", math.nan)
        lines.append(f"  breathing: amplitude {_num(p.amplitude_min)} to {_num(p.amplitude_max)} {p.units} "
                     f"(range {_num(rng)}), period {_num(period)} s")
    return lines


def _other_line(res, p) -> str:
    """One line for a persistent pulse that is not the headline (a reflection, a second soliton)."""
    item, units = f"pulse {p.index}", "" if p.units == "1" else f" {p.units}"
    return (f"  also pulse {p.index} ({p.polarity_label}, moving {'right' if p.direction > 0 else 'left'}): speed "
            f"{_num(p.speed_m_s, 5)} m/s{_theory(res, item, 'speed')}, amplitude {_num(p.amplitude)}{units}, "
            f"sites {p.first_site:g}-{p.last_site:g}")


def _transient_line(res, p) -> str:
    h = res.view.spacing_m
    then = f"turns into pulse {p.continues_as}" if p.continues_as >= 0 else "dies out"
    return (f"  formation transient pulse {p.index} ({p.polarity_label}, amplitude {_num(p.amplitude)} {p.units}): "
            f"travels {_num(p.formation_distance_m)} m ({_num(p.formation_distance_m / h, 3)} sites) in "
            f"{_num(p.formation_time_s)} s, then {then}; not a steady pulse (no theory)")


def _front_lines(res, item, f) -> list[str]:
    n = len(res.fronts)
    which = f"{item} of {n}" if n > 1 else item
    state = "arrested" if f.arrested else "moving"
    return [
        f"{which} in {f.field} ({'right' if f.direction > 0 else 'left'}-moving, {state}): "
        f"speed {_num(f.speed_m_s, 5)} ± {_num(f.speed_stderr_m_s, 2)} m/s{_theory(res, item, 'speed')}, "
        f"width 10–90 % {_num(f.width_10_90_m * 1e3)} mm ({_num(f.width_10_90_sites, 3)} sites)"
        f"{_theory(res, item, 'width 10–90 %', 1e3)}, {f.n_switched} sites switched over {_num(f.distance_m)} m"
    ]


def summary_lines(res) -> list[str]:
    """The run's headline: the principal feature with theory, collisions, and how many others."""
    pick = principal(res)
    if pick is None:
        return [f"nothing measured ({res.kind} analysis of {res.view.spec})"]
    item, m = pick
    if res.kind == "pulse":
        lines = _pulse_lines(res, item, m)
    elif res.kind == "front":
        lines = _front_lines(res, item, m)
    elif res.kind == "modes":
        lines = [f"{len(res.groups)} wave group(s); fastest: speed {_num(m.speed_m_s)} m/s "
                 f"({_num(m.speed_c0)} c0), polarisation {_num(m.polarisation_deg, 3)}°, "
                 f"{_num(100 * m.energy_fraction, 3)} % of the energy"]
    else:
        far = (f"at far end {_num(m.amplitude_far)} {m.units}, transmission {_num(m.transmission)}"
               if getattr(m, "far_reached", True) else
               f"steady over {m.reached_sites} sites from the drive; the far end is not reached within the "
               "run (no transmission)")
        lines = [f"driven at {_num(m.frequency_hz)} Hz in {m.field}: amplitude at drive "
                 f"{_num(m.amplitude_drive)} {m.units}, {far}, decay {_num(m.decay_per_site)} per site"
                 f"{_theory(res, 'driven', 'decay per site')}"]
    if res.kind == "pulse":
        lines += [_other_line(res, p) for p in res.pulses if not getattr(p, "transient", False) and p is not m]
        lines += [_transient_line(res, p) for p in res.pulses if getattr(p, "transient", False) and p is not m]
    for c in getattr(res, "collisions", []) or []:
        theory = [f"pulse {pulse} {_num(r.predicted * 1e3)} mm ({100 * r.rel_diff:+.2f} %)"
                  for pulse in (c.pulse_a, c.pulse_b) for r in res.comparisons
                  if r.item == f"collision {c.index}" and r.quantity == f"space shift of pulse {pulse}"
                  and r.predicted is not None and r.rel_diff is not None]
        lines.append("  " + c.describe() + (f"; theory shifts: {', '.join(theory)}" if theory else ""))
    return lines
