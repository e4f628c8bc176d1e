"""Solitons launched on a predeformed chain, and fields measured from its rest state (fast)."""

import numpy as np
import pytest
from conftest import LEGO_CHAIN

from flexmm.analysis.context import RunContext
from flexmm.analysis.features.rest import from_rest, rest_fields
from flexmm.assemble import SceneError, build_problem
from flexmm.config import scene_from_dict
from flexmm.models.rotating_chain import theory_parameters
from flexmm.theory.prestressed import prestressed_chain
from flexmm.theory.rotating import RotatingChainND, soliton_initial_state

LATTICE = {**LEGO_CHAIN, "n_units": 100, "theta0_rad": 0.05,
           "predeform": {"loads": [{"end": "left", "force_n": 0.2}, {"end": "right", "force_n": 0.2}],
                         "theta_guess_rad": 0.1}}


def _scene(amplitude=-0.38, center=50, lattice=LATTICE):
    return scene_from_dict({"name": "t", "lattice": lattice, "solver": {"duration_s": 1e-3},
                            "excitation": {"kind": "soliton", "amplitude_rad": amplitude, "center_site": center}})


def test_soliton_rides_on_the_relaxed_state():
    system = build_problem(_scene()).system
    n, rest, m = system.n_sites, system.rest_state, theory_parameters(_scene().lattice)
    p = prestressed_chain(RotatingChainND(0.05, m.Ks, m.Ktheta, m.alpha2, 1, 0),
                          float(rest[n + 50]))
    s = soliton_initial_state(p, -0.38, n, 50)
    assert np.allclose(system.q0[n:] - rest[n:], s.theta, atol=1e-14)
    assert np.allclose(system.q0[:n] - rest[:n], s.U, atol=1e-14)
    assert np.allclose(system.v0, np.concatenate([s.U_dot, s.theta_dot]), atol=1e-14)
    assert np.abs(system.q0[n:] - rest[n:])[:20].max() < 1e-6  # far from the pulse: the rest state


@pytest.mark.parametrize("amplitude,center,match", [(-0.38, 8, "not uniform"), (-0.2, 50, "-0.34[67] to -0.40")])
def test_bad_launches_are_reported(amplitude, center, match):
    with pytest.raises(SceneError, match=match):
        build_problem(_scene(amplitude, center))


def test_from_rest_subtracts_the_stored_rest_state_and_never_rebuilds_the_model():
    import xarray as xr

    from flexmm.analysis.features.rest import RestStateMissing

    scene = _scene()
    system = build_problem(scene).system
    n, a = system.n_sites, LATTICE["a_m"]
    q = system.rest_state
    fields = {"u": (("time", "site"), np.tile(q[:n] * a, (2, 1)), {"units": "m", "reference": "absolute"}),
              "theta": (("time", "site"), np.tile(q[n:], (2, 1)), {"units": "rad", "reference": "absolute"})}
    coords = {"time": [0.0, 1.0], "site": np.arange(n), "x": ("site", np.arange(n) * a)}
    rest = {"u_rest": ("site", q[:n] * a), "theta_rest": ("site", q[n:])}
    config = {"name": "t", "lattice": LATTICE, "solver": {"duration_s": 1e-3}}
    ds = xr.Dataset(fields, coords={**coords, **rest})
    moved = from_rest(ds, rest_fields(RunContext("rotating_squares_chain", config, ds)))
    assert np.abs(moved["theta"].values).max() < 1e-15 and np.abs(moved["u"].values).max() < 1e-15
    assert moved["theta"].attrs["reference"] == "rest_state"
    assert np.allclose(moved["x"].values, ds["x"].values + q[:n] * a)
    old = xr.Dataset(fields, coords=coords)  # written before datasets stored the rest state
    with pytest.raises(RestStateMissing, match="run the scene again"):
        rest_fields(RunContext("rotating_squares_chain", config, old))
    plain = RunContext("rotating_squares_chain", {**config, "lattice": {**LATTICE, "predeform": None}}, old)
    assert rest_fields(plain) is None and from_rest(ds, None) is ds
