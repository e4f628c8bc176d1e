"""Combine the points of a sweep into one dataset whose coordinates are the varied parameters.

Grid sweeps give one dimension per varied parameter (an N-D array of points); zipped sweeps a
``point`` dimension with the parameters as coordinates. Per point: the observables of
``flexmm.sweep.observe`` (``speed``, ``speed_stderr``, ``amplitude``, ``width``,
``n_sites_fitted``, ``speed_theory``, ``transmission``; NaN where not measured), ``status``
(finished / failed / pending), ``note`` (why a value is missing) and ``run`` (a kept point's run
directory relative to the sweep directory, '' for the others). Everything is read from the
sweep's store (``flexmm.sweep.store``), not from per-point files. Attributes: the spec, the base config, what was
measured on which field, and theory reference values (``theory_*``). Written to
SWEEP_DIR/sweep.nc atomically.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import numpy as np

from flexmm.io.cf import units_from_name, write_netcdf
from flexmm.sweep.observe import OBSERVABLES
from flexmm.sweep.spec import SweepSpec, spec_summary
from flexmm.sweep.store import CODE, FINISHED, LABELS, STATES


def parameter_units(path: str) -> str:
    """Units of a config field from its unit-suffixed name ('' if it has none)."""
    return units_from_name(path.rsplit(".", 1)[-1]) or ""


def dim_names(spec: SweepSpec) -> list[str]:
    """Short names for the varied parameters: the last key, or the full path if ambiguous."""
    last = [a.path.rsplit(".", 1)[-1] for a in spec.axes]
    return [s if last.count(s) == 1 else a.path.replace(".", "_") for s, a in zip(last, spec.axes)]


def fingerprint(plan, arrays: dict) -> str:
    """Hash of everything the combined dataset is made from."""
    h = hashlib.sha256(json.dumps(spec_summary(plan.spec), sort_keys=True, default=str).encode())
    for name in sorted(arrays):
        h.update(np.ascontiguousarray(arrays[name]).tobytes())
    return h.hexdigest()


def _decode(a: np.ndarray) -> np.ndarray:
    return np.char.decode(np.asarray(a), "utf-8", errors="ignore")


def combine(plan):
    """The sweep dataset (xarray) of a plan, from what is on disk now."""
    import xarray as xr

    from flexmm._version import __version__
    from flexmm.io.provenance import config_text, git_commit, resolved_config
    from flexmm.sweep.theory import reference_lines

    spec = plan.spec
    shape = spec.shape
    arrays = plan.store.read()
    code = np.asarray(arrays["status"])
    status = np.asarray(STATES, dtype=object)[code].reshape(shape)
    note = _decode(arrays["note"]).reshape(shape)
    values = {k: np.array(arrays["observables"][:, j]).reshape(shape) for j, k in enumerate(OBSERVABLES)}
    run = np.full(spec.n_points, "", dtype=object)
    for i in np.flatnonzero(code == CODE[FINISHED]):
        if spec.keeps(int(i), arrays["observables"][i]):
            d = plan.store.point_dir(spec.point_at(int(i)).hash)
            run[i] = str(d.relative_to(plan.store.root)) if d.exists() else ""
    run = run.reshape(shape)
    units = {}
    done = np.flatnonzero(code == CODE[FINISHED])
    labels = _decode(arrays["label"][done]) if len(done) else np.zeros((0, len(LABELS)), str)
    for j, key in enumerate(LABELS):
        found = [v for v in labels[:, j] if v]
        if found:
            units[key] = str(found[0])
    names = dim_names(spec)
    dims = names if spec.mode == "grid" else ["point"]
    coords = {}
    for name, axis in zip(names, spec.axes):
        attrs = {"parameter": axis.path, "units": parameter_units(axis.path), "long_name": axis.path,
                 "scale": axis.scale}
        coords[name] = ((name if spec.mode == "grid" else "point"), list(axis.values), attrs)
    if spec.mode == "zip":
        coords["point"] = ("point", np.arange(shape[0]), {"long_name": "point index"})
    data = {}
    for k, (u, long_name) in OBSERVABLES.items():
        if k != "transmission" or np.isfinite(values[k]).any():
            data[k] = (dims, values[k], {"units": u if u is not None else units.get("amplitude_units", ""),
                                         "long_name": long_name})
    data["status"] = (dims, status.astype(str), {"long_name": "point status (finished, failed, pending)"})
    data["note"] = (dims, note.astype(str), {"long_name": "why a value is missing"})
    data["run"] = (dims, run.astype(str), {"long_name": "run directory relative to the sweep directory"})
    base_scene = spec.base_scene()
    counts = {s: int(np.sum(status == s)) for s in ("finished", "failed", "pending")}
    attrs = {
        "title": spec.name,
        "description": spec.description,
        "sweep_mode": spec.mode,
        "sweep_spec": json.dumps(spec_summary(spec), default=str),
        "base_config": config_text(base_scene),
        "lattice_kind": base_scene.lattice.kind,
        "field": units.get("field", ""),
        "measured": units.get("kind", ""),
        "flexmm_version": __version__,
        "git_commit": git_commit(),
        "n_points": int(np.prod(shape)),
        "n_finished": counts["finished"],
        "n_failed": counts["failed"],
        "n_pending": counts["pending"],
        "fingerprint": fingerprint(plan, arrays),
        **reference_lines(resolved_config(base_scene)),
    }
    ds = xr.Dataset({k: xr.Variable(*v) for k, v in data.items()},
                    coords={k: xr.Variable(*v) for k, v in coords.items()}, attrs=attrs)
    return ds


def write_combined(plan) -> Path:
    """Write SWEEP_DIR/sweep.nc unless an identical one is there (then only touch it)."""
    import xarray as xr

    path = plan.store.result_path
    fp = fingerprint(plan, plan.store.read())
    history = None  # the commands that wrote the sweep.nc this one replaces (CF history)
    if path.exists():
        try:
            with xr.open_dataset(path, engine="h5netcdf") as old:
                same = old.attrs.get("fingerprint") == fp
                history = old.attrs.get("history")
        except (OSError, ValueError):
            same = False
        if same:
            os.utime(path)
            return path
    return write_netcdf(combine(plan), path, previous_history=history)
