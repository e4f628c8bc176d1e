"""Apply ``scene.initial`` (config/initial.py) to a built system: the initial state of any shape.

In order: the last frame of ``from_run`` replaces the state; ``fields`` add their value and rate
(expressions of the site coordinates, or a table); ``launch`` adds exact/continuum chain waves
(``models.launch_chains``); ``pinned`` holds DOFs at their initial value (inverse mass 0,
velocity 0). All of it lives outside the lattice config, so a uniform lattice keeps its theory
comparisons in ``flexmm analyze``. Values are SI (m or rad; per s for rates).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from flexmm.config.initial import evaluate
from flexmm.errors import FlexmmError
from flexmm.models import System
from flexmm.models import launch_chains as lc


class InitialStateError(FlexmmError, ValueError):
    """``initial`` cannot be applied to this lattice (a user error)."""


def _scale(system: System, field: str) -> tuple[float, float]:
    """(value scale, rate scale): SI value / scale = nondimensional state."""
    kind = system.fields[system.field_index(field)].kind
    sc = system.scales
    if kind == "length":
        return sc.length_m, sc.velocity
    return 1.0, 1.0 / sc.time_s


def _slice(system: System, field: str) -> slice:
    if field not in [f.name for f in system.fields]:
        raise InitialStateError(f"initial: model {system.model!r} has no field {field!r} "
                                f"(fields: {', '.join(f.name for f in system.fields)})")
    k = system.field_index(field) * system.n_sites
    return slice(k, k + system.n_sites)


def site_variables(system: System, spacing_m: float) -> dict[str, np.ndarray]:
    """x, y (rest positions, m), n (site index), i, j (column, row) of every site."""
    return grid_variables(*system.site_grid(), spacing_m)


def grid_variables(ix: np.ndarray, iy: np.ndarray, spacing_m: float) -> dict[str, np.ndarray]:
    """The expression variables of sites with column ``ix`` and row ``iy`` (n_sites,), in site order."""
    ix, iy = np.asarray(ix, float), np.asarray(iy, float)
    return {"x": ix * spacing_m, "y": iy * spacing_m, "n": np.arange(ix.size, dtype=float), "i": ix, "j": iy}


def field_values(f, variables: dict, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(value, rate) of one ``initial.fields`` entry on ``n`` sites (SI); ValueError if it fails."""
    if f.table is not None:
        return _table(f.table, variables, n)
    value = evaluate(f.value, n, **variables) if f.value is not None else np.zeros(n)
    rate = evaluate(f.rate, n, **variables) if f.rate is not None else np.zeros(n)
    return value, rate


