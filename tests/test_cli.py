"""The ``flexmm`` command line end to end on a shortened LEGO chain (Typer's CliRunner).

A run writes a self-describing dataset: SI values with units on every variable and coordinate,
the resolved config and its hash, versions; the same config gives the same numbers.
"""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
import yaml
from typer.testing import CliRunner

import flexmm
from flexmm.cli import app
from flexmm.config import scene_from_dict

SHIPPED = Path(__file__).resolve().parents[1] / "configs" / "lego_vector_soliton.yaml"
RUN_FILES = {"dataset.nc", "config.yaml", "run.log"}


@pytest.fixture(scope="module")
def short_lego(tmp_path_factory) -> Path:
    """The shipped LEGO config cut to 300 steps of the automatic dt (0.1 x stable limit)."""
    cfg = yaml.safe_load(SHIPPED.read_text())
    lat = cfg["lattice"]
    t_unit = math.sqrt(lat["mass_kg"] / lat["k_long_n_per_m"])  # ω_max ≈ 2 / t_unit
    cfg["solver"]["duration_s"] = 300 * 0.1 * t_unit
    cfg["output"] = {"n_frames": 31}
    f = tmp_path_factory.mktemp("cfg") / "short.yaml"
    f.write_text(yaml.safe_dump(cfg))
    return f


@pytest.fixture(scope="module")
def declared_run(short_lego, tmp_path_factory):
    """One ``flexmm run --fidelity full`` of the short config, shared by the dataset tests."""
    return run(short_lego, tmp_path_factory.mktemp("declared") / "run")[1]


def invoke(*args: str):
    result = CliRunner().invoke(app, [str(a) for a in args])
    assert "Traceback" not in result.output
    return result


def run(config, out, *extra, fidelity="full"):
    """``flexmm run``; fidelity 'full' runs the scene as declared (the CLI default 'auto' may plan it)."""
    result = invoke("run", config, "--out", out, "--fidelity", fidelity, *extra)
    assert result.exit_code == 0, result.output
    return result, xr.open_dataset(Path(out) / "dataset.nc", engine="h5netcdf")


def test_run_writes_outputs_and_prints_dataset_path(short_lego, tmp_path):
    out = tmp_path / "run"
    result, ds = run(short_lego, out, fidelity="auto")  # the default
    assert {p.name for p in out.iterdir()} == RUN_FILES | {"checkpoint.ckpt"}  # no temporary files left
    assert f"dataset: {out / 'dataset.nc'}" in result.output
    assert ds.attrs["status"] == "finished"
    assert ds.sizes["time"] >= 2 and ds.attrs["n_steps"] > 0
    assert yaml.safe_load((out / "config.yaml").read_text()) == yaml.safe_load(ds.attrs["config"])
    log = (out / "run.log").read_text()
    assert "finished" in log and log.strip() == ds.attrs["log"].strip()


def test_dataset_is_self_describing_si(declared_run):
    ds = declared_run
    # whole steps of the reported dt cover the duration; the frame count is kept
    duration = yaml.safe_load(ds.attrs["config"])["solver"]["duration_s"]
    assert ds.attrs["n_steps"] == math.ceil(duration / ds.attrs["dt_s"] - 1e-9) and ds.sizes["time"] == 31
    for name in list(ds.data_vars) + list(ds.coords):
        assert ds[name].attrs.get("units"), f"{name} has no units"
        assert ds[name].attrs.get("long_name"), f"{name} has no long_name"
    units = {"time": "s", "x": "m", "u": "m", "theta": "rad", "u_dot": "m/s", "theta_dot": "rad/s",
             "total_energy": "J", "dissipated_energy": "J", "applied_work": "J"}
    for name, unit in units.items():
        assert ds[name].attrs["units"] == unit
    for key in ("config", "config_sha256", "flexmm_version", "git_commit", "status", "libraries", "dt_s",
                "stable_dt_s", "omega_max_rad_s"):
        assert key in ds.attrs, key
    assert ds.attrs["flexmm_version"] == flexmm.__version__
    # the hash is the sha256 of the canonical JSON of the stored config, which re-validates
    resolved = yaml.safe_load(ds.attrs["config"])
    canon = json.dumps(resolved, sort_keys=True, separators=(",", ":"))
    assert hashlib.sha256(canon.encode()).hexdigest() == ds.attrs["config_sha256"]
    scene = scene_from_dict(resolved)
    # SI values at t = 0 follow from the config: the struck unit's velocity and spin, rest
    # positions a cos θ0 apart, E(0) = ½ m v² + ½ J ω²
    lat, exc = scene.lattice, scene.excitation
    assert float(ds.u_dot[0, 0]) == pytest.approx(exc.velocity_m_s, rel=1e-12)
    assert float(ds.theta_dot[0, 0]) == pytest.approx(exc.angular_velocity_rad_s, rel=1e-12)
    assert np.allclose(np.diff(ds.x.values), lat.a_m * math.cos(lat.theta0_rad), rtol=1e-12)
    e0 = 0.5 * lat.mass_kg * exc.velocity_m_s**2 + 0.5 * lat.inertia_kg_m2 * exc.angular_velocity_rad_s**2
    assert float(ds.total_energy[0]) == pytest.approx(e0, rel=1e-12)
    # the run covers the duration in whole steps of the reported dt (rounded up, never bent)
    dt, t_end = ds.attrs["dt_s"], float(ds.time[-1])
    assert scene.solver.duration_s * (1 - 1e-9) <= t_end < scene.solver.duration_s + dt
    assert t_end / dt == pytest.approx(round(t_end / dt), abs=1e-6)


