"""Analyse one run directory: choose the analysis, measure, compare with theory.

``analyze_run(path)`` opens ``dataset.nc``, picks what to measure (``kind='auto'``: a driven run
if the excitation is a shaker, transition fronts if the model's theory says so, travelling
pulses otherwise), measures it on the chosen field, adds the energy budget and the theory rows
of the model's theory (``theory_comparison.theory_for``), pairs colliding pulses
(``analysis.measure.collisions``), tells formation transients from persistent pulses
(``analysis.measure.transients``; transients are not compared with theory), and returns a
``RunAnalysis`` that ``analysis.report.export`` writes out. Fields are measured from the rest
state the dataset stores (``analysis.features.rest``; the model is never rebuilt).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import get_args

from flexmm._blas import single_blas_thread
from flexmm.analysis.features.fields import FieldView, check_finite, check_saved_fields, field_view
from flexmm.analysis.features.rest import RestStateMissing, from_rest, rest_fields
from flexmm.analysis.measure.collisions import Collision, find_collisions
from flexmm.analysis.measure.driven import DrivenMeasurement, NotDriven, drive_frequency, measure_driven
from flexmm.analysis.measure.energy import EnergyBudget, energy_budget
from flexmm.analysis.measure.fronts import FrontMeasurement, FrontNotFound, measure_fronts
from flexmm.analysis.measure.oblique import NoWaveGroups, WaveGroup, compare_groups, is_oblique, wave_groups
from flexmm.analysis.measure.pulses import PulseMeasurement, PulseNotFound, measure_pulses
from flexmm.analysis.measure.transients import mark_transients
from flexmm.analysis.report.theory_comparison import (
    Comparison, RunContext, compare_collision, compare_driven, compare_front, compare_pulse, compare_transient,
    theory_for,
)
from flexmm.config.analysis import AnalysisKind, AnalysisOptions
from flexmm.io.identify import RunNotFound, run_dataset

#: the analysis kinds, from the options model (``flexmm.config.analysis``)
KINDS = get_args(AnalysisKind)


@dataclass
class RunAnalysis:
    """Everything measured on one run."""

    path: Path
    kind: str
    ctx: RunContext
    view: FieldView
    pulses: list[PulseMeasurement] = field(default_factory=list)
    fronts: list[FrontMeasurement] = field(default_factory=list)
    driven: DrivenMeasurement | None = None
    groups: list[WaveGroup] = field(default_factory=list)
    energy: EnergyBudget | None = None
    comparisons: list[Comparison] = field(default_factory=list)
    collisions: list[Collision] = field(default_factory=list)
    overlap_artefacts: int = 0

    @property
    def name(self) -> str:
        return str(self.ctx.ds.attrs.get("title") or self.path.name)


def run_status(path: str | Path) -> tuple[str, str]:
    """(status, reason) a run's dataset records ('finished', 'failed', 'interrupted'); RunNotFound
    (saying what the file is) if it is not a readable run dataset. Reads the attributes only (fast)."""
    _, attrs = run_dataset(path)
    return str(attrs.get("status", "finished")), str(attrs.get("status_reason", ""))


def open_dataset(path):
    """A run's dataset, loaded: from a run directory or .nc file, or a loaded Dataset as it is."""
    import xarray as xr

    if isinstance(path, xr.Dataset):
        return path
    from flexmm.io.run_dataset import load_run_quickly

    nc, _ = run_dataset(path)
    try:
        return load_run_quickly(nc)  # the Dataset xarray's reader gives, read with h5py alone
    except (OSError, ValueError) as exc:
        raise RunNotFound(f"cannot read {nc}: {exc}") from None


def choose_kind(ctx: RunContext) -> str:
    """'driven' for a shaker, 'modes' for oblique plane waves, else the model theory's preference,
    else 'pulse'."""
    if drive_frequency(ctx.config)[0] is not None:
        return "driven"
    if is_oblique(ctx):
        return "modes"
    from flexmm.config import ConfigError

    pick = theory_for(ctx).analysis
    try:
        return pick(ctx) if pick is not None else "pulse"
    except (ConfigError, ValueError, AttributeError):  # a stored config this version cannot read
        return "pulse"


def default_field_for(kind: str, ds, ctx=None) -> str | None:
    """Field used when none is given: for fronts the field the model's units switch
    (``ModelTheory.front_field``), else the displacement; the displacement for drives; for pulses
    the field the model's theory predicts (``ModelTheory.pulse_field``), else θ or strain."""
    from flexmm.analysis.features.fields import displacement_field
    from flexmm.config import ConfigError

    theory = None
    if ctx is not None:
        try:
            theory = theory_for(ctx)
        except (ConfigError, ValueError, AttributeError, KeyError):  # a stored config this version cannot read
            theory = None
    if kind == "front" and theory is not None and theory.front_field is not None:
        return theory.front_field
    if kind in ("front", "driven"):
        return displacement_field(ds)
    if kind == "pulse" and theory is not None:
        return theory.pulse_field
    return None


