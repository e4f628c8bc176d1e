"""Synthetic run datasets for the render tests: a scene's stored config and chosen field values."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import yaml

from flexmm.config import scene_from_dict
from flexmm.io.run_dataset import DatasetWriter, add_state, shape_variables
from flexmm.models import MODELS

#: model kinds drawn from the shapes their datasets store (tests/render/test_shapes.py), not by the
#: squares' and masses' renderers these tests check
NOT_RENDERED = ("rotating_triangles_chain", "rotating_triangles_sheet", "rigid_network")


def scene_of(lattice: dict, name: str = "render_test") -> dict:
    return {"name": name, "lattice": copy.deepcopy(lattice), "solver": {"duration_s": 1.0}}


def build(lattice: dict):
    """(validated lattice config, built System) of a lattice dict."""
    lat = scene_from_dict(scene_of(lattice)).lattice
    return lat, MODELS[lat.kind].build(lat)


def random_fields(system, n_frames: int, seed: int = 0, amplitude: float = 1.0) -> dict[str, np.ndarray]:
    """(n_frames, n_sites) SI values of every field and its rate; frame 0 is the rest state (zeros)."""
    rng = np.random.default_rng(seed)
    n, length = system.n_sites, system.scales.length_m
    out = {}
    for f in system.fields:
        scale = 0.08 * length if f.kind == "length" else 0.25
        values = amplitude * scale * rng.uniform(-1, 1, (n_frames, n))
        values[0] = 0.0
        out[f.name] = values
        out[f"{f.name}_dot"] = rng.uniform(-1, 1, (n_frames, n)) * (3.0 if f.kind == "length" else 200.0)
    return out


def write_run(run_dir: Path, lattice: dict, system, fields: dict[str, np.ndarray], times=None, *,
              attrs: dict | None = None, sites: np.ndarray | None = None, rest: dict | None = None,
              state: bool = False) -> Path:
    """A dataset.nc with the given fields (all sites, or ``sites``), the site coordinates of the
    built model and the scene as its stored config; ``state``: with the system's rest and initial
    state as a run stores them (``io.run_dataset.add_state``), else laid out as before they were stored."""
    n_frames = next(iter(fields.values())).shape[0]
    times = np.linspace(0.0, 1e-3 * (n_frames - 1), n_frames) if times is None else np.asarray(times)
    sites = np.arange(system.n_sites) if sites is None else np.asarray(sites)
    coords = {k: (np.asarray(v)[sites], "m" if k in ("x", "y") else "1", k) for k, v in system.site_coords.items()}
    for name, values in (rest or {}).items():  # a predeformed run's rest state (``u_rest``, ...)
        coords[f"{name}_rest"] = (np.asarray(values, float)[sites], "", f"rest {name}")
    units = {f.name: ("m" if f.kind == "length" else "rad") for f in system.fields}
    site_vars = {name: (units.get(name.removesuffix("_dot"), "") + ("/s" if name.endswith("_dot") else ""), name)
                 for name in fields}
    if state:
        add_state(system, sites, site_vars, coords)
    run_dir.mkdir(parents=True, exist_ok=True)
    w = DatasetWriter(run_dir / "dataset.nc", sites.size, site_vars, {}, coords, n_frames=n_frames,
                      constants=shape_variables(system.unit_shapes(), sites, system.scales.length_m))
    for k, t in enumerate(times):
        w.append(float(t), {name: v[k][sites] for name, v in fields.items()}, {})
    base = {"config": yaml.safe_dump(scene_of(lattice)), "model": system.model, "title": "render_test",
            "status": "finished", "status_reason": ""}
    base.update(attrs or {})
    return w.close(base)


def polygons(pic) -> np.ndarray:
    """(N, V, 2) vertices of the drawn units (the closing vertex dropped)."""
    from matplotlib.path import Path as MplPath

    out = []
    for p in pic.fig.polys.get_paths():
        v = p.vertices
        if p.codes is not None and p.codes[-1] == MplPath.CLOSEPOLY:
            v = v[:-1]
        out.append(v)
    return np.array(out)


def hinge_points_drawn(poly: np.ndarray) -> np.ndarray:
    """(N, 4, 2) hinge points of drawn units: a square's corners, a cross's arm-end mid-points."""
    if poly.shape[1] == 4:
        return poly
    arms = poly.reshape(len(poly), 4, 3, 2)
    return 0.5 * (arms[:, :, 0] + arms[:, :, 1])


def export(*args):
    """``flexmm export ARGS`` through typer's runner; never a traceback."""
    from typer.testing import CliRunner

    from flexmm.cli import app

    result = CliRunner().invoke(app, ["export", *[str(a) for a in args]])
    assert "Traceback" not in result.output, result.output
    return result
