"""Error control (solver.accuracy, default target): the run meets it or says it does not."""

from __future__ import annotations

import pytest

from flexmm.accuracy import quantity_error, stable_step, trace
from flexmm.assemble import build_problem
from flexmm.config import load_scene
from flexmm.config.scene import DEFAULT_ACCURACY
from flexmm.integrators import INTEGRATORS
from flexmm.plan import make_plan
from flexmm.prepare import prepare

# held out: the amplitude-gap chain struck ten times harder (10 m/s, 1000 rad/s)
STRUCK = ["excitation.velocity_m_s=10", "excitation.angular_velocity_rad_s=1000", "lattice.n_units=100",
          "solver.duration_s=0.1", f"solver.accuracy={DEFAULT_ACCURACY}"]


@pytest.mark.slow
def test_error_control_on_a_strongly_struck_chain_meets_its_target() -> None:
    """The held-out case: the old default's rotation amplitude is far off; the default target is met."""
    old = build_problem(load_scene("configs/b_lego_amplitude_gap.yaml", STRUCK + ["solver.accuracy=null"]))
    pefrl, verlet = INTEGRATORS["pefrl"], INTEGRATORS["velocity_verlet"]
    plan = make_plan(load_scene("configs/b_lego_amplitude_gap.yaml", STRUCK), "full")
    new = prepare(plan)
    T = plan.choice.pilot_time  # the window the estimate covers
    h_ref = stable_step(old, pefrl) / 400
    n_old = max(1, round(T / old.dt))
    err_old = quantity_error(trace(old, verlet, n_old, T, n_old), trace(old, pefrl, n_old * max(1, round(old.dt / h_ref)), T, n_old))  # converged
    assert err_old.total > 30 * DEFAULT_ACCURACY  # what the old default (Verlet at 0.1 x the stable step) gave

    spec = INTEGRATORS[plan.choice.integrator]
    n = max(1, round(T / new.dt))
    err = quantity_error(trace(new, spec, n, T, n), trace(new, pefrl, n * max(1, round(new.dt / h_ref)), T, n))
    assert err.total < DEFAULT_ACCURACY
    attrs = plan.attrs()
    assert attrs["accuracy_requested"] == DEFAULT_ACCURACY and attrs["accuracy_met"] == 1
    assert attrs["accuracy_check"].startswith("step doubling")
    assert err.total / 10 < attrs["accuracy_estimate"] < 10 * max(err.total, 1e-6)  # the estimate is informative


def test_explicit_step_is_honoured_and_checked(tmp_path) -> None:
    from flexmm.api import run_scene
    from flexmm.io.run_dataset import open_run

    scene = load_scene("configs/b_lego_amplitude_gap.yaml", STRUCK + ["solver.dt_s=2.5e-5", "solver.integrator=pefrl"])
    res = run_scene(scene, run_dir=tmp_path / "r", fidelity="full")
    ds = open_run(res.path)
    assert ds.attrs["dt_s"] == pytest.approx(2.5e-5, rel=1e-12) and ds.attrs["integrator"] == "pefrl"
    assert ds.attrs["plan_accuracy"] == "checked" and ds.attrs["accuracy_check"].startswith("step doubling")
    prob = build_problem(scene)
    pefrl = INTEGRATORS["pefrl"]
    T = ds.attrs["accuracy_window_s"] / prob.system.scales.time_s
    n = max(1, round(T / prob.dt))
    err = quantity_error(trace(prob, pefrl, n, T, n), trace(prob, pefrl, 8 * n, T, n)).total
    assert err / 3 < ds.attrs["accuracy_estimate"] < 3 * err
    assert ds.attrs["accuracy_met"] == int(ds.attrs["accuracy_estimate"] <= DEFAULT_ACCURACY)
    assert res.accuracy["accuracy_estimate"] == ds.attrs["accuracy_estimate"]


def test_cli_prints_the_estimate_and_strict_fails_a_miss(tmp_path) -> None:
    from typer.testing import CliRunner

    from flexmm.cli import app

    args = ["run", "configs/b_lego_amplitude_gap.yaml", "--fidelity", "full", "--set", "lattice.n_units=40",
            "--set", "solver.duration_s=0.02", "--set", "output.n_frames=201", "--set", "solver.dt_s=1e-4",
            "--set", "solver.accuracy=5e-6",
            "--out", str(tmp_path / "r")]
    res = CliRunner().invoke(app, args)  # the estimate (~1.7e-5) misses 5e-6, by less than 10x: a warning
    assert res.exit_code == 0, res.output
    assert "error estimate:" in res.output and "exceeds the target" in res.output
    res = CliRunner().invoke(app, args + ["--strict"])
    assert res.exit_code == 3


def test_accuracy_null_keeps_the_old_rules() -> None:
    plan = make_plan(load_scene("configs/b_lego_amplitude_gap.yaml", STRUCK + ["solver.accuracy=null"]), "full")
    prob = prepare(plan)
    assert plan.choice is None and plan.step("accuracy") is None
    per = plan.frames.steps_per_frame  # 0.1 of the stable step, shortened to land on the frames
    assert 0.1 * prob.stable_dt * (1 - 1 / per) < prob.dt <= 0.1 * prob.stable_dt
    assert prob.dt * prob.system.scales.time_s * per == pytest.approx(plan.frames.interval_s, rel=1e-12)