@single_blas_thread()
def analyze_run(path, *, field_spec: str | None = None, kind: str = "auto",
                row: int | None = None, threshold_fraction: float = 0.25,
                jump: float | None = None) -> RunAnalysis:
    """Measure one run (a run directory, its .nc file, or its dataset already loaded). Raises
    RunNotFound, FieldError (DamagedDataset: a field its run saved is missing, or the field measured
    holds NaN/inf), PulseNotFound, FrontNotFound, NotDriven.

    On one BLAS thread: its linear algebra is small (line and profile fits), and BLAS threads
    waiting for busy cores cost more than the work."""
    if kind not in KINDS:
        raise ValueError(f"unknown analysis {kind!r}; choose one of {', '.join(KINDS)}")
    return analyze_dataset(open_dataset(path), path=path, field_spec=field_spec, kind=kind, row=row,
                           threshold_fraction=threshold_fraction, jump=jump)


def analyze_dataset(ds, *, path: str | Path | None = None, field_spec: str | None = None, kind: str = "auto",
                    row: int | None = None, threshold_fraction: float = 0.25,
                    jump: float | None = None) -> RunAnalysis:
    """``analyze_run`` on a run's ``xarray.Dataset`` in memory (not modified); ``path``: where it
    came from, for the record (default: the file it was read from, else ``<in memory>``)."""
    if kind not in KINDS:
        raise ValueError(f"unknown analysis {kind!r}; choose one of {', '.join(KINDS)}")
    path = path if path is not None else (ds.encoding.get("source") or "<in memory>")
    ctx = RunContext.from_dataset(ds)
    check_saved_fields(ds, ctx.config)  # a deleted field is an error, never a fallback
    ctx.ds = ds = from_rest(ds, rest_fields(ctx))  # measure what moves on the rest state (dataset only)
    kind = choose_kind(ctx) if kind == "auto" else kind
    view = field_view(ds, field_spec or default_field_for(kind, ds, ctx), row=row)
    check_finite(view)
    where = Path(path) if isinstance(path, (str, Path)) else Path(path.encoding.get("source", ""))
    out = RunAnalysis(where, kind, ctx, view, energy=energy_budget(ds))
    if kind == "pulse":
        pulses = measure_pulses(view, threshold_fraction=threshold_fraction)
        t_end, line = float(view.time[-1]), (float(view.x.min()), float(view.x.max()))
        out.collisions, pulses, out.overlap_artefacts = find_collisions(pulses, view.spacing_m, t_end, line)
        out.pulses = mark_transients(pulses, out.collisions, view.spacing_m, t_end, line, view)
        for p in out.pulses:
            out.comparisons += compare_transient(p) if p.transient else compare_pulse(ctx, p)
        for c in out.collisions:
            out.comparisons += compare_collision(ctx, c)
    elif kind == "modes":
        out.groups = wave_groups(ds)
        if not out.groups:
            raise NoWaveGroups("no group of the oblique wave travelled 40 spacings in the second half of the run")
        out.comparisons += compare_groups(ctx, out.groups)
    elif kind == "front":
        out.fronts = measure_fronts(view, jump=jump)
        for f in out.fronts:
            out.comparisons += compare_front(ctx, f)
    else:
        freq, end = drive_frequency(ctx.config)
        out.driven = measure_driven(view, freq, end=end)
        out.comparisons += compare_driven(ctx, out.driven)
    return out


def analyze_with(path, options: AnalysisOptions) -> RunAnalysis:
    """``analyze_run`` with the options of ``flexmm analyze`` or a sweep's ``analysis:`` block."""
    return analyze_run(path, field_spec=options.field, kind=options.kind, row=options.row,
                       threshold_fraction=options.threshold_fraction, jump=options.jump)


def measure_run(path: str | Path, *, field_spec: str | None = None,
                kind: str = "auto") -> tuple[RunAnalysis | None, str | None]:
    """``analyze_run``, or (None, why) when the run is fine but there is nothing (or no such field)
    to measure: what ``flexmm run`` prints after a run (a missing run still raises)."""
    from flexmm.analysis.features.fields import FieldError

    try:
        return analyze_run(path, field_spec=field_spec, kind=kind), None
    except (PulseNotFound, FrontNotFound, NotDriven, NoWaveGroups, FieldError) as exc:
        return None, str(exc)


__all__ = ["KINDS", "RunAnalysis", "RunNotFound", "analyze_dataset", "analyze_run", "analyze_with", "choose_kind", "measure_run",
           "open_dataset",
           "FrontNotFound", "NoWaveGroups", "NotDriven", "PulseNotFound", "RestStateMissing"]


def sweep_bands(results: list[RunAnalysis], pass_level: float = 0.1) -> dict | None:
    """Pass bands measured over a set of driven runs (transmission ≥ pass_level × max) and the
    linear theory's bands of the first run's model; None with fewer than two driven runs."""
    from flexmm.analysis.report.theory_comparison import bands_for
    from flexmm.analysis.measure.driven import pass_bands

    driven = [r for r in results if r.driven is not None]
    if len(driven) < 2:
        return None
    f = [r.driven.frequency_hz for r in driven]
    tr = [r.driven.transmission for r in driven]
    return {"pass_level": pass_level, "frequencies_hz": sorted(f),
            "measured_hz": pass_bands(f, tr, pass_level), "predicted_hz": bands_for(driven[0].ctx)}