def test_set_overrides_land_in_resolved_config(short_lego, tmp_path):
    _, ds = run(short_lego, tmp_path / "run", "--set", "lattice.n_units=40", "--set", "damping.absorbing=null",
                "--set", "damping.viscous.damping_ratio=1e-3", "-s", "output.n_frames=11")
    resolved = yaml.safe_load(ds.attrs["config"])
    assert resolved["lattice"]["n_units"] == 40 and ds.sizes["site"] == 40
    assert resolved["damping"]["viscous"]["damping_ratio"] == 1e-3 and ds.sizes["time"] == 11
    assert float(ds.dissipated_energy[-1]) > 0.0


def test_same_config_twice_gives_identical_numbers(short_lego, declared_run, tmp_path):
    a = declared_run
    _, b = run(short_lego, tmp_path / "b")
    assert a.attrs["config_sha256"] == b.attrs["config_sha256"]
    assert a.attrs["config"] == b.attrs["config"]
    xr.testing.assert_identical(a.drop_attrs(), b.drop_attrs())  # bit-identical values and units
    for key in ("flexmm_version", "git_commit", "status", "integrator", "dt_s", "n_steps"):
        assert a.attrs[key] == b.attrs[key], key


def test_validate(short_lego):
    result = invoke("validate", short_lego)
    assert result.exit_code == 0 and "ok" in result.output and "stable limit" in result.output
    result = invoke("validate", short_lego, "--no-build")
    assert result.exit_code == 0 and "ok" in result.output


def test_schema_is_json_with_lattice():
    result = invoke("schema")
    assert result.exit_code == 0
    schema = json.loads(result.output)
    assert "lattice" in schema["properties"] and "solver" in schema["required"]


def test_schema_of_sweep_specs():
    from flexmm.analysis.report.analyze import KINDS

    result = invoke("schema", "sweep")
    assert result.exit_code == 0
    schema = json.loads(result.output)
    assert {"base", "vary"} <= set(schema["required"]) and "analysis" in schema["properties"]
    assert schema["$defs"]["AnalysisOptions"]["properties"]["kind"]["enum"] == list(KINDS)
    result = invoke("schema", "scenes")
    assert result.exit_code == 2 and "choose scene or sweep" in result.output


def test_unstable_dt_exits_2_and_forced_blow_up_exits_1(short_lego, tmp_path):
    result = invoke("run", short_lego, "--out", tmp_path / "r", "--fidelity", "full", "--set", "solver.dt_s=1e-3")
    assert result.exit_code == 2 and "stable limit" in result.output
    assert not (tmp_path / "r" / "dataset.nc").exists()
    # one frame at the end, so the step (shortened to divide the duration) stays far above the limit
    result = invoke("run", short_lego, "--out", tmp_path / "f", "--fidelity", "full", "--set", "solver.dt_s=1e-3",
                    "--set", "output.n_frames=2", "--set", "output.exact_frame_times=true", "--force")
    assert result.exit_code == 1 and "failed" in result.output
    assert not (tmp_path / "f").exists()  # a failed run is kept aside, never where a finished one goes
    ds = xr.open_dataset(tmp_path / "f.failed" / "dataset.nc", engine="h5netcdf")
    assert ds.attrs["status"] == "failed" and np.isfinite(ds.u.values).all()
    assert {p.name for p in (tmp_path / "f.failed").iterdir()} == RUN_FILES


def test_lego_fixture_matches_shipped_config(lego_config, make_scene):
    """tests/conftest.py's LEGO dict with DEMO_CHANGES is the shipped configs/lego_vector_soliton.yaml,
    and the shipped file with DEMO_AS_LEGO_SCENE is the dict."""
    from conftest import DEMO_AS_LEGO_SCENE_SETS, DEMO_CHANGES

    from flexmm.config import load_scene

    assert make_scene(lego_config, DEMO_CHANGES) == load_scene(SHIPPED)
    assert load_scene(SHIPPED, DEMO_AS_LEGO_SCENE_SETS) == make_scene(lego_config)
