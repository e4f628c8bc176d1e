"""Pick the (time, position) array an analysis works on from a run dataset.

A *field spec* names what to look at:

- a variable of the dataset with dims (time, site): ``theta``, ``u``, ``u_dot``, ...;
- ``strain`` or ``strain:NAME``: bond strain (f_{i+1} − f_i)/h of a displacement field at bond
  midpoints (default NAME: the longitudinal displacement, ``u`` or ``x``);
- ``velocity`` or ``velocity:NAME``: the rate ``NAME_dot`` of a displacement field.

2D datasets whose sites carry ``row`` and ``col`` coordinates are cut along one row (the middle
one unless ``row`` is given), ordered by column; datasets with dims (time, row, col) likewise.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from flexmm.errors import FlexmmError
from flexmm.io.run_dataset import REST_SUFFIX


class FieldError(FlexmmError, ValueError):
    """The requested field does not exist in (or cannot be derived from) the dataset."""


class DamagedDataset(FieldError):
    """A run dataset lacks a field its run saved, or holds NaN/inf values where a field is measured:
    it was damaged or edited (or the run blew up); it is not measured."""


def check_saved_fields(ds, config: dict) -> None:
    """DamagedDataset if ``ds`` lacks a field its run saved: the config's ``output.fields`` (else
    every field of the model, as the run's rest-state coordinates ``<field>_rest`` list them) and,
    with ``output.velocities``, their rates. Nothing is then measured on another field instead."""
    suffix = REST_SUFFIX
    model = [c[: -len(suffix)] for c in ds.coords if c.endswith(suffix) and ds[c].dims == ("site",)]
    out = (config or {}).get("output") or {}
    asked = out.get("fields") or model
    saved = [f for f in model if f in asked]
    if out.get("velocities", True):
        saved += [f + "_dot" for f in saved]
    missing = [f for f in saved if f not in ds.data_vars]
    if missing:
        raise DamagedDataset(f"the dataset has no {', '.join(missing)}, which its run saved (the "
                             f"stored config's output.fields, or every field of the model): a damaged or "
                             f"edited dataset, not measured (rerun the scene)")


def check_finite(view: "FieldView") -> None:
    """DamagedDataset if the field measured (or its times) holds NaN or infinite values."""
    bad = ~np.isfinite(view.values)
    if not np.all(np.isfinite(view.time)):
        raise DamagedDataset("the dataset's time holds NaN or infinite values: a damaged dataset, "
                             "not measured")
    if bad.any():
        i, j = np.argwhere(bad)[0]
        raise DamagedDataset(f"{int(bad.sum())} of the {bad.size} values of {view.spec!r} are NaN or "
                             f"infinite (the first at t = {view.time[i]:.6g} s, site {view.site[j]:g}): a "
                             f"damaged dataset or a run that blew up, not measured")


@dataclass
class FieldView:
    """One scalar field sampled on a line of sites.

    values : (n_time, n_pos) SI values; time : (n_time,) s; x : (n_pos,) positions (m) along the
    line; site : (n_pos,) site index (k + 0.5 for a bond between sites k and k+1).
    """

    spec: str
    values: np.ndarray
    time: np.ndarray
    x: np.ndarray
    site: np.ndarray
    units: str
    long_name: str
    spacing_m: float
    kind: str  # 'angle', 'length', 'strain', 'rate', 'other'

    @property
    def n_time(self) -> int:
        return self.values.shape[0]

    @property
    def n_pos(self) -> int:
        return self.values.shape[1]


def _line(ds, row: int | None):
    """Reduce a 2D dataset to the sites of one row (a (time, site) dataset)."""
    if "row" in ds.dims and "col" in ds.dims:
        r = int(ds.sizes["row"] // 2 if row is None else row)
        sub = ds.isel(row=r)
        return sub.rename({"col": "site"}) if "site" not in sub.dims else sub
    if "row" in ds.coords and "col" in ds.coords and ds["row"].dims == ("site",):
        rows = np.asarray(ds["row"].values)
        r = int(np.unique(rows)[len(np.unique(rows)) // 2] if row is None else row)
        idx = np.flatnonzero(rows == r)
        if idx.size == 0:
            raise FieldError(f"no sites in row {r} (rows {rows.min()}..{rows.max()})")
        idx = idx[np.argsort(np.asarray(ds["col"].values)[idx])]
        return ds.isel(site=idx)
    return ds


def site_fields(ds) -> list[str]:
    """Names of the (time, site) variables of a dataset."""
    return [str(k) for k, v in ds.data_vars.items() if v.dims[:1] == ("time",) and len(v.dims) >= 2]


def displacement_field(ds) -> str:
    """The longitudinal displacement of a dataset: ``u`` if present, else ``x`` as a field."""
    for name in ("u", "x"):
        if name in ds.data_vars and ds[name].dims[:1] == ("time",):
            return name
    raise FieldError(f"no displacement field (u or x) among {site_fields(ds)}")


def default_field(ds) -> str:
    """``theta`` when the model has rotations, else the strain of the displacement field."""
    return "theta" if "theta" in ds.data_vars else "strain"


def _positions(ds) -> np.ndarray:
    x = ds.coords.get("x")
    if x is not None and x.dims == ("site",) and "x" not in ds.data_vars:
        return np.asarray(x.values, float)
    h = float(ds.attrs.get("spacing_m", 1.0))
    return np.arange(ds.sizes["site"], dtype=float) * h


def _spacing(x: np.ndarray, ds) -> float:
    d = np.diff(x)
    return float(np.median(np.abs(d))) if d.size else float(ds.attrs.get("spacing_m", 1.0))


def field_view(ds, spec: str | None = None, *, row: int | None = None) -> FieldView:
    """The field ``spec`` (see module doc) as a FieldView; FieldError if unavailable."""
    ds = _line(ds, row)
    spec = spec or default_field(ds)
    base, _, arg = spec.partition(":")
    time = np.asarray(ds["time"].values, float)
    x = _positions(ds)
    h = _spacing(x, ds)
    site = np.arange(x.size, dtype=float)
    if base in ("strain", "velocity"):
        name = arg or displacement_field(ds)
        if base == "velocity":
            name = name + "_dot"
        if name not in ds.data_vars:
            raise FieldError(f"{spec!r} needs the field {name!r}; available: {', '.join(site_fields(ds))}")
    else:
        name = spec
    if name not in ds.data_vars or ds[name].dims != ("time", "site"):
        raise FieldError(f"no field {spec!r}; available: {', '.join(site_fields(ds))}, strain, velocity")
    var = ds[name]
    values = np.asarray(var.values, float)
    units, long_name = var.attrs.get("units", ""), var.attrs.get("long_name", name)
    kind = {"rad": "angle", "m": "length"}.get(units, "rate" if name.endswith("_dot") else "other")
    if base == "strain":
        dx = np.diff(x)
        values = np.diff(values, axis=1) / np.where(dx == 0, h, dx)
        x, site = 0.5 * (x[1:] + x[:-1]), site[:-1] + 0.5
        units, long_name, kind = "1", f"strain of {long_name}", "strain"
    return FieldView(spec, values, time, x, site, units, long_name, h, kind)
