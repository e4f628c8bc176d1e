"""Per-point observables of a sweep, from the public extraction of ``flexmm.analysis``.

What is measured follows ``flexmm.analysis.report.choose_kind`` (travelling pulse, transition
front or driven response) unless the sweep spec's ``analysis: {kind: ...}`` says otherwise:

- pulse on a dataset variable (θ, u, ...): ``leading_pulse`` — arrival-time line fit for the
  speed, median signed peak for the amplitude, FWHM for the width (fast and robust for the
  first pulse of an impact or a launched soliton);
- pulse on a derived field (``strain``, the default without rotations), fronts and driven runs:
  ``analyze_run`` — the dominant item (largest |amplitude| among pulses tracked over ≥ 10 sites;
  the front that switched most sites; the fastest group of an oblique plane wave);
- theory: the model's ``speed_curve`` at the measured amplitude (pulses), or the analysis'
  predicted speed (fronts), from ``flexmm.analysis.compare.THEORY``.

Options (``analysis:`` block): ``kind`` (auto, pulse, front, driven, modes), ``field``,
``threshold_fraction``, ``trim_fraction`` (leading_pulse only).
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
}
MIN_TRACK_SITES = 10


def _nan_result(kind: str, field: str, units: str, note: str) -> dict:
    return {**{k: math.nan for k in OBSERVABLES}, "kind": kind, "field": field,
            "amplitude_units": units, "note": note}


def observe_run(path: str | Path, options: dict | None = None) -> dict:
    """Observables of the run at ``path`` (run directory) as plain floats plus kind/field/note."""
    from flexmm.analysis.compare import RunContext
    from flexmm.analysis.fields import default_field
    from flexmm.analysis.report import choose_kind
    from flexmm.io.dataset import open_run

    opts = dict(options or {})
    ds = open_run(path)
    ctx = RunContext.from_dataset(ds)
    kind = opts.get("kind", "auto")
    kind = choose_kind(ctx) if kind == "auto" else kind
    field = opts.get("field") or (None if kind != "pulse" else default_field(ds))
    if kind == "pulse" and field in ds.data_vars:
        return _leading(ds, ctx, field, opts)
    return _full(path, kind, field, opts)


def _leading(ds, ctx, field: str, opts: dict) -> dict:
    from flexmm.analysis import PulseNotFound, leading_pulse

    units = ds[field].attrs.get("units", "")
    kw = {k: opts[k] for k in ("threshold_fraction", "trim_fraction") if k in opts}
    try:
        p = leading_pulse(ds, field, **kw)
    except PulseNotFound as exc:
        return _nan_result("pulse", field, units, f"no pulse: {exc}")
    out = _nan_result("pulse", field, units, "")
    out.update(speed=p.speed_m_s, speed_stderr=p.speed_stderr_m_s, amplitude=p.amplitude,
               width=p.fwhm_m, n_sites_fitted=float(p.n_sites_fitted),
               speed_theory=_speed_theory(ctx, units, p.amplitude))
    return out


def _speed_theory(ctx, units: str, amplitude: float) -> float:
    from flexmm.sweep.theory import speed_at

    return float(speed_at(ctx.config, units, [amplitude])[0])


def _full(path, kind: str, field: str | None, opts: dict) -> dict:
    from flexmm.analysis import FieldError, FrontNotFound, NotDriven, PulseNotFound, analyze_run
    from flexmm.analysis.oblique import NoWaveGroups

    kw = {k: opts[k] for k in ("threshold_fraction",) if k in opts}
    try:
        a = analyze_run(path, field_spec=field, kind=kind, **kw)
    except (PulseNotFound, FrontNotFound, NotDriven, NoWaveGroups, FieldError) as exc:
        return _nan_result(kind, field or "", "", f"no {kind}: {exc}")
    out = _nan_result(a.kind, a.view.spec, a.view.units, "")
    if a.kind == "pulse":
        long = [p for p in a.pulses if p.n_sites_fitted >= MIN_TRACK_SITES] or a.pulses
        p = max(long, key=lambda q: abs(q.amplitude))
        out.update(speed=p.speed_m_s, speed_stderr=p.speed_stderr_m_s, amplitude=p.amplitude,
                   width=p.fwhm_m, n_sites_fitted=float(p.n_sites_fitted),
                   speed_theory=_speed_theory(a.ctx, p.units, p.amplitude))
        item = f"pulse {p.index}"
    elif a.kind == "front":
        f = max(a.fronts, key=lambda q: q.n_switched)
        out.update(speed=f.speed_m_s, speed_stderr=f.speed_stderr_m_s, amplitude=f.jump,
                   width=f.width_10_90_m, n_sites_fitted=float(f.n_switched))
        item = f"front {f.index}"
        if f.arrested:
            out["note"] = f"front arrested after {f.distance_m:.4g} m"
    elif a.kind == "modes":  # oblique plane waves: the fastest group
        out.update(speed=a.groups[0].speed_m_s)
        item = "group 1"
    else:
        d = a.driven
        out.update(amplitude=d.amplitude_far, transmission=d.transmission)
        item = "driven"
    for c in a.comparisons:
        if c.item == item and c.quantity == "speed" and c.predicted is not None and math.isnan(out["speed_theory"]):
            out["speed_theory"] = float(c.predicted)
    return out
