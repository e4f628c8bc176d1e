"""From a plan to the problem that runs: build once, choose the step when accuracy is asked.

``prepare(plan)`` builds the planned scene (reusing the lattice the plan already built when only
the output changed) and, for its ``solver.accuracy`` (every scene has one unless it sets null),
runs the pilots of ``flexmm.accuracy`` to choose the integrator and dt — among all methods when
the scene sets the target, the scene's integrator when it names one, else ``DEFAULT_METHOD`` —
or, when the scene gives ``solver.dt_s``, honours it and estimates its error (with the scene's
integrator, else ``DEFAULT_METHOD``, which the plan already set: ``plan.planner.method``). The plan's scene,
steps and choice are updated so the recorded config reproduces the run. The error estimate is
the pilot's step doubling, over the whole run when that is cheap and else extrapolated to the
duration with the error's growth over the pilot (``accuracy.run_estimate``; ``error_check: pilot``,
the default for the default target, in the plan attrs) or ``accuracy_check(plan, problem)``, the whole run
repeated at 2 dt after it (``error_check: run``, the default when the scene sets the target or
the step).
"""

from __future__ import annotations

import math
from typing import Callable

from flexmm import accuracy as acc
from flexmm.assemble import Problem, build_problem, scene_notes
from flexmm.config.scene import DEFAULT_METHOD
from flexmm.errors import PlanError
from flexmm.integrators import INTEGRATORS
from flexmm.plan.planner import Plan, PlanStep, replace_section




def prepare(plan: Plan, check_steps: Callable | None = None) -> Problem:
    """The problem of ``plan.scene``, built once; with ``solver.accuracy``, integrator and dt chosen
    (or, with an explicit ``solver.dt_s``, honoured and its error estimated).

    ``check_steps(steps, dt_s, n_sites)`` (``plan.cost.check_steps``) sees the fewest steps any
    explicit method could take before the pilots run, so an impossible run is refused at once.
    """
    problem = build_problem(plan.scene, built=plan.built_for(plan.scene))
    if check_steps is not None and plan.scene.solver.accuracy is not None and plan.scene.solver.dt_s is None \
            and problem.omega_max > 0:
        specs = acc.candidates(problem)
        h = acc.CAP * max(s.stability_limit for s in specs) / problem.omega_max if specs else problem.dt
        check_steps(problem.duration / h, h * problem.system.scales.time_s, problem.system.n_sites)
    if plan.scene.solver.accuracy is not None:
        problem = _accuracy(plan, problem)
    problem.notes[:0] = plan.lines()
    return problem


def _accuracy(plan: Plan, problem: Problem) -> Problem:
    """Choose (or check) the step for ``solver.accuracy``; decide how the error is estimated."""
    solver, given = plan.scene.solver, plan.source.solver.model_fields_set
    spec = INTEGRATORS[solver.integrator]
    asked = "accuracy" in given  # the scene's own target, not the default
    mode = solver.error_check or "pilot"
    if not spec.explicit_limit:
        why = "adaptive: its error is controlled by rtol" if spec.adaptive else "not an explicit fixed-step method"
        plan.steps = [s for s in plan.steps if s.name != "accuracy"] + [
            PlanStep("accuracy", "not applied", [f"accuracy {solver.accuracy:g} not applied: {spec.name} is {why}"])]
        return problem
    if solver.dt_s is not None:  # the scene chose its step: honoured, then checked
        plan.error_check, plan.choice = mode, acc.Choice(spec.name, problem.dt, math.nan, 0.0, 0.0, order=spec.order)
        notes = [f"accuracy {solver.accuracy:g}: solver.dt_s = {solver.dt_s:.4g} s honoured ({spec.name})"]
        attrs = {}
        if mode == "pilot":
            est = acc.run_estimate(problem, spec, problem.dt, acc.estimate(problem, spec, problem.dt))
            attrs = _estimate_attrs(solver.accuracy, est, problem.system.scales.time_s)
            if est.converges is False and est.error > solver.accuracy:
                attrs["accuracy_converges"] = 0
                notes.append(_not_converging(est))
            notes.append(_estimate_line(solver.accuracy, est, problem.system.scales.time_s))
        plan.steps = [s for s in plan.steps if s.name != "accuracy"] + [PlanStep("accuracy", "checked", notes, attrs)]
        return problem
    only = solver.integrator if "integrator" in given else (None if asked else DEFAULT_METHOD)
    try:
        return _choose(plan, problem, only, mode)
    except PlanError as exc:
        if asked:
            raise
        plan.steps = [s for s in plan.steps if s.name != "accuracy"] + [
            PlanStep("accuracy", "not applied", [f"default accuracy not applied ({exc}); dt from solver.dt_fraction"])]
        return problem


