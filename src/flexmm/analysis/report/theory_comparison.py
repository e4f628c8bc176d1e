"""Measured against predicted: each run's rows, with its model's theory where it has one.

A model kind's theory is a ``ModelTheory`` (``analysis.context``): plain functions that take the
run's context and a measurement and return ``Comparison`` rows (or a curve for figures), named by
the ``theory`` hook of its ``ModelSpec`` (``flexmm.config.lattice.MODELS``; see
``predict.rotating_squares.CHAIN`` and ``predict.mass_chain.MASS_CHAIN``). A model without one, or a measurement
a theory does not cover, simply gets no prediction.
"""

from __future__ import annotations

import math

import numpy as np

from flexmm.analysis.context import Comparison, ModelTheory, RunContext


def theory_for(ctx: RunContext) -> ModelTheory:
    """The registered theory of the run's model, or an empty one."""
    from flexmm.config.lattice import MODELS

    spec = MODELS.get(ctx.model)
    theory = None if spec is None else spec.hook("theory")
    return ModelTheory() if theory is None else theory


def _rows(item: str, measured: dict, predicted: list[Comparison]) -> list[Comparison]:
    """Measured rows (units given), with predictions merged in by quantity name; a quantity that
    was not measured (NaN) gets no prediction: there is nothing to compare it with."""
    pred = {c.quantity: c for c in predicted}
    rows = []
    for q, (value, units) in measured.items():
        c = pred.pop(q, None)
        if value is None or not math.isfinite(value):
            c = None
        rows.append(Comparison(item, q, value, c.predicted if c else None, units, c.note if c else ""))
    rows.extend(Comparison(item, c.quantity, c.measured, c.predicted, c.units, c.note) for c in pred.values())
    return rows


def _safe(fn, *args) -> list[Comparison]:
    """Call a predictor; a theory that does not apply (ValueError) or a stored config that no
    longer validates (ConfigError) contributes nothing."""
    from flexmm.config import ConfigError

    if fn is None:
        return []
    try:
        return fn(*args)
    except (ValueError, KeyError, ArithmeticError, ConfigError):
        return []


def compare_pulse(ctx: RunContext, p) -> list[Comparison]:
    """Rows for one PulseMeasurement: speed, amplitude, widths, attenuation, with theory."""
    u = p.units
    measured = {
        "speed": (p.speed_m_s, "m/s"),
        "amplitude": (p.amplitude, u),
        "width W (sech fit)": (p.width_sech_m, "m"),
        "width W (sech² fit)": (p.width_sech2_m, "m"),
        "width W (§1.3 fit)": (p.width_kg_m, "m"),
        "FWHM": (p.fwhm_m, "m"),
        "temporal FWHM": (p.temporal_fwhm_s, "s"),
        "attenuation": (p.attenuation_per_m, "1/m"),
        "formation distance": (p.formation_distance_m, "m"),
        "amplitude range": (p.amplitude_range, u),
        "breathing period": (p.breathing_period_s, "s"),
    }
    return _rows(f"pulse {p.index}", measured, _safe(theory_for(ctx).pulse, ctx, p))


def compare_transient(p) -> list[Comparison]:
    """Rows for a formation transient (``analysis.measure.transients``): how far and how long the lobe
    travelled, and what it turned into; never compared with a steady-pulse law."""
    note = "formation transient" + (f", turns into pulse {p.continues_as}" if p.continues_as >= 0 else ", dies out")
    return [Comparison(f"pulse {p.index}", q, value, None, units, note) for q, value, units in (
        ("formation distance", p.formation_distance_m, "m"), ("formation time", p.formation_time_s, "s"),
        ("amplitude", p.amplitude, p.units), ("speed", p.speed_m_s, "m/s"))]


