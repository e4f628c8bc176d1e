"""Every netCDF file flexmm writes is self-describing (flexmm.io.cf, docs/architecture.md "Datasets").

Small, fast runs of each command that writes one — run (a rotating-squares chain, a mass chain, a
continuum prediction),
analyze, sweep, bench, fit, design — then every variable (coordinates included) must have
``long_name`` and ``units``, the globals ``Conventions`` and a timestamped ``history`` naming the
command must be there, ``time``/``x`` carry their CF ``axis``, the reproducibility attrs stay, and
the run datasets store their rest and initial state with every field saying what it is measured from.
"""

from __future__ import annotations

import copy
import re
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
import yaml
from conftest import LEGO_CHAIN
from typer.testing import CliRunner

from flexmm.cli import app
from flexmm.design.fit import synthetic_table, write_table
from flexmm.io.cf import (
    CONVENTIONS,
    global_attrs,
    history_line,
    units_from_name,
    variable_attrs,
)
from flexmm.io.run_dataset import REFERENCES

REPO = Path(__file__).resolve().parents[2]
runner = CliRunner()

CHAIN = dict(LEGO_CHAIN, theta0_rad=0.0)
IMPACT = {"name": "small", "lattice": {**CHAIN, "n_units": 8, "left": "driven", "right": "free"},
          "excitation": {"kind": "impact", "end": "left", "velocity_m_s": 3.0, "angular_velocity_rad_s": 300.0},
          "damping": {"viscous": {"damping_ratio": 0.01}}, "solver": {"duration_s": 0.004}}


def _cli(*args: str) -> None:
    res = runner.invoke(app, [str(a) for a in args])
    assert res.exit_code == 0, res.output


@pytest.fixture(scope="module")
def written(tmp_path_factory) -> dict[str, Path]:
    """One file of every kind flexmm writes, from small runs (~15 s together)."""
    d = tmp_path_factory.mktemp("cf")
    files = {}
    scene = {"name": "cf_chain", "lattice": {**CHAIN, "theta0_rad": 0.05, "n_units": 60, "left": "free"},
             "excitation": {"kind": "soliton", "amplitude_rad": 0.4, "center_site": 10},
             "solver": {"duration_s": 0.03}, "output": {"n_frames": 31, "velocities": True}}
    (d / "chain.yaml").write_text(yaml.safe_dump(scene))
    _cli("run", d / "chain.yaml", "--out", d / "chain")
    files["run dataset"] = d / "chain" / "dataset.nc"
    _cli("analyze", d / "chain")
    files["analysis.nc"] = d / "chain" / "analysis.nc"
    _cli("run", d / "chain.yaml", "--fidelity", "continuum", "--out", d / "continuum")
    files["continuum run dataset"] = d / "continuum" / "dataset.nc"
    _cli("run", REPO / "configs" / "h_raney_transition_wave.yaml", "--out", d / "masses", "--set",
         "lattice.n_units=40", "--set", "solver.duration_s=0.02", "--set", "output.n_frames=5")
    files["mass-chain run dataset"] = d / "masses" / "dataset.nc"
    _cli("sweep", d / "chain.yaml", "--vary", "excitation.amplitude_rad=0.3,0.4", "--out", d / "sweep",
         "--workers", "1", "--set", "lattice.n_units=30", "--set", "solver.duration_s=0.005")
    files["sweep.nc"] = d / "sweep" / "sweep.nc"
    _cli("bench", d / "chain.yaml", "--methods", "velocity_verlet", "--ivp", "RK45", "--repeats", "1",
         "--out", d / "bench", "--set", "lattice.n_units=20", "--set", "solver.duration_s=0.005", "--quiet")
    files["workprecision.nc"] = d / "bench" / "workprecision.nc"
    (d / "scene.yaml").write_text(yaml.safe_dump(IMPACT))
    write_table(synthetic_table(copy.deepcopy(IMPACT), "theta", [2, 4], 2.5e-4, 11, noise=0.0, seed=3),
                d / "trace.csv", "mrad")
    fit = {"name": "small_fit", "scene": "scene.yaml",
           "data": {"file": "trace.csv", "field": "theta", "unit": "mrad", "sigma": 1e-3},
           "parameters": [{"name": "k_rot", "target": "k_rot_n_m_per_rad", "initial": 8.5e-4, "bounds": [1e-4, 5e-3]}]}
    (d / "fit.yaml").write_text(yaml.safe_dump(fit))
    _cli("fit", d / "fit.yaml", "--out", d / "fit")
    files["fit.nc"] = d / "fit" / "fit.nc"
    design = {"name": "small_design", "scene": IMPACT, "optimizer": {"max_iterations": 1},
              "variables": [{"name": "zeta", "path": "damping.viscous.damping_ratio", "initial": 0.02,
                             "bounds": [0.0, 0.5]}],
              "objective": [{"kind": "energy", "region": {"sites": [5, 6]}, "goal": "maximize"}]}
    (d / "design.yaml").write_text(yaml.safe_dump(design))
    _cli("design", d / "design.yaml", "--out", d / "design")
    files["design history.nc"] = d / "design" / "history.nc"
    return files


