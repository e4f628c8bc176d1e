"""Real (short) runs of every model kind rendered end to end, the drawing checked against the dataset.

One example lattice per model kind (tests/conftest.py) is kicked and run for a few frames with
``flexmm.api.run_scene``; the still of its last frame is rendered and its units (bodies) are
compared with the kinematics of docs/physics.md §1–2 evaluated on the dataset's own fields.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import EXAMPLE_LATTICES
from render_helpers import NOT_RENDERED, hinge_points_drawn, polygons
from test_kinematics import expected_hinge_points

from flexmm.api import run_scene
from flexmm.config import scene_from_dict
from flexmm.io.run_dataset import open_run
from flexmm.render.api import RenderOptions, render_run, still_figure

FIRST = {kind: next(iter(examples.values()))["lattice"] for kind, examples in EXAMPLE_LATTICES.items()
         if kind not in NOT_RENDERED}  # kinds flexmm.render does not draw yet
KICK = {"rotating_squares_chain": {"angular_velocity_rad_s": 80.0, "velocity_x_m_s": 0.5},
        "rotating_squares_sheet": {"angular_velocity_rad_s": 80.0, "velocity_y_m_s": 0.3},
        "bistable_linkage": {"angular_velocity_rad_s": 80.0}}


@pytest.mark.parametrize("kind", sorted(FIRST))
def test_rendered_run_matches_its_dataset(kind, tmp_path):
    lattice = FIRST[kind]
    kick = dict(KICK.get(kind, {"velocity_x_m_s": 0.3}), sites=[0, 1])
    scene = scene_from_dict({"name": f"tiny_{kind}", "lattice": lattice,
                             "excitation": {"kind": "kicks", "kicks": [kick]},
                             "solver": {"duration_s": 2e-3}, "output": {"n_frames": 5}})
    result = run_scene(scene, run_dir=tmp_path / "run")
    assert result.status == "finished"
    ds = open_run(tmp_path / "run")
    pic = still_figure(tmp_path / "run", RenderOptions(shape="square" if kind in KICK else None))
    fields = {name: ds[name].values for name in ds.data_vars if ds[name].dims == ("time", "site")}
    if kind in KICK:
        lat = scene.lattice
        from flexmm.models import MODELS

        system = MODELS[kind].build(lat)
        drawn = hinge_points_drawn(polygons(pic))
        want = expected_hinge_points(lat, system, fields, ds.sizes["time"] - 1)
        np.testing.assert_allclose(drawn, want, atol=1e-12)
    else:
        x0 = pic.structure.p.x0
        drawn = np.asarray(pic.fig.bodies.get_offsets())
        u = fields["u"][-1]
        if kind != "mass_network":
            np.testing.assert_allclose(drawn[:, 0], ds["x"].values + x0 + u, atol=1e-12)
    out = render_run(tmp_path / "run", RenderOptions(out=tmp_path / "movie.gif", spacetime=True, color="energy"))
    assert out.stat().st_size > 0
