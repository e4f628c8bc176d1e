"""Write a RunAnalysis as ``analysis.nc`` (xarray, h5netcdf), JSON or CSV rows.

analysis.nc layout (SI units, ``units``/``long_name`` on every variable):

- dims ``pulse``, ``front``, ``position`` (the analysed line: sites, or bonds for strain),
  ``time`` (the run's frames), ``comparison``, and for driven runs ``harmonic`` and ``frequency``;
- per pulse: every scalar of PulseMeasurement (``pulse_speed_m_s``, ...), ``arrival_time``
  and ``peak`` on (pulse, position), ``track_position`` on (pulse, time);
- per collision (dim ``collision``): every scalar of ``collisions.Collision``;
- per front: scalars, ``switch_time`` on (front, position), ``front_position`` on (front, time);
- oblique plane waves (analysis ``modes``): per group, every scalar of WaveGroup on ``group``;
- driven: ``steady_amplitude`` (position), ``harmonic_amplitude`` (harmonic),
  ``far_spectrum`` (frequency) and scalars;
- the comparison table (``comparison_item``, ``_quantity``, ``_measured``, ``_predicted``,
  ``_rel_diff``, ``_units``, ``_note`` on ``comparison``; ``comparison_measured`` and
  ``comparison_predicted`` have one unit per row, named by their ``units_variable``), energy
  budget scalars ``energy_*``;
- attrs: source dataset, its config hash, model, analysis kind and field (measured from the run's
  rest state: ``field_reference``), flexmm version and commit, and the
  CF globals (``flexmm.io.cf``: every variable has ``long_name`` and ``units``).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import xarray as xr

from flexmm._version import __version__
from flexmm.io.cf import DIMENSIONLESS, units_from_name, write_netcdf
from flexmm.io.provenance import git_commit

_SKIP = {"index", "field", "units"}


def _field_valued(key: str) -> bool:
    """Whether a measurement scalar is a value of the analysed field (amplitudes, jumps)."""
    return key == "jump" or (key.startswith("amplitude") and not key.startswith("amplitude_change"))


def _scalar_vars(prefix: str, dim: str, items: list[dict], field_units: str) -> dict:
    """One variable per scalar of the measurements; units from the name (io.cf), the field's for
    amplitudes, else dimensionless."""
    if not items:
        return {}
    out = {}
    for key in items[0]:
        if key in _SKIP:
            continue
        vals = [d[key] for d in items]
        if isinstance(vals[0], str):
            arr = np.asarray(vals, dtype=str)
        elif all(isinstance(x, (bool, int, np.bool_, np.integer)) for x in vals):
            arr = np.asarray(vals, dtype=np.int64)
        else:
            arr = np.asarray(vals, dtype=float)
        unit = field_units if _field_valued(key) and arr.dtype.kind == "f" else units_from_name(key)
        out[f"{prefix}_{key}"] = ((dim,), arr, {"units": unit or DIMENSIONLESS, "long_name": key.replace("_", " ")})
    return out


def _on_positions(view, rows: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
    """(n_rows, n_pos) array with values placed at their sites, NaN elsewhere."""
    out = np.full((len(rows), view.n_pos), np.nan)
    index = {float(s): k for k, s in enumerate(view.site)}
    for r, (sites, vals) in enumerate(rows):
        for s, v in zip(sites, vals):
            out[r, index[float(s)]] = v
    return out


def _on_time(view, rows: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
    out = np.full((len(rows), view.n_time), np.nan)
    for r, (t, pos) in enumerate(rows):
        k = np.searchsorted(view.time, t)
        ok = (k < view.n_time) & np.isclose(view.time[np.minimum(k, view.n_time - 1)], t)
        out[r, k[ok]] = pos[ok]
    return out


def to_dataset(res) -> xr.Dataset:
    """The analysis of one run as an xarray Dataset (see module docstring)."""
    v = res.view
    coords = {"position": ("position", v.x, {"units": "m", "long_name": "position along the line", "axis": "X"}),
              "site": ("position", v.site, {"units": DIMENSIONLESS, "long_name": "site index (k + 0.5: bond)"}),
              "time": ("time", v.time, {"units": "s", "long_name": "time"})}
    data = {}

    def var(dims, values, units, long_name):
        return (dims, values, {"units": units, "long_name": long_name})

    if res.pulses:
        ps = res.pulses
        data.update(_scalar_vars("pulse", "pulse", [p.scalars() for p in ps], v.units))
        data["arrival_time"] = var(("pulse", "position"), _on_positions(v, [(p.sites, p.arrival_time_s) for p in ps]),
                                   "s", "pulse arrival time")
        data["peak"] = var(("pulse", "position"), _on_positions(v, [(p.sites, p.peak) for p in ps]),
                           v.units, f"pulse peak of {v.spec}")
        data["track_position"] = var(("pulse", "time"), _on_time(v, [(p.track_time_s, p.track_pos_m) for p in ps]),
                                     "m", "tracked peak position")
    if getattr(res, "collisions", None):
        data.update(_scalar_vars("collision", "collision", [c.scalars() for c in res.collisions], v.units))
    if res.fronts:
        fs = res.fronts
        data.update(_scalar_vars("front", "front", [f.scalars() for f in fs], v.units))
        data["switch_time"] = var(("front", "position"), _on_positions(v, [(f.sites, f.switch_time_s) for f in fs]),
                                  "s", "time of the 50 % crossing")
        data["front_position"] = var(("front", "time"), _on_time(v, [(f.track_time_s, f.track_pos_m) for f in fs]),
                                     "m", "50 % crossing position")
    if res.groups:
        data.update(_scalar_vars("group", "group", [g.scalars() for g in res.groups], v.units))
    d = res.driven
    if d is not None:
        data["steady_amplitude"] = var(("position",), d.amplitude, v.units, "steady amplitude at the drive frequency")
        data["harmonic_amplitude"] = var(("harmonic",), d.harmonics, v.units, "far-end amplitude of n f")
        data["far_spectrum"] = var(("frequency",), d.spectrum, v.units, "far-end amplitude spectrum")
        coords["harmonic"] = ("harmonic", np.arange(1, d.harmonics.size + 1),
                              {"units": DIMENSIONLESS, "long_name": "harmonic number n (frequency n f)"})
        coords["frequency"] = ("frequency", d.spectrum_hz, {"units": "Hz", "long_name": "frequency"})
        for k, val in d.scalars().items():
            if isinstance(val, (int, float)):
                units = v.units if _field_valued(k) else units_from_name(k) or DIMENSIONLESS
                data[f"driven_{k}"] = ((), float(val), {"units": units, "long_name": k.replace("_", " ")})
    if res.energy is not None:
        for k, val in res.energy.scalars().items():
            data[f"energy_{k}"] = ((), val, {"units": "J" if k.endswith("_j") else DIMENSIONLESS,
                                             "long_name": "energy budget: " + k.replace("_", " ")})
    rows = [c.as_dict() for c in res.comparisons]
    if rows:
        for key in ("item", "quantity", "units", "note"):
            data[f"comparison_{key}"] = (("comparison",), np.array([r[key] for r in rows], dtype=str),
                                         {"units": DIMENSIONLESS, "long_name": f"compared {key}"})
        for key, long_name in (("measured", "measured value"), ("predicted", "predicted value"),
                               ("rel_diff", "(measured - predicted) / |predicted|")):
            vals = [np.nan if r[key] is None else r[key] for r in rows]
            attrs = {"units": DIMENSIONLESS, "long_name": long_name}
            if key != "rel_diff":  # one unit per row: the variable that holds them
                attrs.update(units_variable="comparison_units", long_name=f"{long_name} (in the row's comparison_units)")
            data[f"comparison_{key}"] = (("comparison",), np.array(vals, float), attrs)
    ds = xr.Dataset(data, coords=coords)
    src = res.ctx.ds.attrs
    ds.attrs.update(source=str(res.path), source_config_sha256=str(src.get("config_sha256", "")),
                    model=res.ctx.model, analysis=res.kind, field=v.spec, field_units=v.units,
                    field_reference="rest_state",  # analysis measures every field from the run's rest state
                    flexmm_version=__version__, git_commit=git_commit())
    return ds


def write_dataset(res, path: str | Path | None = None) -> Path:
    """Write analysis.nc beside the run's dataset (atomic rename); returns its path."""
    base = Path(res.path)
    target = Path(path) if path else (base if base.is_dir() else base.parent) / "analysis.nc"
    return write_netcdf(to_dataset(res), target)


