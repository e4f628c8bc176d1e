"""Predeformed runs: measure fields from the relaxed, loaded state, not from the stress-free lattice.

A run whose lattice has ``predeform`` starts from a static equilibrium (models.predeform.relax)
whose fields the dataset stores per saved site (``u_rest``, ``theta_rest``, ...): θ carries the
static rotation θ_s and u the static shortening. Pulses, strains and drives are what moves on top
of it, so ``from_rest`` subtracts it field by field (rates are unchanged: the state is static);
site coordinates move to the rest positions (x + u_rest), so speeds and widths use the loaded spacing.
"""

from __future__ import annotations

import numpy as np

from flexmm.io.dataset import REST_SUFFIX

#: displacement field -> the site coordinate it moves
AXES = {"u": "x", "v": "y"}


def rest_fields(ctx) -> dict[str, np.ndarray] | None:
    """SI rest values per site field, shape (n_sites,), of a predeformed run; None if not predeformed.

    Read from the dataset's ``<field>_rest`` site coordinates (on the saved sites); a dataset
    written before they existed has the lattice rebuilt (and relaxed) from its stored config.
    Cached in ``ctx.cache['rest']``.
    """
    if "rest" not in ctx.cache:
        ctx.cache["rest"] = None
        stored = {} if ctx.ds is None else {
            name[: -len(REST_SUFFIX)]: np.asarray(ctx.ds.coords[name].values, float)
            for name in ctx.ds.coords if name.endswith(REST_SUFFIX)}
        if stored:
            ctx.cache["rest"] = stored
            return stored
        lat = ctx.scene().lattice
        if getattr(lat, "predeform", None) is not None:
            from flexmm.models import MODELS

            system = MODELS[lat.kind].build(lat)
            n, q = system.n_sites, system.rest_state
            ctx.cache["rest"] = {f.name: q[k * n : (k + 1) * n] * system.scales.coordinate(f.kind)
                                 for k, f in enumerate(system.fields)}
    return ctx.cache["rest"]


def from_rest(ds, rest: dict[str, np.ndarray] | None):
    """A copy of the run dataset with each (time, site) field minus its rest value; ``ds`` if None."""
    if rest is None:
        return ds
    out = ds.copy()
    for name, value in rest.items():
        if name in out.data_vars and out[name].dims == ("time", "site") and out.sizes["site"] == value.size:
            out[name] = out[name] - value
            out[name].attrs = {**ds[name].attrs, "measured_from": "predeformed rest state"}
            axis = AXES.get(name)
            if axis in out.coords and out[axis].dims == ("site",):  # sites sit where the load put them
                out = out.assign_coords({axis: (("site",), out[axis].values + value, out[axis].attrs)})
    return out