def compare_collision(ctx: RunContext, c) -> list[Comparison]:
    """Rows for one Collision: per incoming pulse its shift, delay, amplitude and speed change,
    with the model's collision relation where it has one (Toda chains: the head-on shifts; the
    rotating-squares solitons have none in docs/physics.md)."""
    pred = {p.quantity: p for p in _safe(theory_for(ctx).collision, ctx, c)}
    rows = []
    for tag, pulse, out, outcome in (("a", c.pulse_a, c.out_a, c.outcome_a), ("b", c.pulse_b, c.out_b, c.outcome_b)):
        note = f"pulse {pulse} {outcome}" + (f" as pulse {out}" if out >= 0 else "")
        for q, attr, units in (("space shift", "shift", "m"), ("time shift", "delay", "s"),
                               ("amplitude change", "amplitude_change", "1"), ("speed change", "speed_change", "1")):
            key = f"{attr}_{tag}_m" if attr == "shift" else f"{attr}_{tag}_s" if attr == "delay" else f"{attr}_{tag}"
            p = pred.get(f"{q} of pulse {pulse}")
            rows.append(Comparison(f"collision {c.index}", f"{q} of pulse {pulse}", getattr(c, key),
                                   p.predicted if p else None, units, p.note if p else note))
    return rows


def compare_front(ctx: RunContext, f) -> list[Comparison]:
    measured = {
        "speed": (f.speed_m_s, "m/s"),
        "width 10–90 %": (f.width_10_90_m, "m"),
        "distance": (f.distance_m, "m"),
        "switched sites": (float(f.n_switched), "sites"),
    }
    return _rows(f"front {f.index}", measured, _safe(theory_for(ctx).front, ctx, f))


def generic_bands_hz(ctx: RunContext) -> list[tuple[float, float]]:
    """Linear pass bands (Hz) of any 1D model from its Bloch eigenproblem (linear.dispersion).

    Built on a short copy of the lattice (n_units = 32); ValueError for models without
    ``n_units`` or whose Hessian is not periodic.
    """
    from flexmm.models import MODELS
    from flexmm.linear.dispersion import band_edges_numeric

    lat = ctx.scene().lattice
    if "n_units" not in type(lat).model_fields:
        raise ValueError(f"no generic dispersion for {ctx.model}: not a chain with n_units")
    system = MODELS[lat.kind].build(lat.model_copy(update={"n_units": 32}))
    f = 1.0 / (2 * math.pi * system.scales.time_s)
    return [(lo * f, hi * f) for lo, hi in band_edges_numeric(system)]


def bands_for(ctx: RunContext) -> list[tuple[float, float]]:
    """The model's linear pass bands (Hz): its registered formula, else the generic Bloch one."""
    if "bands" not in ctx.cache:
        fn = theory_for(ctx).bands_hz or generic_bands_hz
        try:
            ctx.cache["bands"] = fn(ctx)
        except (ValueError, KeyError, ArithmeticError) as exc:
            ctx.cache["bands"] = []
            ctx.cache["bands_error"] = str(exc)
    return ctx.cache["bands"]


def _band_note(ctx: RunContext, f_hz: float) -> list[Comparison]:
    try:
        bands = bands_for(ctx)
    except Exception as exc:  # noqa: BLE001 - an invalid stored config only loses the note
        ctx.cache["bands_error"] = str(exc)
        bands = []
    if not bands:
        return []
    inside = any(lo <= f_hz <= hi for lo, hi in bands)
    text = ", ".join(f"{lo:.4g}–{hi:.4g} Hz" for lo, hi in bands)
    return [Comparison("", "drive frequency", f_hz, None, "Hz",
                       f"{'inside' if inside else 'outside'} the linear pass bands {text}")]


def compare_driven(ctx: RunContext, d) -> list[Comparison]:
    measured = {
        "drive frequency": (d.frequency_hz, "Hz"),
        "amplitude at drive": (d.amplitude_drive, d.units),
        "amplitude at far end": (d.amplitude_far, d.units),
        "transmission": (d.transmission, "1"),
        "decay per site": (d.decay_per_site, "1/site"),
        "dominant far-end frequency": (d.dominant_far_hz, "Hz"),
        "2nd harmonic / fundamental": (d.scalars().get("harmonic_2_ratio", np.nan), "1"),
        "3rd harmonic / fundamental": (d.scalars().get("harmonic_3_ratio", np.nan), "1"),
    }
    return _rows("driven", measured, _band_note(ctx, d.frequency_hz) + _safe(theory_for(ctx).driven, ctx, d))
