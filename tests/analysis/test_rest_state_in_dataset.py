"""A predeformed run stores its rest state, so analysis reads it instead of rebuilding the model.

Oracle: a predeformed chain left alone stays in its equilibrium, so every field measured from
the stored rest state is zero (up to the relaxation's residual, ~1e-8 rad against a static
rotation of ~0.1 rad) on every saved site — with a site stride too, where the rest state must be
sampled on the same sites as the fields (a mismatch would leave the static rotation in).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from flexmm.models import rotating_chain
from flexmm.analysis.context import RunContext
from flexmm.analysis.rest import from_rest, rest_fields
from flexmm.api import run_scene
from flexmm.config import scene_from_dict
from flexmm.io.dataset import open_run

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
    assert ds.sizes["site"] == len(range(0, 60, stride))
    assert float(np.median(np.abs(ds["theta"].values[0]))) > 0.05  # the static rotation is there

    def no_rebuild(*_a, **_k):
        raise AssertionError("analysis rebuilt the model")

    monkeypatch.setattr(rotating_chain, "build", no_rebuild)  # what MODELS["rotating_squares_chain"] builds with
    moved = from_rest(ds, rest_fields(RunContext.from_dataset(ds)))
    assert np.max(np.abs(moved["theta"].values)) < 1e-6  # residual of the relaxation only (static θ ≈ 0.1)
    assert np.max(np.abs(moved["u"].values)) < 1e-8
