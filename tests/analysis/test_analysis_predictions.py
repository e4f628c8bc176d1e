"""Theory registry: predictions read from a run's config, checked on synthetic runs built from
the same theory (so measured = predicted up to the extraction error), and the generic Bloch
dispersion against the closed form of docs/physics.md §1.4."""

from __future__ import annotations

import math

import numpy as np
import pytest
import xarray as xr
from conftest import LEGO_CHAIN

from flexmm.analysis import analyze_run
from flexmm.analysis.report.export import write_dataset
from flexmm.analysis.report.theory_comparison import RunContext, bands_for, theory_for
from flexmm.config import scene_from_dict
from flexmm.config.lattice import RotatingSquaresChain
from flexmm.io.provenance import config_text
from flexmm.linalg import bloch_frequencies
from flexmm.linear.dispersion import band_edges_numeric, chain_cell
from flexmm.models import MODELS
from flexmm.models.rotating_chain import nondimensional
from flexmm.theory import chains as th
from flexmm.theory import rotating as rt


def _write_run(path, scene, fields: dict, time, x):
    ds = xr.Dataset({k: (("time", "site"), v, {"units": u}) for k, (v, u) in fields.items()},
                    coords={"time": ("time", time, {"units": "s"}), "x": ("site", x, {"units": "m"})},
                    attrs={"model": scene.lattice.kind, "config": config_text(scene),
                           "spacing_m": float(x[1] - x[0])})
    path.mkdir(parents=True)
    ds.to_netcdf(path / "dataset.nc", engine="h5netcdf")
    return path


def _mass_chain(bond, onsite=(), damping=None, excitation=None):
    cfg = {"name": "synthetic", "lattice": {"kind": "mass_chain", "n_units": 200, "spacing_m": 0.01, "mass_kg": 0.01,
                                             "bond": bond, "onsite": list(onsite)},
           "solver": {"duration_s": 1.0}}
    if damping:
        cfg["damping"] = damping
    if excitation:
        cfg["excitation"] = excitation
    return scene_from_dict(cfg)


def test_softening_chain_sech2_wave(tmp_path):
    k1, k2, Dm, a, m = 100.0, 5.0e4, 2e-4, 0.01, 0.01
    scene = _mass_chain({"law": "polynomial", "k1_n_per_m": k1, "k2_n_per_m2": k2})
    wave = th.softening_solitary_wave(k1, k2, Dm, m, a)
    n = np.arange(200)
    t = np.linspace(0, 150 * a / wave.v, 601)
    strain = wave.profile(n[None, :] - 20, t[:, None]) / a  # D/a, sites
    u = np.concatenate([np.zeros((t.size, 1)), np.cumsum(strain, axis=1)[:, :-1] * a], axis=1)
    run = _write_run(tmp_path / "soft", scene, {"u": (u, "m")}, t, n * a)
    res = analyze_run(run, field_spec="strain")
    rows = {c.quantity: c for c in res.comparisons if c.item == "pulse 0"}
    assert res.pulses[0].polarity == 1  # tensile: a rarefaction soliton
    assert abs(rows["speed"].rel_diff) < 2e-3
    assert abs(rows["width W (sech² fit)"].rel_diff) < 5e-3


def test_bistable_front_prediction_and_default_analysis(tmp_path):
    alpha, beta, L, k, m, a, eta = 2.6667e4, 0.3, 0.01, 100.0, 0.01, 0.01, 0.08
    scene = _mass_chain({"law": "linear", "k_n_per_m": k},
                        [{"law": "bistable_cubic", "alpha_n_per_m3": alpha, "beta": beta, "jump_m": L}],
                        {"viscous": {"coefficient_n_s_per_m": eta}})
    fr = th.bistable_front(alpha, beta, L, k, m, a, eta)
    x = np.arange(200) * a
    t = np.linspace(0, 2.0 / fr.v, 401)
    u = fr.profile(x[None, :] + 0.3, t[:, None])  # u = L behind the front, 0 ahead; enters from x < 0
    u = u - u[0]
    run = _write_run(tmp_path / "front", scene, {"u": (u, "m")}, t, x)
    ctx = RunContext.from_dataset(xr.load_dataset(run / "dataset.nc", engine="h5netcdf"))
    assert theory_for(ctx).analysis(ctx) == "front"
    res = analyze_run(run)  # auto: a front
    rows = {c.quantity: c for c in res.comparisons}
    assert res.kind == "front"
    assert abs(rows["speed"].rel_diff) < 2e-3
    assert abs(rows["width 10–90 %"].rel_diff) < 0.02
    ana = xr.load_dataset(write_dataset(res), engine="h5netcdf")
    assert float(ana["front_speed_m_s"][0]) == pytest.approx(fr.v, rel=2e-3)
    assert np.isfinite(ana["switch_time"].values).sum() > 100 and ana.attrs["analysis"] == "front"


