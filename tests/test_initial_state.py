"""Initial states of any shape (scene.initial): safe expressions, tables, launchers, pins, --from."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
import yaml
from typer.testing import CliRunner

from flexmm.analysis.report import analyze as report
from flexmm.api import run_scene
from flexmm.assemble import build_system
from flexmm.cli import app
from flexmm.config import ConfigError, load_scene, scene_from_dict
from flexmm.config.initial import evaluate, parse_expression

TODA = {"kind": "mass_chain", "n_units": 300, "spacing_m": 0.01, "mass_kg": 0.01,
        "bond": {"law": "toda", "a_n": 1.0, "b_per_m": 100.0}}


@pytest.mark.parametrize("text", [
    "__import__('os').system('true')", "x.__class__", "open('/etc/passwd')", "(lambda: 1)()",
    "[1, 2]", "'text'", "exp", "y2 + 1", "tanh(x, out=x)", "x; 1", "getattr(x, 'real')", "True",
    "{1: 2}", "x[0]", "f'{x}'", "1" * 3000,
])
def test_expression_language_rejects_unsafe_or_unknown_input(text):
    with pytest.raises(ValueError):
        parse_expression(text)


def test_expressions_evaluate_with_numpy_on_every_site():
    n = np.arange(6.0)
    x = 0.1 * n
    assert np.allclose(evaluate("0.5 * sech((x - 0.2) / 0.1) ** 2", 6, x=x, n=n),
                       0.5 / np.cosh((x - 0.2) / 0.1) ** 2)
    assert np.array_equal(evaluate("1 if n < 2 else -1", 6, x=x, n=n), [1, 1, -1, -1, -1, -1])
    assert np.array_equal(evaluate("where(n >= 4, 2, 0) + 1", 6, x=x, n=n), [1, 1, 1, 1, 3, 3])
    assert np.allclose(evaluate("-pi", 6, x=x, n=n), -math.pi)
    with pytest.raises(ValueError, match="not finite"):
        evaluate("1 / (n - 3)", 6, x=x, n=n)


def test_bad_expression_is_a_config_error_with_file_line_and_field(tmp_path):
    f = tmp_path / "bad.yaml"
    f.write_text(yaml.safe_dump({"name": "bad", "lattice": TODA, "solver": {"duration_s": 0.1},
                                 "initial": {"fields": [{"field": "u", "value": "__import__('os')"}]}},
                                sort_keys=False))
    with pytest.raises(ConfigError) as err:
        load_scene(f)
    msg = str(err.value)
    assert "bad.yaml:" in msg and "initial.fields.0.value" in msg and "not allowed" in msg


def test_fields_from_expressions_and_a_table_relative_to_the_config(tmp_path):
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "rate.csv").write_text("x,value,rate\n0.0,0.0,0.0\n2.99,0.0,2.99\n")
    cfg = {"name": "fields", "lattice": TODA, "solver": {"duration_s": 0.1},
           "initial": {"fields": [{"field": "u", "value": "1e-3 * tanh((x - 1.5) / 0.1)"},
                                  {"field": "u", "table": "rate.csv"}]}}
    f = tmp_path / "sub" / "scene.yaml"
    f.write_text(yaml.safe_dump(cfg))
    system, _ = build_system(load_scene(f))
    x = np.arange(300) * 0.01
    sc = system.scales
    assert np.allclose(system.q0[:300] * sc.length_m, 1e-3 * np.tanh((x - 1.5) / 0.1))
    assert np.allclose(system.v0[:300] * sc.velocity, x)  # the table's rate, interpolated in x


def test_launched_toda_soliton_runs_at_its_exact_speed_and_keeps_the_theory_comparison(tmp_path):
    """κ = 1: speed sqrt(ab/m) sinh κ/κ sites per unit time (docs/physics.md §2), within 0.3 %."""
    sc = scene_from_dict({"name": "toda_launch", "lattice": TODA, "solver": {"duration_s": 1.5},
                          "initial": {"launch": [{"kind": "toda_soliton", "kappa": 1.0, "center_site": 40}]}})
    res = report.analyze_run(run_scene(sc, run_dir=tmp_path / "toda").path)
    (p,) = res.pulses
    exact = math.sqrt(1.0 * 100.0 / 0.01) * math.sinh(1.0) * 0.01  # m/s
    assert p.speed_m_s == pytest.approx(exact, rel=3e-3)
    # exact amplitude r_max = −ln(1 + sinh²κ)/b, as strain r/a
    assert p.amplitude == pytest.approx(-math.log(math.cosh(1.0) ** 2) / 100.0 / 0.01, rel=0.03)
    speed = next(c for c in res.comparisons if c.item == "pulse 0" and c.quantity == "speed")
    assert speed.predicted is not None and abs(speed.rel_diff) < 0.01  # still compared with theory


def test_pinned_site_stays_fixed_while_its_neighbours_move(tmp_path):
    sc = scene_from_dict({"name": "pinned", "lattice": {**TODA, "n_units": 60},
                          "excitation": {"kind": "impact", "velocity_m_s": 0.5},
                          "initial": {"pinned": [{"field": "u", "sites": [30]}]},
                          "solver": {"duration_s": 0.5}, "output": {"n_frames": 51}})
    ds = xr.load_dataset(run_scene(sc, run_dir=tmp_path / "pin").path)
    u = ds["u"].values
    assert np.ptp(u[:, 30]) == 0.0 and np.ptp(u[:, 29]) > 1e-4


def test_pinned_static_kink_is_held(tmp_path):
    """A kink centred on a site is a saddle; pinning that site holds it (bistable chain, §2)."""
    lat = {"kind": "mass_chain", "n_units": 80, "spacing_m": 0.01, "mass_kg": 0.01,
           "bond": {"law": "linear", "k_n_per_m": 100.0},
           "onsite": [{"law": "bistable_cubic", "alpha_n_per_m3": 2e5, "beta": 0.5, "jump_m": 0.01}]}
    sc = scene_from_dict({"name": "kink", "lattice": lat, "solver": {"duration_s": 2.0},
                          "initial": {"launch": [{"kind": "tanh_front", "center_site": 40, "speed": "static"}],
                                      "pinned": [{"field": "u", "sites": [40]}]}})
    ds = xr.load_dataset(run_scene(sc, run_dir=tmp_path / "kink").path)
    u = ds["u"].values
    assert np.ptp(u[:, 40]) == 0.0 and u[0, 40] == pytest.approx(0.005, rel=1e-9)
    # the kink stays: the left part in the upper well (L = 0.01 m), the right part in the lower one
    # (w = sqrt(8 k a²/(α L²)) = 6.3 sites)
    assert np.all(u[:, :30] > 0.0095) and np.all(u[:, 51:] < 0.0005)


def test_from_continues_a_run_from_its_last_frame(tmp_path):
    cfg = {"name": "a", "lattice": TODA, "solver": {"duration_s": 0.3},
           "initial": {"launch": [{"kind": "toda_soliton", "kappa": 1.0, "center_site": 40}]}}
    f = tmp_path / "a.yaml"
    f.write_text(yaml.safe_dump(cfg))
    runner = CliRunner()
    r = runner.invoke(app, ["run", str(f), "--out", str(tmp_path / "a"), "-q"])
    assert r.exit_code == 0, r.output
    r = runner.invoke(app, ["run", str(f), "--from", str(tmp_path / "a"), "--set", "initial.launch=[]",
                            "--out", str(tmp_path / "b"), "-q"])
    assert r.exit_code == 0, r.output
    a = xr.load_dataset(tmp_path / "a" / "dataset.nc")
    b = xr.load_dataset(tmp_path / "b" / "dataset.nc")
    assert np.array_equal(a["u"].values[-1], b["u"].values[0])
    assert np.array_equal(a["u_dot"].values[-1], b["u_dot"].values[0])
    assert yaml.safe_load(b.attrs["config"])["initial"]["from_run"] == str((tmp_path / "a").resolve())
    assert "last frame of" in (Path(tmp_path / "b") / "run.log").read_text()


def test_from_keeps_the_positions_when_the_runs_rest_states_differ(tmp_path):
    """Mass chains measure u from their rest state (the relaxed start), which each dataset stores:
    continuing in a chain started in the lower well from a run that rested in the upper well
    (L = 0.01 m) keeps the masses where they were (u = L, at rest), not at u = 0 of the new chain."""
    lat = {"kind": "mass_chain", "n_units": 20, "spacing_m": 0.01, "mass_kg": 0.01,
           "bond": {"law": "linear", "k_n_per_m": 100.0},
           "onsite": [{"law": "bistable_cubic", "alpha_n_per_m3": 2e5, "beta": 0.5, "jump_m": 0.01}],
           "initial_displacement_m": 0.0099}
    a = scene_from_dict({"name": "upper", "lattice": lat, "solver": {"duration_s": 0.05}, "output": {"n_frames": 3}})
    ds_a = xr.load_dataset(run_scene(a, run_dir=tmp_path / "a").path)
    assert np.allclose(ds_a["u_rest"].values, 0.01, atol=1e-9) and np.allclose(ds_a["u"].values, 0.0, atol=1e-9)
    b = scene_from_dict({"name": "lower", "lattice": {**lat, "initial_displacement_m": 0.0},
                         "initial": {"from_run": str(tmp_path / "a")}, "solver": {"duration_s": 0.05},
                         "output": {"n_frames": 3}})
    ds_b = xr.load_dataset(run_scene(b, run_dir=tmp_path / "b").path)
    assert np.allclose(ds_b["u_rest"].values, 0.0) and ds_b["u"].attrs["reference"] == "rest_state"
    np.testing.assert_allclose(ds_b["u"].values, 0.01, atol=1e-9)  # where run a left them, and static


@pytest.mark.parametrize("direction", [1, -1])
def test_launched_sech2_pulse_keeps_its_shape_and_long_wave_speed(tmp_path, direction):
    """W = 5 sites, D_m = 0.05 a: v − c0 within 3 % of the long-wave law (docs/physics.md §2; the
    discrete wave differs at O(1/W²)), W and D_m within 1 %; it moves the way it was launched."""
    k1, a, m, strain, W = 100.0, 0.01, 0.01, 0.05, 5.0
    k2 = k1 / (2 * W * W * strain * a)
    sc = scene_from_dict({
        "name": "sech2", "solver": {"duration_s": 2.0},
        "lattice": {"kind": "mass_chain", "n_units": 300, "spacing_m": a, "mass_kg": m,
                    "bond": {"law": "polynomial", "k1_n_per_m": k1, "k2_n_per_m2": k2}},
        "initial": {"launch": [{"kind": "sech2_pulse", "strain": strain, "direction": direction,
                                "center_site": 50 if direction > 0 else 249}]}})
    (p,) = report.analyze_run(run_scene(sc, run_dir=tmp_path / "sech2").path).pulses
    c0 = a * math.sqrt(k1 / m)
    v = c0 * math.sqrt(1 + 2 * k2 * strain * a / (3 * k1))
    assert p.direction == direction
    assert (p.speed_m_s - c0) / (v - c0) == pytest.approx(1.0, abs=0.06)
    assert p.width_sech2_m == pytest.approx(W * a, rel=0.01) and p.amplitude == pytest.approx(strain, rel=0.01)


def test_launch_on_the_wrong_chain_is_a_config_error_and_a_cli_user_error(tmp_path):
    f = tmp_path / "wrong.yaml"
    f.write_text(yaml.safe_dump({
        "name": "wrong", "solver": {"duration_s": 0.1},
        "lattice": {**TODA, "bond": {"law": "linear", "k_n_per_m": 100.0}},
        "initial": {"launch": [{"kind": "toda_soliton", "kappa": 1.0, "center_site": 40}]}}, sort_keys=False))
    with pytest.raises(ConfigError, match="wrong.yaml:.*toda bond"):
        load_scene(f)
    r = CliRunner().invoke(app, ["run", str(f), "--out", str(tmp_path / "w")])
    assert r.exit_code == 2 and "toda bond" in r.output and "Traceback" not in r.output


def test_rotation_field_of_a_rotating_squares_chain_from_an_expression(lego_config):
    lego_config["initial"] = {"fields": [{"field": "theta", "value": "0.1 * sech((x - 1.0) / 0.05)",
                                          "rate": "where(n == 3, 2.0, 0)"}]}
    lego_config["excitation"] = {"kind": "none"}
    lego_config["lattice"]["left"] = "free"
    system, _ = build_system(scene_from_dict(lego_config))
    sl = slice(system.field_index("theta") * system.n_sites, (system.field_index("theta") + 1) * system.n_sites)
    x = np.arange(system.n_sites) * lego_config["lattice"]["a_m"]
    assert np.allclose(system.q0[sl], 0.1 / np.cosh((x - 1.0) / 0.05))  # radians are not scaled
    rate = system.v0[sl] / system.scales.time_s  # rad/s
    assert rate[3] == pytest.approx(2.0) and np.count_nonzero(rate) == 1


def test_launched_damped_front_runs_at_its_predicted_speed(tmp_path):
    """The tanh front of a damped bistable_cubic chain (w = 14 sites) launched at its predicted
    speed keeps it (docs/physics.md §2): speed within 1 %, carried kinetic energy within 2 %."""
    from flexmm.analysis.report.summary import principal
    from flexmm.theory.chains import bistable_front

    sc = scene_from_dict({
        "name": "front", "solver": {"duration_s": 1.5},
        "lattice": {"kind": "mass_chain", "n_units": 300, "spacing_m": 0.01, "mass_kg": 0.01,
                    "bond": {"law": "linear", "k_n_per_m": 100.0},
                    "onsite": [{"law": "bistable_cubic", "alpha_n_per_m3": 2e4, "beta": 0.25, "jump_m": 0.01}]},
        "damping": {"viscous": {"coefficient_n_s_per_m": 0.05}},
        "initial": {"launch": [{"kind": "tanh_front", "center_site": 60}]}})
    res = report.analyze_run(run_scene(sc, run_dir=tmp_path / "front").path)
    item, f = principal(res)
    assert f.speed_m_s == pytest.approx(bistable_front(2e4, 0.25, 0.01, 100.0, 0.01, 0.01, 0.05).v, rel=0.01)
    assert not f.arrested and f.n_switched > 90
    k = next(c for c in res.comparisons if c.item == item and c.quantity == "kinetic energy")
    assert abs(k.rel_diff) < 0.02


def test_seeded_random_fields_are_frozen_noise_per_site(lego_config):
    """``normal(seed)``/``random(seed)``: numpy's default generator seeded with the integer (the
    documented contract), one value per site in site order: reproducible, independent between
    seeds, a site's value independent of the chain's length, and the right statistics."""
    n = np.arange(20000.0)
    z = evaluate("normal(7)", n.size, n=n)
    assert np.array_equal(z, np.random.default_rng(7).standard_normal(n.size))
    assert np.array_equal(evaluate("normal(7)", 50, n=n[:50]), z[:50])
    assert abs(z.mean()) < 4 / math.sqrt(n.size) and abs(z.std() - 1) < 0.03
    w = evaluate("random(8)", n.size, n=n)
    assert w.min() >= 0 and w.max() < 1 and abs(w.mean() - 0.5) < 0.01
    assert abs(np.corrcoef(z, evaluate("normal(8)", n.size, n=n))[0, 1]) < 0.03
    lego_config["initial"] = {"fields": [{"field": "theta", "value": "1e-3 * normal(7)", "rate": "2 * random(1)"}]}
    lego_config["excitation"] = {"kind": "none"}
    lego_config["lattice"]["left"] = "free"
    system, _ = build_system(scene_from_dict(lego_config))
    k = system.field_index("theta") * system.n_sites
    theta = system.q0[k : k + system.n_sites]
    assert np.array_equal(theta, 1e-3 * np.random.default_rng(7).standard_normal(system.n_sites))
    assert np.allclose(system.v0[k : k + system.n_sites] / system.scales.time_s,
                       2 * np.random.default_rng(1).random(system.n_sites), rtol=1e-14, atol=0)


@pytest.mark.parametrize("text", ["normal(1.5)", "normal(x)", "random()", "random(-1)", "normal(1, 2)",
                                  "random(seed=1)", "normal"])
def test_random_field_needs_one_integer_seed(text):
    with pytest.raises(ValueError, match="seed|must be called"):
        parse_expression(text)
