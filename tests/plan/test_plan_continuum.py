"""Continuum predictions, the continuum fidelity and the front shooting (flexmm.plan.continuum, fronts)."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import LEGO_CHAIN

from flexmm.api import run_scene
from flexmm.assemble import build_problem
from flexmm.config import scene_from_dict
from flexmm.plan.continuum import NeedsAmplitude, NoContinuum, predict
from flexmm.plan.fronts import solve_front
from flexmm.theory.chains import bistable_front

LEGO = LEGO_CHAIN


def soliton_scene(n=200, center=50, direction=1, duration=0.05):
    return scene_from_dict({"name": "sol", "lattice": {**LEGO, "n_units": n},
                            "excitation": {"kind": "soliton", "amplitude_rad": 0.4, "center_site": center,
                                           "direction": direction},
                            "solver": {"duration_s": duration}, "output": {"n_frames": 51}})


@pytest.mark.parametrize("direction", [1, -1])
def test_soliton_prediction_is_the_launched_state(direction):
    sc = soliton_scene(center=100, direction=direction)
    pred = predict(sc)
    assert pred.complete and pred.spans_many_units
    s = build_problem(sc).system
    n, sc_ = s.n_sites, s.scales
    f = pred.sample(s.site_coords["x"], 0.0)
    assert np.allclose(f["theta"], s.q0[n:], atol=1e-9)
    assert np.allclose(f["u"] / sc_.length_m, s.q0[:n], atol=1e-5)
    assert np.allclose(f["theta_dot"] * sc_.time_s, s.v0[n:], atol=1e-7)
    # the profile moves at the predicted speed
    t = 0.02
    g = pred.sample(s.site_coords["x"], t)
    shift = (np.argmax(np.abs(g["theta"])) - np.argmax(np.abs(f["theta"]))) * s.spacing_m
    assert shift == pytest.approx(direction * pred.speed_m_s * t, abs=s.spacing_m)


def test_impact_needs_the_amplitude():
    sc = scene_from_dict({"name": "i", "lattice": {**LEGO, "n_units": 50, "left": "driven"},
                          "excitation": {"kind": "impact", "velocity_m_s": 1.0}, "solver": {"duration_s": 0.01}})
    with pytest.raises(NeedsAmplitude):
        predict(sc)


def test_continuum_fidelity_writes_the_travelling_wave(tmp_path):
    from flexmm.analysis import leading_pulse
    from flexmm.io.run_dataset import open_run

    sc = soliton_scene(duration=0.3)
    res = run_scene(sc, run_dir=tmp_path, fidelity="continuum")
    assert res.ok and res.n_steps == 0
    ds = open_run(res.path)
    assert ds.attrs["plan_fidelity"] == "continuum"
    p = leading_pulse(ds, "theta")
    pred = predict(sc)
    assert p.speed_m_s == pytest.approx(pred.speed_m_s, rel=5e-3)
    assert p.amplitude == pytest.approx(0.4, rel=3e-3)  # peaks sampled on the sites


def test_front_shooting_matches_the_cubic_closed_form():
    alpha, beta, L, k, m, a, eta = 2.0, 0.25, 1.0, 1.0, 1.0, 1.0, 0.3

    def Vp(u):
        return alpha * u * (u - beta * L) * (u - L)

    fr = solve_front(Vp, k, eta / m, 0.0, +1.0)  # from u = 0 towards L
    th = bistable_front(alpha, beta, L, k, m, a, eta)
    assert fr.v == pytest.approx(th.v, rel=1e-6)
    assert fr.jump == pytest.approx(L, rel=1e-9)
    assert fr.width_10_90 == pytest.approx(2 * np.arctanh(0.8) * th.w, rel=1e-3)


def test_mass_front_prediction_and_equal_wells():
    lat = {"kind": "mass_chain", "n_units": 100, "spacing_m": 0.01, "mass_kg": 0.01,
           "bond": {"law": "linear", "k_n_per_m": 100.0},
           "onsite": [{"law": "bistable_cubic", "alpha_n_per_m3": 5e4, "beta": 0.25, "jump_m": 0.01}]}
    data = {"name": "f", "lattice": lat, "excitation": {"kind": "impact", "velocity_m_s": 1.0},
            "damping": {"viscous": {"coefficient_n_s_per_m": 0.05}}, "solver": {"duration_s": 1.0}}
    pred = predict(scene_from_dict(data))
    th = bistable_front(5e4, 0.25, 0.01, 100.0, 0.01, 0.01, 0.05)
    assert pred.complete and pred.speed_m_s == pytest.approx(th.v, rel=1e-5)
    data["lattice"]["onsite"][0]["beta"] = 0.5
    with pytest.raises(NoContinuum, match="not lower"):
        predict(scene_from_dict(data))
