"""Measure every field from the run's rest state, read from the dataset (the model is never rebuilt).

A run dataset stores its rest state per saved site (``u_rest``, ``theta_rest``, ...: the predeformed
equilibrium, the relaxed start of a mass model, else zeros), measured from the lattice's reference
configuration, and each field variable says what its values are measured from (``reference``:
``absolute`` or ``rest_state``; docs/architecture.md, "Datasets"). ``from_rest`` makes every field
relative to the rest state — it subtracts the rest state from absolute fields (θ of a predeformed
chain carries the static rotation θ_s) and leaves fields already relative to it — and moves the site
coordinates to the rest positions (x + u_rest), so speeds and widths use the loaded spacing. Rates
are unchanged: the rest state is static.

Datasets written before the rest state was stored: those of a predeformed run cannot be measured
(``RestStateMissing``: run the scene again); the others are taken as measured from q = 0, the rest
state of a lattice that is not predeformed (documented fallback).
"""

from __future__ import annotations

import numpy as np

from flexmm.errors import FlexmmError
from flexmm.io.run_dataset import REST_SUFFIX

#: displacement field -> the site coordinate it moves
AXES = {"u": "x", "v": "y"}


class RestStateMissing(FlexmmError):
    """A predeformed run's dataset without its rest state (written by an older flexmm)."""


def rest_fields(ctx) -> dict[str, np.ndarray] | None:
    """Field name -> SI rest values on the saved sites (from the reference configuration), read from
    the dataset's ``<field>_rest`` coordinates; None for an older dataset of a run that is not
    predeformed (rest state q = 0). RestStateMissing for an older predeformed one. Cached in
    ``ctx.cache['rest']``."""
    if "rest" not in ctx.cache:
        ds = ctx.ds
        stored = {} if ds is None else {
            str(name)[: -len(REST_SUFFIX)]: np.asarray(ds.coords[name].values, float)
            for name in ds.coords if str(name).endswith(REST_SUFFIX)}
        if not stored and (ctx.config.get("lattice") or {}).get("predeform") is not None:
            raise RestStateMissing(
                f"the dataset of predeformed run {ds.attrs.get('title', '?')!r} does not store its rest state "
                f"(written by flexmm {ds.attrs.get('flexmm_version', '?')}, before datasets stored it); "
                "its fields include the predeformation and cannot be measured from it: run the scene again")
        ctx.cache["rest"] = stored or None
    return ctx.cache["rest"]


def from_rest(ds, rest: dict[str, np.ndarray] | None):
    """A copy of the run dataset with every (time, site) field measured from the rest state
    (module docstring); ``ds`` itself if ``rest`` is None."""
    if rest is None:
        return ds
    out = ds.copy()
    for name, value in rest.items():
        if name not in out.data_vars or out[name].dims != ("time", "site") or out.sizes["site"] != value.size:
            if name in out.data_vars:
                raise ValueError(f"rest state of {name!r} has {value.size} sites, the field {out.sizes['site']}")
            continue
        if not np.any(value):  # the rest state is the reference configuration: nothing moves
            out[name].attrs = {**ds[name].attrs, "reference": "rest_state"}
            continue
        # datasets written before fields declared a reference stored absolute fields only
        if ds[name].attrs.get("reference", "absolute") == "absolute":
            out[name] = out[name] - value
            out[name].attrs = {**ds[name].attrs, "reference": "rest_state"}
        axis = AXES.get(name)
        if axis in out.coords and out[axis].dims == ("site",):  # sites sit where the rest state put them
            out = out.assign_coords({axis: (("site",), out[axis].values + value, out[axis].attrs)})
    return out