def _estimate_attrs(target: float, est: acc.Estimate, time_s: float) -> dict:
    """Dataset attrs of an error estimate (``accuracy_*``)."""
    return {"accuracy_requested": target, "accuracy_estimate": est.error, "accuracy_met": int(est.error <= target),
            "accuracy_estimate_amplitude": est.amplitude, "accuracy_estimate_speed": est.speed,
            "accuracy_check": est.method, "accuracy_window_s": est.window * time_s,
            "accuracy_check_wall_s": est.wall_s, "accuracy_extrapolated": int("extrapolated" in est.method)}


def _estimate_line(target: float, est: acc.Estimate, time_s: float) -> str:
    how = (f"{est.method} over {est.window * time_s:.3g} s: amplitudes {est.amplitude:.2g}, "
           f"speeds {est.speed:.2g}")
    if est.error <= target:
        return f"estimated error {est.error:.3g} meets the target {target:g} ({how})"
    return f"WARNING: estimated error {est.error:.3g} exceeds the target {target:g} ({how})"


def _not_converging(est: acc.Estimate) -> str:
    return (f"WARNING: over the whole run the reported quantities do not converge in the step (halving it "
            f"changes them as much again): the estimate {est.error:.3g} is their spread, not an integration error "
            "that a smaller step removes (a chaotic late field, a threshold's or a collision's timing)")


def _choose(plan: Plan, problem: Problem, only: str | None, mode: str) -> Problem:
    """Pilot runs choose integrator and dt (``accuracy.choose``); plan and problem follow the choice."""
    scene = plan.scene
    target = scene.solver.accuracy
    ts = problem.system.scales.time_s
    out = scene.output
    every = out.every_s / ts if out.every_s else problem.duration / (out.n_frames - 1)
    try:
        choice = acc.choose(problem, target, only, every=every)
    except ValueError as exc:
        raise PlanError(f"solver.accuracy: {exc}") from None
    est = acc.run_estimate(problem, INTEGRATORS[choice.integrator], choice.dt, choice.estimate) \
        if mode == "pilot" else None
    if est is not None and est.method != choice.estimate.method:
        est = acc.shorten_for_run(problem, choice, est, target, every)
    planned = replace_section(scene, "solver", integrator=choice.integrator, dt_s=choice.dt * ts, accuracy=None)
    rows = "; ".join(f"{r['integrator']}: dt {r['dt'] * ts:.3g} s, {r['cost']:.3g} force evals"
                     for r in choice.table)
    notes = [f"accuracy {target:g}: {choice.integrator} with dt = {choice.dt * ts:.4g} s "
             f"(pilot over {choice.pilot_time * ts:.3g} s) — {rows}"]
    row = next(r for r in choice.table if r["integrator"] == choice.integrator)
    if not choice.reachable:
        notes.append(f"WARNING: accuracy {target:g} looks out of reach ({row['why']}); the run uses the step "
                     "above and its error estimate is reported")
    attrs = {"accuracy_integrator": choice.integrator, "accuracy_predicted_error": choice.predicted_error,
             "accuracy_pilot_s": choice.pilot_time * ts, "accuracy_reachable": int(choice.reachable),
             "accuracy_converges": int(row.get("converges", True))}
    if est is not None:  # the pilot's step doubling at the step used, over the whole run (run_estimate)
        attrs.update(_estimate_attrs(target, est, ts))
        notes.append(_estimate_line(target, est, ts))
        if est.converges is False and est.error > target:
            attrs["accuracy_converges"] = 0
            notes.append(_not_converging(est))
    plan.error_check = mode
    plan.steps = [s for s in plan.steps if s.name != "accuracy"] + [PlanStep("accuracy", "chosen", notes, attrs)]
    plan.scene, plan.choice = planned, choice
    if choice.integrator == scene.solver.integrator:  # same method: the built problem only changes dt
        problem.scene, problem.dt = planned, choice.dt
        problem.notes = scene_notes(planned, problem.system, problem.omega_max)  # not the dt it no longer uses
        return problem
    return build_problem(planned, built=plan.built_for(planned))  # another method: its own stable limit


def accuracy_check(plan: Plan, problem: Problem) -> Callable | None:
    """Callback for ``run_problem(on_finish=...)``: step doubling over the whole run
    (``solver.error_check: run``), at the step the run used."""
    if plan.choice is None or plan.error_check != "run" or plan.accuracy is None:
        return None
    target = plan.accuracy
    spec = INTEGRATORS[plan.choice.integrator]

    def on_finish(q, v, h, say, t) -> dict:
        est = acc.estimate(problem, spec, h, whole_run=True)
        ts = problem.system.scales.time_s
        say(f"accuracy check: {_estimate_line(target, est, ts)}")
        return _estimate_attrs(target, est, ts)

    return on_finish
