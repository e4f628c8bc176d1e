"""Run a scene at two fidelities and report how observables and costs differ.

Observables come from the analysis module on the sites both runs share (a trimmed run has
fewer; 2D datasets are cut along their middle row): for a pulse, the dominant travelling pulse
— speed, amplitude, FWHM; for a front, the first transition front — speed, jump, 10–90 % width.
Cost is the time to the answer — solve plus plan (a continuum's shooting or pilot is its
solve), JIT compilation apart — and the work, DOF-steps = steps × degrees of freedom.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from flexmm.plan.output import AnalysisRequest, default_field


@dataclass
class Observed:
    """What one fidelity gave: observables (SI) and costs."""

    fidelity: str
    path: Path | None
    status: str
    speed_m_s: float = math.nan
    amplitude: float = math.nan
    width_m: float = math.nan
    units: str = ""
    wall_s: float = math.nan
    compile_s: float = math.nan
    plan_s: float = math.nan
    dof_steps: float = math.nan
    estimate_s: float = math.nan  # the plan's estimated integration time (``plan_estimated_s``)
    n_units: int = 0
    note: str = ""


@dataclass
class Comparison:
    scene_name: str
    kind: str
    field: str
    runs: list[Observed] = field(default_factory=list)

    def relative(self, name: str) -> float:
        """(b − a)/|a| for an observable of the two runs."""
        a, b = (getattr(r, name) for r in self.runs)
        return (b - a) / abs(a) if a and math.isfinite(a) and math.isfinite(b) else math.nan

    @property
    def cost_ratio(self) -> float:
        """Time to the answer (solve + plan) of the first fidelity over the second's (> 1: cheaper)."""
        a, b = (r.wall_s + r.plan_s for r in self.runs)
        return a / b if b > 0 else math.inf

    @property
    def work_ratio(self) -> float:
        a, b = self.runs[0].dof_steps, self.runs[1].dof_steps
        return a / b if b > 0 else math.inf

    def table(self) -> list[str]:
        a, b = self.runs
        w = "FWHM" if self.kind == "pulse" else "width 10-90"
        rows = [f"{self.scene_name}: {self.kind} of {self.field}, {a.fidelity} vs {b.fidelity}",
                f"  {'':<22}{a.fidelity:>14}{b.fidelity:>14}{'difference':>14}"]
        for label, name, scale in (("speed (m/s)", "speed_m_s", 1.0), (f"amplitude ({a.units})", "amplitude", 1.0),
                                   (f"{w} (mm)", "width_m", 1e3)):
            rows.append(f"  {label:<22}{getattr(a, name) * scale:>14.5g}{getattr(b, name) * scale:>14.5g}"
                        f"{100 * self.relative(name):>13.2f}%")
        rows.append(f"  {'units':<22}{a.n_units:>14d}{b.n_units:>14d}")
        rows.append(f"  {'solve + plan (s)':<22}{a.wall_s + a.plan_s:>14.4g}{b.wall_s + b.plan_s:>14.4g}"
                    f"{self.cost_ratio:>13.1f}x")
        rows.append(f"  {'  of which plan (s)':<22}{a.plan_s:>14.3g}{b.plan_s:>14.3g}")
        rows.append(f"  {'integration (s)':<22}{a.wall_s:>14.4g}{b.wall_s:>14.4g}")
        rows.append(f"  {'  planned estimate (s)':<22}{a.estimate_s:>14.4g}{b.estimate_s:>14.4g}")
        rows.append(f"  {'work (DOF-steps)':<22}{a.dof_steps:>14.4g}{b.dof_steps:>14.4g}{self.work_ratio:>13.1f}x")
        rows.append(f"  {'compile (s)':<22}{a.compile_s:>14.3g}{b.compile_s:>14.3g}")
        for r in self.runs:
            if r.note:
                rows.append(f"  {r.fidelity}: {r.note}")
        return rows


