"""Per-point observables of a sweep, from the public extraction of ``flexmm.analysis``.

What is measured follows ``flexmm.analysis.report.analyze.choose_kind`` (travelling pulse, transition
front or driven response) unless the sweep spec's ``analysis: {kind: ...}`` says otherwise:

- ``analyze_run`` on the field analyze uses (θ, else the strain of u), and of what it measures
  the feature ``flexmm run`` prints (``analysis.report.summary.principal``: the largest |amplitude|
  among pulses fitted over ≥ 10 sites, the front that switched most sites, the fastest group of
  an oblique plane wave, the driven response);
- theory: the model's ``speed_curve`` at the measured amplitude (pulses), or the analysis'
  predicted speed (fronts), from the model's theory (``analysis.report.theory_comparison.theory_for``).

Options: the sweep spec's ``analysis:`` block, a ``flexmm.config.analysis.AnalysisOptions``
(``kind``, ``field``, ``row``, ``threshold_fraction``, ``jump``), the options of ``flexmm analyze``.
"""

from __future__ import annotations

import math
from pathlib import Path

# name: (units or None for the field's units, long_name); NaN where not measured
OBSERVABLES = {
    "speed": ("m/s", "speed of the measured pulse or front"),
    "speed_stderr": ("m/s", "standard error of the speed"),
    "amplitude": (None, "signed amplitude (pulse peak, front jump, far-end drive amplitude)"),
    "width": ("m", "width: FWHM of a pulse, 10-90 % width of a front"),
    "n_sites_fitted": ("1", "sites used in the speed fit (switched sites for a front)"),
    "speed_theory": ("m/s", "theory: speed at the measured amplitude"),
    "transmission": ("1", "driven: far-end over drive amplitude"),
    "formation_distance": ("m", "pulse: distance travelled before its amplitude is steady"),
    "amplitude_min": (None, "pulse: smallest |peak| of the steady part (signed), the breathing range"),
    "amplitude_max": (None, "pulse: largest |peak| of the steady part (signed)"),
    "breathing_period": ("s", "pulse: period of its amplitude oscillation (NaN: not breathing)"),
    "n_collisions": ("1", "pulse collisions found (analysis.measure.collisions)"),
    "collision_shift": ("m", "first collision: space shift of its first incoming pulse"),
    "collision_delay": ("s", "first collision: time shift (delay) of its first incoming pulse"),
    "collision_amplitude_change": ("1", "first collision: relative amplitude change of its first incoming pulse"),
    "collision_speed_change": ("1", "first collision: relative speed change of its first incoming pulse"),
    "collision_passed": ("1", "first collision: 1 if both pulses passed through, 0 if reflected, else NaN"),
}


def _nan_result(kind: str, field: str, units: str, note: str) -> dict:
    return {**{k: math.nan for k in OBSERVABLES}, "kind": kind, "field": field,
            "amplitude_units": units, "note": note}


def observe_run(path, options=None) -> dict:
    """Observables of the run at ``path`` (run directory, or its dataset already in memory) as
    plain floats plus kind/field/note.

    ``options``: an ``AnalysisOptions``, or its fields as a dict (what a sweep task carries).
    """
    from flexmm.analysis.report.theory_comparison import RunContext
    from flexmm.analysis.report.analyze import choose_kind
    from flexmm.config.analysis import AnalysisOptions
    from flexmm.io.run_dataset import load_run_quickly

    opts = options if isinstance(options, AnalysisOptions) else AnalysisOptions.model_validate(options or {})
    import xarray as xr

    ds = path if isinstance(path, xr.Dataset) else load_run_quickly(path)  # as open_run, read faster
    ctx = RunContext.from_dataset(ds)
    kind = choose_kind(ctx) if opts.kind == "auto" else opts.kind
    return _full(ds, kind, opts)  # the dataset read once


def _speed_theory(ctx, units: str, amplitude: float) -> float:
    from flexmm.sweep.theory import speed_at

    return float(speed_at(ctx.config, units, [amplitude])[0])


def _pulse(a, p) -> dict:
    out = dict(speed=p.speed_m_s, speed_stderr=p.speed_stderr_m_s, amplitude=p.amplitude, width=p.fwhm_m,
               n_sites_fitted=float(p.n_sites_fitted), speed_theory=_speed_theory(a.ctx, p.units, p.amplitude),
               n_collisions=float(len(a.collisions)), formation_distance=p.formation_distance_m,
               amplitude_min=p.amplitude_min, amplitude_max=p.amplitude_max, breathing_period=p.breathing_period_s)
    if a.collisions:
        c = a.collisions[0]
        out.update(collision_shift=c.shift_a_m, collision_delay=c.delay_a_s,
                   collision_amplitude_change=c.amplitude_change_a, collision_speed_change=c.speed_change_a,
                   collision_passed={"passed through": 1.0, "reflected": 0.0}.get(c.outcome, math.nan))
    return out


def _front(a, f) -> dict:
    out = dict(speed=f.speed_m_s, speed_stderr=f.speed_stderr_m_s, amplitude=f.jump, width=f.width_10_90_m,
               n_sites_fitted=float(f.n_switched))
    return out | ({"note": f"front arrested after {f.distance_m:.4g} m"} if f.arrested else {})


#: analysis kind -> ``record(analysis, principal feature) -> observables`` of a point
RECORDS = {
    "pulse": _pulse,
    "front": _front,
    "modes": lambda a, g: dict(speed=g.speed_m_s),  # oblique plane waves: the fastest group
    "driven": lambda a, d: dict(amplitude=d.amplitude_far, transmission=d.transmission),
}


def _full(ds, kind: str, opts) -> dict:
    from flexmm.analysis import FieldError, FrontNotFound, NotDriven, PulseNotFound
    from flexmm.analysis.measure.oblique import NoWaveGroups
    from flexmm.analysis.report.analyze import analyze_with
    from flexmm.analysis.report.summary import principal

    try:
        a = analyze_with(ds, opts.model_copy(update={"kind": kind}))
    except (PulseNotFound, FrontNotFound, NotDriven, NoWaveGroups, FieldError) as exc:
        return _nan_result(kind, opts.field or "", "", f"no {kind}: {exc}")
    out = _nan_result(a.kind, a.view.spec, a.view.units, "")
    item, m = principal(a)  # the feature flexmm run prints and analyze lists
    out.update(RECORDS[a.kind](a, m))
    for c in a.comparisons:
        if c.item == item and c.quantity == "speed" and c.predicted is not None and math.isnan(out["speed_theory"]):
            out["speed_theory"] = float(c.predicted)
    return out