def test_rotating_chain_strain_pulse_rides_on_theta_soliton(tmp_path, lego_config):
    cfg = dict(lego_config, excitation={"kind": "soliton", "amplitude_rad": 0.4, "center_site": 20})
    cfg["lattice"] = dict(cfg["lattice"], n_units=160, left="free")
    scene = scene_from_dict(cfg)
    lat = scene.lattice
    nd = nondimensional(lat)
    p = rt.RotatingChainND(0.0, nd["Ks"], nd["Ktheta"], nd["alpha2"], 1, 0)
    T = math.sqrt(lat.mass_kg / lat.k_long_n_per_m)
    c = float(rt.soliton_speed(p, 0.4))
    t = np.linspace(0, 110 / c * T, 301)
    x = np.arange(160) * lat.a_m
    zeta = (x[None] / lat.a_m - 20 - c * t[:, None] / T)
    theta, up = (v.reshape(zeta.shape) for v in rt.exact_soliton(p, 0.4, zeta.ravel()))
    u = np.concatenate([np.zeros((t.size, 1)), np.cumsum(up, axis=1)[:, :-1] * lat.a_m], axis=1)
    run = _write_run(tmp_path / "vec", scene, {"theta": (theta, "rad"), "u": (u, "m")}, t, x)
    res = analyze_run(run, field_spec="strain")
    rows = {c.quantity: c for c in res.comparisons if c.item == "pulse 0"}
    assert "vector soliton" in rows["speed"].note
    assert abs(rows["speed"].rel_diff) < 2e-3
    assert abs(rows["amplitude"].rel_diff) < 0.02  # sampled bond strain vs continuum peak


@pytest.mark.parametrize("theta0, n_v, s_v", [(0.0, 1, 0), (0.3, 1, 1), (-0.2, 2, 1), (0.25, 0, 0)])
def test_bloch_dispersion_from_the_hessian_matches_the_closed_form(theta0, n_v, s_v):
    cfg = RotatingSquaresChain(**dict(LEGO_CHAIN, n_units=24, theta0_rad=theta0, n_lateral=n_v,
                                      lateral_stretch=bool(s_v)))
    system = MODELS[cfg.kind].build(cfg)
    nd = nondimensional(cfg)
    p = rt.RotatingChainND(theta0, nd["Ks"], nd["Ktheta"], nd["alpha2"], n_v, s_v)
    q = np.linspace(0, math.pi, 17)
    w = bloch_frequencies(chain_cell(system), q)
    lo, hi = rt.dispersion_chain(p, q)
    assert np.allclose(w[:, 0], lo, atol=1e-8) and np.allclose(w[:, 1], hi, atol=1e-8)
    edges = band_edges_numeric(system)
    assert edges[1][1] == pytest.approx(rt.omega_max_chain(p), rel=1e-6)


def test_generic_bands_for_a_model_without_a_formula(lego_config):
    chain = _mass_chain({"law": "linear", "k_n_per_m": 100.0}, [{"law": "linear", "k_n_per_m": 30.0}])
    ctx = RunContext(model="mass_chain", config=chain.model_dump(mode="json"))
    (lo, hi), = bands_for(ctx)
    assert lo == pytest.approx(math.sqrt(30.0 / 0.01) / (2 * math.pi), rel=1e-6)
    assert hi == pytest.approx(math.sqrt((30.0 + 400.0) / 0.01) / (2 * math.pi), rel=1e-6)