def middle_row(ds):
    """The sites of the middle row of a 2D dataset (ordered by column); a 1D dataset unchanged."""
    import numpy as np

    if "row" not in ds.coords or ds["row"].dims != ("site",):
        return ds
    rows = np.asarray(ds["row"].values)
    r = np.unique(rows)[np.unique(rows).size // 2]
    idx = np.flatnonzero(rows == r)
    return ds.isel(site=idx[np.argsort(np.asarray(ds["col"].values)[idx])])


def measure(path, kind: str, field_spec: str, x_range: tuple[float, float] | None = None) -> dict:
    """Observables of a run dataset: speed, amplitude, width (SI) and units.

    Pulses: ``analysis.leading_pulse`` (largest peak of each site's trace, line fit over the
    interior sites), robust to the secondary pulses an impact leaves behind; fronts:
    ``analysis.measure.fronts.measure_fronts``, first front.
    """
    from flexmm.io.run_dataset import open_run

    ds = middle_row(open_run(path))
    if x_range is not None:
        import numpy as np

        x = np.asarray(ds["x"].values, float)
        ds = ds.isel(site=np.flatnonzero((x >= x_range[0] - 1e-12) & (x <= x_range[1] + 1e-12)))
    if kind == "front":
        from flexmm.analysis.features.fields import field_view
        from flexmm.analysis.measure.fronts import measure_fronts

        view = field_view(ds, field_spec)
        f = measure_fronts(view)[0]
        return dict(speed_m_s=abs(f.speed_m_s), amplitude=f.jump, width_m=f.width_10_90_m, units=view.units)
    from flexmm.analysis import leading_pulse

    if field_spec == "strain":
        import numpy as np

        u = ds["u"]
        x = np.asarray(ds["x"].values, float)
        strain = u.diff("site") / np.diff(x)
        ds = ds.isel(site=slice(0, -1)).assign(strain=(("time", "site"), strain.values))
        ds["strain"].attrs["units"] = "1"
    p = leading_pulse(ds, field_spec)
    return dict(speed_m_s=abs(p.speed_m_s), amplitude=p.amplitude, width_m=p.fwhm_m, units=p.amplitude_units)


def run_fidelity(scene, fidelity: str, run_dir: Path, request: AnalysisRequest, log=None,
                 announce=None) -> Observed:
    """Run one fidelity of a scene into ``run_dir`` and measure it; ``announce(lines)`` receives its
    plan (``prepare.resolve``, as ``flexmm plan --fidelity`` prints it) before the run."""
    from flexmm.api import run_scene
    from flexmm.io.run_dataset import open_run
    from flexmm.models import model_fields

    res = run_scene(scene, run_dir=run_dir, fidelity=fidelity, analysis=str(request), log=log, announce=announce)
    obs = Observed(fidelity, res.path, res.status, wall_s=res.wall_s, compile_s=res.compile_s,
                   n_units=res.n_units)
    ds = open_run(res.path)
    obs.plan_s = float(ds.attrs.get("plan_time_s", 0.0))
    obs.estimate_s = float(ds.attrs.get("plan_estimated_s", math.nan))
    n_fields = len(model_fields(ds.attrs.get("model", scene.lattice.kind)))
    obs.dof_steps = float(res.n_steps) * res.n_units * n_fields
    if not res.ok:
        obs.note = f"{res.status}: {res.reason}"
    return obs


def _x_extent(path) -> tuple[float, float]:
    import numpy as np

    from flexmm.io.run_dataset import open_run

    x = np.asarray(middle_row(open_run(path))["x"].values, float)
    return float(x.min()), float(x.max())


def compare_fidelities(scene, fidelities: tuple[str, str], out_dir, request: AnalysisRequest | None = None,
                       log=None, announce=None) -> Comparison:
    """Run ``scene`` at both fidelities under ``out_dir/<fidelity>`` and compare them; ``announce(fidelity,
    lines)`` receives each fidelity's plan before its run."""
    request = request or AnalysisRequest("pulse")
    fld = default_field(request, _fields(scene))
    request = AnalysisRequest(request.kind, fld)
    cmp = Comparison(scene.name, request.kind, fld)
    for fid in fidelities:
        say = None if announce is None else (lambda lines, fid=fid: announce(fid, lines))
        cmp.runs.append(run_fidelity(scene, fid, Path(out_dir) / fid, request, log, say))
    done = [r for r in cmp.runs if r.status == "finished"]
    if len(done) == 2:
        (a0, a1), (b0, b1) = (_x_extent(r.path) for r in done)
        common = (max(a0, b0), min(a1, b1))
        for r in done:
            try:
                for k, v in measure(r.path, request.kind, request.field, common).items():
                    setattr(r, k, v)
            except Exception as exc:  # noqa: BLE001 - a run without a measurable pulse is reported
                r.note = f"not measured: {exc}"
    return cmp


def _fields(scene) -> tuple[str, ...]:
    from flexmm.models import model_fields

    return model_fields(scene.lattice.kind)
