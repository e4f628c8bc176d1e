"""Error control (solver.accuracy, at the recommended target): the run meets it or says it does not."""

from __future__ import annotations

import numpy as np
import pytest

from flexmm.accuracy import integrate, stable_step, state_error
from flexmm.assemble import build_problem
from flexmm.config import load_scene
from flexmm.config.scene import DEFAULT_ACCURACY
from flexmm.integrators import INTEGRATORS
from flexmm.plan import make_plan
from flexmm.prepare import prepare

# held out: the amplitude-gap chain struck ten times harder (10 m/s, 1000 rad/s)
STRUCK = ["excitation.velocity_m_s=10", "excitation.angular_velocity_rad_s=1000", "lattice.n_units=100",
          "solver.duration_s=0.1", f"solver.accuracy={DEFAULT_ACCURACY}"]


def test_error_control_on_a_strongly_struck_chain_meets_its_target() -> None:
    old = build_problem(load_scene("configs/b_lego_amplitude_gap.yaml", STRUCK + ["solver.accuracy=null"]))
    pefrl = INTEGRATORS["pefrl"]
    q_ref, _, pk_ref, _ = integrate(old, pefrl, stable_step(old, pefrl) / 400, old.duration)  # converged
    q_old, _, pk_old, _ = integrate(old, INTEGRATORS["velocity_verlet"], old.dt, old.duration)
    err_old = state_error(old.system, q_old, q_ref, np.maximum(pk_old, pk_ref))
    assert err_old > 30 * DEFAULT_ACCURACY  # what the old default (Verlet at 0.1 x the stable step) gave

    plan = make_plan(load_scene("configs/b_lego_amplitude_gap.yaml", STRUCK), "full")
    new = prepare(plan)
    q, _, pk, _ = integrate(new, INTEGRATORS[plan.choice.integrator], new.dt, new.duration)
    err = state_error(new.system, q, q_ref, np.maximum(pk, pk_ref))
    assert err < DEFAULT_ACCURACY
    attrs = plan.attrs()
    assert attrs["accuracy_requested"] == DEFAULT_ACCURACY and attrs["accuracy_met"] == 1
    assert attrs["accuracy_check"] == "pilot"
    assert err / 10 < attrs["accuracy_estimate"] < 10 * max(err, 1e-6)  # the estimate is informative
    n = new.system.n_sites  # the rotation amplitude, the quantity that was wrong
    assert np.max(np.abs(q[n:2 * n])) == pytest.approx(np.max(np.abs(q_ref[n:2 * n])), rel=DEFAULT_ACCURACY)


def test_explicit_step_is_honoured_and_checked(tmp_path) -> None:
    from flexmm.api import run_scene
    from flexmm.io.dataset import open_run

    scene = load_scene("configs/b_lego_amplitude_gap.yaml", STRUCK + ["solver.dt_s=2e-5", "solver.integrator=pefrl"])
    res = run_scene(scene, run_dir=tmp_path / "r", fidelity="full")
    ds = open_run(res.path)
    assert ds.attrs["dt_s"] == pytest.approx(2e-5, rel=1e-12) and ds.attrs["integrator"] == "pefrl"
    assert ds.attrs["plan_accuracy"] == "checked" and ds.attrs["accuracy_check"] == "step doubling"
    prob = build_problem(scene)
    pefrl = INTEGRATORS["pefrl"]
    t_end = float(ds["time"][-1]) / prob.system.scales.time_s
    q, _, pk, _ = integrate(prob, pefrl, prob.dt, t_end)
    qr, _, pkr, _ = integrate(prob, pefrl, prob.dt / 8, t_end)
    err = state_error(prob.system, q, qr, np.maximum(pk, pkr))
    assert err / 3 < ds.attrs["accuracy_estimate"] < 3 * err
    assert ds.attrs["accuracy_met"] == int(ds.attrs["accuracy_estimate"] <= DEFAULT_ACCURACY)
    assert res.accuracy["accuracy_estimate"] == ds.attrs["accuracy_estimate"]


def test_cli_prints_the_estimate_and_strict_fails_a_miss(tmp_path) -> None:
    from typer.testing import CliRunner

    from flexmm.cli import app

    args = ["run", "configs/b_lego_amplitude_gap.yaml", "--fidelity", "full", "--set", "lattice.n_units=40",
            "--set", "solver.duration_s=0.02", "--set", "solver.dt_s=1e-4", "--set", "solver.accuracy=1e-9",
            "--out", str(tmp_path / "r")]
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 0, res.output
    assert "error estimate:" in res.output and "exceeds the target" in res.output
    res = CliRunner().invoke(app, args + ["--strict"])
    assert res.exit_code == 3


def test_accuracy_null_keeps_the_old_rules() -> None:
    plan = make_plan(load_scene("configs/b_lego_amplitude_gap.yaml", STRUCK + ["solver.accuracy=null"]), "full")
    prob = prepare(plan)
    assert plan.choice is None and plan.step("accuracy") is None
    assert prob.dt == pytest.approx(0.1 * prob.stable_dt)
