"""What runs by default: PEFRL, whether the step is chosen by the pilots or set by ``solver.dt_s``.

On the old code a scene that set ``solver.dt_s`` alone ran velocity Verlet (the field's default),
so halving a default run's step changed its method and lowered its order from 4 to 2.
"""

from __future__ import annotations

import pytest

from flexmm.config import scene_from_dict
from flexmm.plan import make_plan
from flexmm.prepare import prepare


def scene(**solver):
    # a damped linear chain struck at its free end, fixed at the other: waves that bounce and decay
    return scene_from_dict({
        "name": "standing", "lattice": {"kind": "mass_chain", "n_units": 20, "spacing_m": 0.01, "mass_kg": 0.01,
                                         "bond": {"law": "linear", "k_n_per_m": 1e4}, "right": "fixed"},
        "excitation": {"kind": "impact", "end": "left", "velocity_m_s": 0.1},
        "damping": {"viscous": {"damping_ratio": 0.01}},
        "solver": {"duration_s": 0.05, **solver}, "output": {"n_frames": 11}})


def method_and_dt(sc) -> tuple[str, float]:
    plan = make_plan(sc)
    problem = prepare(plan)
    assert plan.scene.solver.integrator == problem.scene.solver.integrator  # the recorded config says what ran
    return problem.scene.solver.integrator, problem.dt * problem.system.scales.time_s


def test_halving_a_default_runs_step_keeps_its_method() -> None:
    method, dt = method_and_dt(scene())
    assert method == "pefrl"
    for factor in (1.0, 0.5):
        m, h = method_and_dt(scene(dt_s=factor * dt))
        assert m == "pefrl" and h == pytest.approx(factor * dt, rel=1e-12)


@pytest.mark.parametrize("solver, expected", [
    ({"accuracy": None}, "velocity_verlet"),  # no error control: the field's default (docs/physics.md §3)
    ({"integrator": "velocity_verlet", "dt_s": 1e-5}, "velocity_verlet"),  # named: honoured
    ({"integrator": "rk4"}, "rk4"),
])
def test_a_named_method_or_no_accuracy_target_runs_as_documented(solver, expected) -> None:
    assert method_and_dt(scene(**solver))[0] == expected
