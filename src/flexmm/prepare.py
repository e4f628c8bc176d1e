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
the step). Then the frames: the step is fitted to the frame times (``flexmm.frames``: shortened to
divide the frame interval, or the request refused).

``resolve(scene, fidelity, analysis)`` is the one plan every verb shows — ``validate``, ``plan``,
``run``, ``compare``, ``bench`` and ``stability`` print its ``lines()`` (method, step, stable limit,
frame times, domain, cost and every change made to what the scene asked) and run its problem.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Callable

from flexmm import accuracy as acc
from flexmm.assemble import Problem, build_problem, scene_notes
from flexmm.config.scene import DEFAULT_METHOD
from flexmm.errors import PlanError
from flexmm.integrators import INTEGRATORS
from flexmm.plan.cost import Cost, estimate
from flexmm.plan.cost import check_steps as cost_check_steps
from flexmm.plan.domain import trim_scene
from flexmm.frames import FrameTimes, frame_times
from flexmm.plan.planner import Plan, PlanStep, make_plan, replace_section


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
    _frames(plan, problem)
    problem.notes[:0] = plan.lines()
    return problem


def _frames(plan: Plan, problem: Problem) -> FrameTimes:
    """Fit the step to the frame times (``flexmm.frames.frame_times``); the plan and problem follow a
    shortened step, and a ``frames`` plan step records the frames and any change."""
    scene, ts = plan.scene, problem.system.scales.time_s
    spec, out = INTEGRATORS[scene.solver.integrator], scene.output
    frames, changes = frame_times(scene.solver.duration_s, out.n_frames, out.every_s,
                                  None if spec.adaptive else problem.dt * ts,
                                  given=plan.source.solver.dt_s is not None, exact=out.exact_frame_times,
                                  stable_dt_s=problem.stable_dt * ts)
    if changes:
        planned = replace_section(scene, "solver", dt_s=frames.dt_s)
        plan.scene = problem.scene = planned
        problem.dt = frames.dt_s / ts
    steps = "" if frames.dt_s is None else f", {frames.steps_per_frame} steps of {frames.dt_s:.6g} s each"
    notes = [f"{frames.n_frames} frames every {frames.interval_s:.6g} s from 0 to {frames.t_end_s:.6g} s{steps}"]
    attrs = {"plan_frames": frames.n_frames, "plan_frame_interval_s": frames.interval_s}
    plan.steps.append(PlanStep("frames", "changed" if changes else "kept", notes + changes, attrs))
    plan.frames = frames
    return frames


#: plan steps whose action changes what the scene asked, with the notes that say how
CHANGES = {"dimension": ("reduced",), "domain": ("trimmed",), "output": ("pruned",),
           "accuracy": ("not applied",), "frames": ("changed",)}


@dataclass
class RunPlan:
    """The one plan of a scene (``resolve``): the planner's decisions, the problem that runs, its
    frames and cost, and the changes made to what the scene asked."""

    plan: Plan
    problem: Problem | None  # None: the continuum replaces the run
    cost: Cost | None
    changes: list[str] = field(default_factory=list)

    @property
    def frames(self) -> FrameTimes | None:
        return self.plan.frames

    def lines(self) -> list[str]:
        """What runs, one 'plan: ...' line per item; the same numbers in every verb."""
        p, src = self.plan, self.plan.source
        if self.problem is None:
            return [f"plan: no discrete run: the continuum wave replaces it (--fidelity {p.fidelity})"] + [
                f"plan: change: {c}" for c in self.changes]
        s, ts = self.problem.system, self.problem.system.scales.time_s
        lat, solver = p.scene.lattice, p.scene.solver
        size = ("as declared" if lat.n_sites == src.lattice.n_sites and lat.kind == src.lattice.kind
                else f"declared: {src.lattice.kind}, {src.lattice.n_sites:,} units")
        acc = p.step("accuracy")
        how = ("chosen by the accuracy pilots" if acc is not None and acc.action == "chosen"
               else "solver.dt_s" if src.solver.dt_s is not None
               else f"solver.dt_fraction {solver.dt_fraction:g} of the stable limit")
        spec = INTEGRATORS[solver.integrator]
        f = self.frames
        step = (f"adaptive steps (rtol {solver.rtol or 1e-6:g})" if spec.adaptive
                else f"dt {f.dt_s:.6g} s ({how})")
        steps = "" if f.n_steps is None else f"; {f.n_steps:,} steps, {f.steps_per_frame:,} per frame"
        c = self.cost
        out = [f"plan: lattice {lat.kind}: {lat.n_sites:,} units ({size}), {s.ndof:,} DOFs",
               f"plan: method {spec.name}, {step}, stable limit {self.problem.stable_dt * ts:.6g} s",
               f"plan: frames {f.n_frames:,} every {f.interval_s:.6g} s from 0 to {f.t_end_s:.6g} s{steps}",
               f"plan: cost: integration {c.time_line() or 'time unknown (adaptive steps)'}; memory ≈ "
               f"{c.memory_bytes / 2**30:.2g} GiB; output {c.frames:,} frames × {c.saved_sites:,} sites ≈ "
               f"{c.output_bytes / 2**30:.3g} GiB"]
        return out + [f"plan: change: {c}" for c in self.changes]

    def attrs(self) -> dict:
        """The planner's attrs (``Plan.attrs``) with the changes (``plan_changes``, one per line, '' for
        none), these lines (``plan_summary``) and the estimated integration time."""
        a = {**self.plan.attrs(), "plan_changes": "\n".join(self.changes), "plan_summary": "\n".join(self.lines())}
        if self.cost is not None and self.cost.seconds is not None:
            a.update(plan_estimated_s=self.cost.seconds, plan_unit_steps_per_s=self.cost.rate)
        return a