def _table(path: str, variables: dict, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(value, rate) per site from a CSV: first column site index (header 'site') or x (m)."""
    data = np.genfromtxt(path, delimiter=",", names=True, comments="#")
    names = data.dtype.names or ()
    if len(names) < 2:
        raise InitialStateError(f"initial table {path}: need a header and columns (site or x), value[, rate]")
    key, cols = names[0], names[1:]
    where = np.atleast_1d(data[key]).astype(float)
    vals = [np.atleast_1d(data[c]).astype(float) for c in cols[:2]]
    if key == "site":
        out = [np.zeros(n) for _ in vals]
        idx = where.astype(int)
        if idx.min() < 0 or idx.max() >= n or np.any(idx != where):
            raise InitialStateError(f"initial table {path}: site indices must be integers in 0..{n - 1}")
        for o, v in zip(out, vals):
            o[idx] = v
    elif key == "x":
        order = np.argsort(where)
        out = [np.interp(variables["x"], where[order], v[order]) for v in vals]
    else:
        raise InitialStateError(f"initial table {path}: first column must be 'site' or 'x', not {key!r}")
    return out[0], (out[1] if len(out) > 1 else np.zeros(n))


def spacing(lat) -> float:
    """The spacing (m) that turns column and row indices into the expression variables x and y."""
    return float(getattr(lat, "spacing_m", None) or getattr(lat, "a_m"))


def _rest_shift(system: System, ds, name: str) -> np.ndarray | float:
    """SI amount that turns field ``name`` of a run dataset into this system's measure of the same state.

    A field measured from its run's rest state (``reference: rest_state``, mass models) is that
    plus the stored rest state from the reference configuration; this system's own rest state is
    subtracted if its field is measured from it. Exactly 0 when both rest states agree (the same
    lattice), and for datasets that do not declare a reference.
    """
    source_ref = ds[name].attrs.get("reference")
    rest_name = ds[name].attrs.get("rest_state", "")
    if source_ref is None or rest_name not in ds.variables:
        return 0.0
    source = np.asarray(ds[rest_name].values, float) if source_ref == "rest_state" else 0.0
    target = system.rest_fields_si()[name] if system.field_reference == "rest_state" else 0.0
    shift = source - target
    return shift if np.any(shift) else 0.0


def _from_run(system: System, path: str) -> str:
    """Replace the state by the last frame of the run at ``path`` (the same positions, also when
    that run measured its fields from another rest state); a provenance note."""
    from flexmm.io.run_dataset import open_run

    ds = open_run(Path(path))
    t = float(ds["time"].values[-1])
    for f in system.fields:
        if f.name not in ds or ds[f.name].shape[-1] != system.n_sites:
            raise InitialStateError(f"initial.from_run {path}: its dataset has no field {f.name!r} on "
                                    f"{system.n_sites} sites (is it a run of the same lattice?)")
        rate = f"{f.name}_dot"
        if rate not in ds:
            raise InitialStateError(f"initial.from_run {path}: its dataset stores no {rate} "
                                    "(continue from a run with output.velocities: true)")
        last = (np.asarray(ds[f.name].values[-1], float), np.asarray(ds[rate].values[-1], float))
        if not (np.all(np.isfinite(last[0])) and np.all(np.isfinite(last[1]))):
            raise InitialStateError(f"initial.from_run {path}: the last frame of its {f.name} or {rate} holds NaN "
                                    "or infinite values (a damaged dataset or a run that blew up)")
        sl = _slice(system, f.name)
        vs, rs = _scale(system, f.name)
        system.q0[sl] = (np.asarray(ds[f.name].values[-1], float) + _rest_shift(system, ds, f.name)) / vs
        system.v0[sl] = np.asarray(ds[rate].values[-1], float) / rs
    sha = str(ds.attrs.get("config_sha256", ""))
    return f"initial state: last frame (t = {t:.6g} s) of {path} (config_sha256 {sha})"


#: launch kind -> ``wave(lattice, entry, viscous coefficient or None) -> (u, u_dot)``, the exact
#: chain waves of ``models.launch_chains``
WAVES = {
    "toda_soliton": lambda lat, s, eta: lc.toda_soliton(lat, s.kappa, s.center_site, s.direction),
    "toda_two_soliton": lambda lat, s, eta: lc.toda_two_soliton(lat, s.kappa, s.center_site, s.direction),
    "sech2_pulse": lambda lat, s, eta: lc.sech2_pulse(lat, s.strain, s.center_site, s.direction),
    "fpu_beta_pulse": lambda lat, s, eta: lc.fpu_beta_pulse(lat, s.strain, s.center_site, s.direction),
    "hertz_kdv_pulse": lambda lat, s, eta: lc.hertz_kdv_pulse(lat, s.amplitude_ratio, s.center_site, s.direction),
    "kink": lambda lat, s, eta: lc.kink(lat, eta, s.center_site, s.direction, static=s.speed == "static"),
    "tanh_front": lambda lat, s, eta: lc.tanh_front(lat, eta, s.center_site, s.direction, static=s.speed == "static"),
}


def _launch(system: System, scene, spec) -> tuple[np.ndarray, np.ndarray]:
    vis = scene.damping.viscous
    return WAVES[spec.kind](scene.lattice, spec, vis.coefficient_n_s_per_m if vis is not None else None)


def apply_initial(system: System, scene) -> list[str]:
    """Apply ``scene.initial`` to ``system`` (q0, v0, inv_mass); returns what it read (a note per
    source run, with the source's config hash)."""
    init = scene.initial
    notes = []
    if init.from_run is not None:
        notes.append(_from_run(system, init.from_run))
    variables = site_variables(system, spacing(scene.lattice))
    n = system.n_sites
    for k, f in enumerate(init.fields):
        sl = _slice(system, f.field)
        vs, rs = _scale(system, f.field)
        try:
            value, rate = field_values(f, variables, n)
        except ValueError as exc:
            raise InitialStateError(f"initial.fields.{k}: {exc}") from None
        system.q0[sl] += value / vs
        system.v0[sl] += rate / rs
    for k, spec in enumerate(init.launch):
        field = system.longitudinal_field
        try:
            u, ud = _launch(system, scene, spec)
        except ValueError as exc:
            raise InitialStateError(f"initial.launch.{k} ({spec.kind}): {exc}") from None
        sl = _slice(system, field)
        vs, rs = _scale(system, field)
        system.q0[sl] += u / vs
        system.v0[sl] += ud / rs
    for k, pin in enumerate(init.pinned):
        sl = _slice(system, pin.field)
        bad = [s for s in pin.sites if s >= n]
        if bad:
            raise InitialStateError(f"initial.pinned.{k}.sites {bad} outside 0..{n - 1}")
        dofs = np.asarray(pin.sites) + sl.start
        system.inv_mass[dofs] = 0.0
        system.v0[dofs] = 0.0
    return notes