def _clean(v):
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, (np.floating, np.integer)):
        return _clean(v.item())
    if isinstance(v, np.bool_):
        return bool(v)
    return v


def to_dict(res) -> dict:
    """JSON-ready summary of one run (scalars only; NaN becomes null)."""
    out = {
        "run": str(res.path), "name": res.name, "model": res.ctx.model, "analysis": res.kind,
        "field": res.view.spec, "field_units": res.view.units,
        "pulses": [{k: _clean(x) for k, x in p.scalars().items()} for p in res.pulses],
        "collisions": [{**{k: _clean(x) for k, x in c.scalars().items()}, "outcome": c.outcome}
                       for c in getattr(res, "collisions", [])],
        "overlap_artefacts": getattr(res, "overlap_artefacts", 0),
        "fronts": [{k: _clean(x) for k, x in f.scalars().items()} for f in res.fronts],
        "driven": {k: _clean(x) for k, x in res.driven.scalars().items()} if res.driven else None,
        "groups": [{k: _clean(x) for k, x in g.scalars().items()} for g in res.groups],
        "energy": {k: _clean(x) for k, x in res.energy.scalars().items()} if res.energy else None,
        "comparisons": [{k: _clean(x) for k, x in c.as_dict().items()} for c in res.comparisons],
    }
    return out


def to_json(results: list, errors: list[dict] | None = None, bands: dict | None = None) -> str:
    """JSON of several runs: {"runs": [...], "errors": [...], "bands": {...} or null}."""
    return json.dumps({"runs": [to_dict(r) for r in results], "errors": errors or [], "bands": bands},
                      indent=2, default=_clean)


CSV_COLUMNS = ("run", "analysis", "field", "item", "quantity", "measured", "predicted", "rel_diff", "units", "note")


def csv_rows(results: list) -> list[dict]:
    """One row per measured quantity of every run (the comparison table, long format)."""
    rows = []
    for r in results:
        for c in r.comparisons:
            d = {k: _clean(x) for k, x in c.as_dict().items()}
            rows.append({"run": str(r.path), "analysis": r.kind, "field": r.view.spec, **d})
    return rows
