"""From a plan to the problem that runs: build once, choose the step when accuracy is asked.

``prepare(plan)`` builds the planned scene (reusing the lattice the plan already built when only
the output changed) and, when the scene sets ``solver.accuracy``, runs the pilots of
``flexmm.accuracy`` to choose the integrator and dt; the plan's scene, steps and choice are
updated so the recorded config reproduces the run. ``accuracy_check(plan, problem)`` is the
step-doubling check after the run (``controller.run_problem(on_finish=...)``).
"""

from __future__ import annotations

from typing import Callable

from flexmm import accuracy as acc
from flexmm.assemble import Problem, build_problem
from flexmm.errors import PlanError
from flexmm.plan.planner import Plan, PlanStep, replace_section


def prepare(plan: Plan) -> Problem:
    """The problem of ``plan.scene``, built once; with ``solver.accuracy``, integrator and dt chosen."""
    problem = build_problem(plan.scene, built=plan.built_for(plan.scene))
    if plan.scene.solver.accuracy is not None:
        problem = _choose(plan, problem)
    problem.notes[:0] = plan.lines()
    return problem


def _choose(plan: Plan, problem: Problem) -> Problem:
    """Pilot runs choose integrator and dt (``accuracy.choose``); plan and problem follow the choice."""
    scene = plan.scene
    target = scene.solver.accuracy
    only = scene.solver.integrator if "integrator" in plan.source.solver.model_fields_set else None
    try:
        choice = acc.choose(problem, target, only)
    except ValueError as exc:
        raise PlanError(f"solver.accuracy: {exc}") from None
    ts = problem.system.scales.time_s
    planned = replace_section(scene, "solver", integrator=choice.integrator, dt_s=choice.dt * ts, accuracy=None)
    rows = "; ".join(f"{r['integrator']}: dt {r['dt'] * ts:.3g} s, {r['cost']:.3g} force evals"
                     for r in choice.table)
    notes = [f"accuracy {target:g}: {choice.integrator} with dt = {choice.dt * ts:.4g} s "
             f"(predicted error {choice.predicted_error:.2g}, pilot over {choice.pilot_time * ts:.3g} s) — {rows}"]
    row = next(r for r in choice.table if r["integrator"] == choice.integrator)
    if not choice.reachable:
        notes.append(f"WARNING: accuracy {target:g} looks out of reach ({row['why']}; pilot errors grow "
                     f"like t^{row['growth']:.1f}: the dynamics amplify perturbations); the run uses the "
                     "step above and the check after it reports the error reached")
    elif row["uncertain"]:
        notes.append(f"prediction uncertain: {row['uncertain']}; the check after the run reports the error reached")
    attrs = {"accuracy_integrator": choice.integrator, "accuracy_predicted_error": choice.predicted_error,
             "accuracy_pilot_s": choice.pilot_time * ts, "accuracy_reachable": int(choice.reachable)}
    plan.steps = [s for s in plan.steps if s.name != "accuracy"] + [PlanStep("accuracy", "chosen", notes, attrs)]
    plan.scene, plan.choice = planned, choice
    if choice.integrator == scene.solver.integrator:  # same method: the built problem only changes dt
        problem.scene, problem.dt, problem.notes = planned, choice.dt, []
        return problem
    return build_problem(planned)  # another method: its own stable limit and checks


def accuracy_check(plan: Plan, problem: Problem) -> Callable | None:
    """Callback for ``run_problem(on_finish=...)``: the step-doubling accuracy check, if asked."""
    if plan.accuracy is None or plan.choice is None:
        return None
    choice = plan.choice

    def on_finish(q, v, h, say, t) -> dict:
        chk = acc.check(problem, choice.integrator, h, t, q, choice.order)
        ok = chk.estimate <= plan.accuracy
        ts = problem.system.scales.time_s
        say(f"accuracy check ({chk.method}, dt {chk.companion_dt * ts:.4g} s): estimated error "
            f"{chk.estimate:.3g} {'meets' if ok else 'MISSES'} the requested {plan.accuracy:g}")
        return {"accuracy_requested": plan.accuracy, "accuracy_estimate": chk.estimate,
                "accuracy_met": int(ok), "accuracy_check": chk.method,
                "accuracy_check_dt_s": chk.companion_dt * ts, "accuracy_check_wall_s": chk.wall_s}

    return on_finish