KINDS = ["run dataset", "mass-chain run dataset", "continuum run dataset", "analysis.nc", "sweep.nc", "workprecision.nc", "fit.nc",
         "design history.nc"]


@pytest.mark.parametrize("kind", KINDS)
def test_every_file_flexmm_writes_is_cf_described(written, kind):
    path = written[kind]
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        missing = [(name, key) for name, var in ds.variables.items() for key in ("long_name", "units")
                   if not str(var.attrs.get(key, "")).strip()]
        assert not missing, f"{kind}: variables without long_name/units: {missing}"
        assert ds.attrs["Conventions"] == CONVENTIONS
        line = ds.attrs["history"].splitlines()[-1]
        assert re.match(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\dZ: ", line), line
        if "time" in ds.variables:
            assert ds["time"].attrs["axis"] == "T" and ds["time"].attrs["units"] == "s"
        if "x" in ds.variables:
            assert ds["x"].attrs["axis"] == "X"
        if kind.endswith("run dataset"):  # rest and initial state, and what each field is measured from
            for name in ("u", "theta" if "theta" in ds else "u"):
                assert ds[name].attrs["reference"] in REFERENCES
                assert ds[name].attrs["rest_state"] in ds.coords
                np.testing.assert_array_equal(ds[ds[name].attrs["initial_state"]].values, ds[name].values[0])
        if kind.endswith("run dataset") or kind in ("fit.nc", "design history.nc", "workprecision.nc"):
            for key in ("config", "config_sha256", "flexmm_version", "git_commit"):
                assert ds.attrs[key], key


def test_run_datasets_store_rest_and_initial_state_and_say_what_fields_measure(written):
    """A rotating chain stores absolute fields (rest state: q = 0), a relaxed mass chain stores
    u from its rest state (the relaxed positions, stored as u_rest): both say so."""
    with xr.open_dataset(written["run dataset"], engine="h5netcdf") as ds:
        for name in ("u", "theta", "u_dot", "theta_dot"):
            assert ds[name].attrs["reference"] == "absolute"
        assert ds["theta"].attrs["rest_state"] == "theta_rest" and ds["theta_dot"].attrs["rest_state"] == "theta_rest"
        assert np.all(ds["theta_rest"].values == 0) and ds["theta_rest"].attrs["units"] == "rad"
        np.testing.assert_array_equal(ds["theta_initial"].values, ds["theta"].values[0])
        np.testing.assert_array_equal(ds["theta_dot_initial"].values, ds["theta_dot"].values[0])
        assert np.abs(ds["theta_initial"].values).max() > 0.3  # the launched soliton
    with xr.open_dataset(written["mass-chain run dataset"], engine="h5netcdf") as ds:
        assert ds["u"].attrs["reference"] == "rest_state" and ds["u"].attrs["rest_state"] == "u_rest"
        assert ds["u_rest"].attrs["reference"] == "absolute" and ds["u_rest"].attrs["units"] == "m"
        # relaxed from the 7 mm guess into the well at 6.97 mm (the driven end is held at 7 mm)
        np.testing.assert_allclose(ds["u_rest"].values[1:], 6.97e-3, atol=0.02e-3)
        np.testing.assert_array_equal(ds["u_initial"].values, ds["u"].values[0])


def test_units_come_from_the_name_and_given_attributes_win():
    assert units_from_name("pulse_speed_m_s") == "m/s" and units_from_name("k_long_n_per_m") == "N/m"
    assert units_from_name("attenuation_per_m") == "1/m" and units_from_name("wall_s") == "s"
    assert units_from_name("n_sites_fitted") is None
    # compound units are not read as their tail (N s/m is not 1/m, N m s is not m/s)
    assert units_from_name("coefficient_n_s_per_m") == "N s/m" and units_from_name("k_rot_n_m_per_rad") == "N m/rad"
    assert units_from_name("c_n_m_s") == "N m s" and units_from_name("velocity_m_s") == "m/s"
    assert variable_attrs("width_m", {})["units"] == "m"
    assert variable_attrs("width_m", {"units": "mm", "long_name": "w"}) == {"units": "mm", "long_name": "w"}
    assert variable_attrs("status", {}, np.dtype("U8"))["units"] == "1"
    assert variable_attrs("time", {"units": "s"})["axis"] == "T"
    assert history_line(["/x/flexmm/cli/__main__.py", "run", "a b.yaml"]).endswith(": flexmm run 'a b.yaml'")
    lines = global_attrs("2026-01-01T00:00:00Z: flexmm sweep s.yaml")["history"].splitlines()
    assert lines[0] == "2026-01-01T00:00:00Z: flexmm sweep s.yaml" and len(lines) == 2  # a rewrite appends
