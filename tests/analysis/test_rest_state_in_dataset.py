"""A predeformed run stores its rest state, so analysis reads it instead of rebuilding the model.

Oracle: a predeformed chain left alone stays in its equilibrium, so every field measured from
the stored rest state is zero (up to the relaxation's residual, ~1e-8 rad against a static
rotation of ~0.1 rad) on every saved site — with a site stride too, where the rest state must be
sampled on the same sites as the fields (a mismatch would leave the static rotation in). A dataset
without the stored rest state is refused (formerly the model was rebuilt, and with a site stride
the subtraction was silently skipped: θ median 0.150 rad instead of 0).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from flexmm.models import rotating_chain
from flexmm.analysis.context import RunContext
from flexmm.analysis.features.rest import RestStateMissing, from_rest, rest_fields
from flexmm.api import run_scene
from flexmm.cli import app
from flexmm.config import scene_from_dict
from flexmm.io.run_dataset import open_run

CONFIG = Path(__file__).resolve().parents[2] / "configs" / "predeformed_rarefaction_soliton.yaml"


@pytest.mark.parametrize("stride", [1, 3])
def test_rest_state_is_stored_on_the_saved_sites_and_used_without_a_rebuild(stride, tmp_path, monkeypatch):
    data = yaml.safe_load(CONFIG.read_text())
    data.update(excitation={"kind": "none"}, solver={"duration_s": 0.002},
                output={"n_frames": 5, "site_stride": stride})
    data["lattice"]["n_units"] = 60
    scene = scene_from_dict(data)
    assert run_scene(scene, run_dir=tmp_path).ok
    ds = open_run(tmp_path)
    assert "theta_rest" in ds.coords and ds["theta_rest"].attrs["units"] == "rad"
    for name in ("u", "theta"):  # absolute fields, saying where their rest and initial state are
        assert ds[name].attrs["reference"] == "absolute"
        assert ds[name].attrs["rest_state"] == f"{name}_rest" and ds[name].attrs["initial_state"] == f"{name}_initial"
        np.testing.assert_array_equal(ds[f"{name}_initial"].values, ds[name].values[0])
    assert ds.sizes["site"] == len(range(0, 60, stride))
    assert float(np.median(np.abs(ds["theta"].values[0]))) > 0.05  # the static rotation is there

    def no_rebuild(*_a, **_k):
        raise AssertionError("analysis rebuilt the model")

    monkeypatch.setattr(rotating_chain, "build", no_rebuild)  # what MODELS["rotating_squares_chain"] builds with
    moved = from_rest(ds, rest_fields(RunContext.from_dataset(ds)))
    assert np.max(np.abs(moved["theta"].values)) < 1e-6  # residual of the relaxation only (static θ ≈ 0.1)
    assert np.max(np.abs(moved["u"].values)) < 1e-8
    # a dataset without the rest state (older flexmm) is refused, not measured with θ_s left in
    old = ds.drop_vars([v for v in ds.variables if str(v).endswith(("_rest", "_initial"))])
    with pytest.raises(RestStateMissing):
        from_rest(old, rest_fields(RunContext.from_dataset(old)))
    if stride > 1:  # flexmm analyze says why and goes on with the other runs
        old.to_netcdf(tmp_path / "old.nc", engine="h5netcdf")
        res = CliRunner().invoke(app, ["analyze", str(tmp_path / "old.nc"), "--no-save"])
        said = " ".join(res.output.split())  # unwrapped
        assert "does not store its rest state" in said and "run the scene again" in said


def test_fields_measured_from_the_rest_state_are_kept_and_sites_move_to_their_rest_positions():
    """The same rule for every family: an absolute field loses its rest value, a field already
    measured from the rest state (mass models) keeps its values; both put the sites at x + u_rest.
    A rest state on other sites than the fields is an error, never a skipped subtraction."""
    import xarray as xr

    rest = np.array([0.0, 1e-3, 2e-3])
    u = np.array([[5e-4, 6e-4, 7e-4]])
    coords = {"time": [0.0], "x": ("site", [0.0, 0.01, 0.02]), "u_rest": ("site", rest)}
    for reference, expected in (("absolute", u - rest), ("rest_state", u)):
        ds = xr.Dataset({"u": (("time", "site"), u, {"units": "m", "reference": reference, "rest_state": "u_rest"})},
                        coords=coords)
        moved = from_rest(ds, rest_fields(RunContext("mass_chain", {}, ds)))
        np.testing.assert_array_equal(moved["u"].values, expected)
        np.testing.assert_array_equal(moved["x"].values, ds["x"].values + rest)
        assert moved["u"].attrs["reference"] == "rest_state"
    with pytest.raises(ValueError, match="sites"):
        from_rest(ds, {"u": rest[:2]})
