"""solver.accuracy: integrator and dt from a pilot, checked by step doubling (flexmm.accuracy);
planning itself runs nothing, and a run builds its model once."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import DEMO_AS_LEGO_SCENE_SETS, LEGO_CHAIN

from flexmm.accuracy import Trace, quantity_error, state_error, trace
from flexmm.api import run_scene
from flexmm.config import load_scene, scene_from_dict
from flexmm.integrators import INTEGRATORS
from flexmm.io.run_dataset import open_run
from flexmm.plan import make_plan
from flexmm.prepare import prepare

LEGO = LEGO_CHAIN


def soliton_scene(accuracy=1e-4, **solver):
    return scene_from_dict({"name": "acc", "lattice": {**LEGO, "n_units": 120},
                            "excitation": {"kind": "soliton", "amplitude_rad": 0.4, "center_site": 30},
                            "solver": {"duration_s": 0.06, "accuracy": accuracy, **solver},
                            "output": {"n_frames": 11}})


def test_state_error_relative_to_each_fields_peak():
    class S:
        n_sites = 3
        fields = (1, 2)

    q = np.array([1.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    r = np.array([1.0, 0.1, 0.0, 0.0, 0.0, 0.0])
    assert state_error(S, q, r, np.array([2.0, 0.0])) == pytest.approx(0.05)


def _sech2_trace(speed: float, amp: float, n_sites: int = 200, width: float = 4.0, n_t: int = 400) -> Trace:
    """|q| of a sech² pulse entering a line of sites at ``speed`` sites per unit time."""
    t = np.linspace(0.0, 1.0, n_t + 1)[:, None]
    x = amp / np.cosh((np.arange(n_sites)[None, :] + 3 * width - speed * n_sites * t) / width) ** 2
    x0 = x[:1]
    return Trace(np.abs(x - x0)[:, None, :], 1.0 / n_t, n_t)


@pytest.mark.parametrize("eps", [1e-3, -3e-4])
def test_quantity_error_of_a_pulse_is_its_relative_speed_error(eps):
    """A pulse faster by δc/c arrives at every site earlier by t δc/(c + δc): e_c = |δc/c| (to first order)."""
    ref, a = _sech2_trace(0.8, 0.4), _sech2_trace(0.8 * (1 + eps), 0.4)
    err = quantity_error(a, ref)
    assert err.speed == pytest.approx(abs(eps) / (1 + eps), rel=0.05)
    assert err.amplitude < 0.1 * abs(eps)  # the sampled peaks differ only by where the samples fall


def test_quantity_error_of_a_pulse_is_its_relative_amplitude_error():
    ref, a = _sech2_trace(0.8, 0.4), _sech2_trace(0.8, 0.4 * (1 + 2e-3))
    err = quantity_error(a, ref)
    assert err.amplitude == pytest.approx(2e-3, rel=0.05)
    assert err.speed < 2e-4  # a larger pulse crosses half the reference's peak slightly sooner


def _window_error(prob, spec, h: float, t_end: float, refine: int = 16):
    """Error of the reported quantities of steps h against steps h/refine over [0, t_end]."""
    n = max(1, round(t_end / h))
    return quantity_error(trace(prob, spec, n, t_end, n), trace(prob, spec, n * refine, t_end, n))


def test_accuracy_run_meets_its_target(tmp_path):
    sc = soliton_scene(1e-4, integrator="velocity_verlet")  # one method: keeps the test quick
    plan = make_plan(sc, "full")
    assert plan.step("accuracy").action == "pending" and plan.choice is None  # planning runs nothing
    prob = prepare(plan)
    assert plan.scene.solver.accuracy is None and plan.scene.solver.dt_s is not None
    assert plan.step("accuracy").action == "chosen"
    res = run_scene(sc, run_dir=tmp_path)
    ds = open_run(res.path)
    assert ds.attrs["accuracy_requested"] == 1e-4
    assert ds.attrs["accuracy_estimate"] < 1e-4 and ds.attrs["accuracy_met"] == 1
    # against a tight reference over the window the estimate covers
    spec = INTEGRATORS[plan.choice.integrator]
    err = _window_error(prob, spec, plan.choice.dt, ds.attrs["accuracy_window_s"] / prob.system.scales.time_s)
    assert err.total < 1e-4
    assert ds.attrs["accuracy_estimate"] == pytest.approx(err.total, rel=0.5)


@pytest.mark.slow
def test_accuracy_picks_the_cheapest_method():
    """At 1e-7 a fourth-order method beats Verlet; the choice still meets the target."""
    plan = make_plan(soliton_scene(1e-7), "full")
    prob = prepare(plan)
    table = {r["integrator"]: r for r in plan.choice.table}
    assert "velocity_verlet" in table and len(table) >= 2
    assert plan.choice.integrator != "velocity_verlet"
    assert plan.choice.cost == min(r["cost"] for r in table.values())
    spec = INTEGRATORS[plan.choice.integrator]
    assert _window_error(prob, spec, plan.choice.dt, plan.choice.pilot_time, refine=8).total < 1e-7


def test_accuracy_with_an_explicit_dt_honours_it():
    plan = make_plan(soliton_scene(1e-4, dt_s=1e-6))
    assert plan.scene.solver.dt_s == 1e-6 and "honoured" in " ".join(plan.step("accuracy").notes)


def test_a_run_builds_its_model_once(tmp_path, monkeypatch):
    """Plan (which builds to linearise), run and summary together build the lattice once."""
    from flexmm.models import rotating_chain

    build = rotating_chain.build  # what MODELS["rotating_squares_chain"] builds with
    calls = []

    def counting(cfg):
        calls.append(cfg.n_units)
        return build(cfg)

    monkeypatch.setattr(rotating_chain, "build", counting)
    # the demo's impact on 200 units (a longer chain's plan also builds the bands' 256-unit copy)
    demo = load_scene(Path(__file__).resolve().parents[2] / "configs" / "lego_vector_soliton.yaml",
                      DEMO_AS_LEGO_SCENE_SETS)
    assert run_scene(demo, run_dir=tmp_path / "demo", fidelity="auto").ok
    assert len(calls) == 1, calls  # not trimmed: the plan's build runs
    calls.clear()
    assert run_scene(soliton_scene(1e-4, integrator="velocity_verlet"), run_dir=tmp_path / "acc").ok
    assert len(calls) == 1, calls  # the accuracy pilots reuse it too