def changes(plan: Plan) -> list[str]:
    """What the plan changed of what the scene asked (``CHANGES``), one line each."""
    out = []
    for s in plan.steps:
        if s.action.startswith(CHANGES.get(s.name, ("-",))):
            notes = s.notes[1:] if s.name in ("domain", "frames") and len(s.notes) > 1 else s.notes
            out += [f"{s.name}: {n}" for n in notes]
    return out


def resolve(scene, fidelity: str = "auto", analysis=None, check_steps: Callable | None = None) -> RunPlan:
    """The plan of ``scene`` as every verb shows and ``flexmm run`` runs it (module docstring):
    ``plan.make_plan``, then ``prepare`` (build, accuracy pilots, frames), then the cost of what runs.
    ``check_steps`` as for ``prepare`` (default ``plan.cost.check_steps``: a run beyond FLEXMM_MAX_STEPS
    is refused before the pilots run); PlanError for a request that cannot be met."""
    check_steps = check_steps or cost_check_steps
    if scene.solver.dt_s is not None:  # a given step: its steps are known before anything is built or piloted
        check_steps(math.ceil(scene.solver.duration_s / scene.solver.dt_s - 1e-9), scene.solver.dt_s,
                    scene.lattice.n_sites)
    try:
        plan = make_plan(scene, fidelity, analysis)
    except ValueError as exc:  # the planner's plain ValueErrors (e.g. an absorbing layer wider than the lattice)
        raise PlanError(str(exc)) from None
    if plan.skip_discrete:
        return RunPlan(plan, None, None, changes(plan))
    problem = prepare(plan, check_steps)
    ts = problem.system.scales.time_s
    cost = estimate(plan.scene, step=False)
    f = plan.frames
    cost.dt_s, cost.stable_dt_s = (None, problem.stable_dt * ts) if f.dt_s is None else (f.dt_s, problem.stable_dt * ts)
    cost.steps = f.n_steps
    cost.frames = f.n_frames
    return RunPlan(plan, problem, cost, changes(plan))


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
            pilot = _pilot_problem(plan, problem)
            est = acc.run_estimate(pilot, spec, problem.dt, acc.estimate(pilot, spec, problem.dt))
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


def _pilot_problem(plan: Plan, problem: Problem) -> Problem:
    """The problem the accuracy pilots run: ``problem`` itself, or — when the run keeps a lattice
    the waves never cross (``--fidelity full``; the domain step's ``plan_pilot_first/last``) —
    the same scene on the units they reach (``plan.domain.trim_scene``), with the whole lattice's
    ω_max, steps and duration. The pilots measure the waves' speeds and amplitudes where the waves
    are; on the whole lattice they would spend most of their time on units at rest (and sample
    the waves at a stride of the lattice's length)."""
    dom = plan.step("domain")
    if dom is None or "plan_pilot_first" not in dom.attrs:
        return problem
    keep = (int(dom.attrs["plan_pilot_first"]), int(dom.attrs["plan_pilot_last"]))
    small = build_problem(trim_scene(plan.scene, keep, probe=True))
    return dataclasses.replace(small, dt=problem.dt, duration=problem.duration, omega_max=problem.omega_max,
                               stable_dt=problem.stable_dt)


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
    pilot = _pilot_problem(plan, problem)
    try:
        choice = acc.choose(pilot, target, only, every=every)
    except ValueError as exc:
        raise PlanError(f"solver.accuracy: {exc}") from None
    est = acc.run_estimate(pilot, INTEGRATORS[choice.integrator], choice.dt, choice.estimate) \
        if mode == "pilot" else None
    if est is not None and est.method != choice.estimate.method:
        est = acc.shorten_for_run(pilot, choice, est, target, every)
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
    check = error_check_of(plan)
    return None if check is None else whole_run_check(problem, **check)


def error_check_of(plan: Plan) -> dict | None:
    """What ``whole_run_check`` needs to be made again without the plan (a resumed run), or None."""
    if plan.choice is None or plan.error_check != "run" or plan.accuracy is None:
        return None
    return {"target": plan.accuracy, "integrator": plan.choice.integrator}


def whole_run_check(problem: Problem, target: float, integrator: str) -> Callable:
    """``accuracy_check``'s callback for ``problem`` run with ``integrator``, against ``target``."""
    spec = INTEGRATORS[integrator]

    def on_finish(q, v, h, say, t) -> dict:
        est = acc.estimate(problem, spec, h, whole_run=True)
        ts = problem.system.scales.time_s
        say(f"accuracy check: {_estimate_line(target, est, ts)}")
        return _estimate_attrs(target, est, ts)

    return on_finish
