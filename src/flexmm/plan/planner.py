"""The plan of a scene: what to model, in what size, what to save, with which step.

``make_plan(scene, fidelity)`` returns a ``Plan`` whose ``scene`` is what actually runs, plus
one ``PlanStep`` per decision (dimension, domain, continuum, output, accuracy) with the numbers
behind it. Fidelities:

- ``auto`` (``flexmm run``, ``flexmm plan``): every reduction that keeps the answer — a planar
  sheet as its chain, a lattice trimmed to the reach of its waves, output pruned to the
  requested analysis; ``solver.accuracy`` picks integrator and dt;
- ``full``: the scene as declared (warnings say what is wasted); accuracy still honoured;
- ``chain``: as ``auto`` but a planar sheet runs as the n_lateral = 2 chain of PHYSICS.md
  (approximate, see ``dimension``) instead of the exact 2-row strip;
- ``continuum``: no discrete run; the continuum wave is sampled (only where the theory fixes it).

The planned scene is explicit (sizes, dt, integrator set; ``solver.accuracy`` cleared), so the
config recorded with a run reproduces it exactly.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from flexmm.plan import accuracy as acc_mod
from flexmm.plan.continuum import ContinuumPrediction, NeedsAmplitude, NoContinuum, predict
from flexmm.plan.dimension import reduce_dimension
from flexmm.plan.domain import TRIM_WASTE, built_system, length_key, trim_scene, wave_reach
from flexmm.plan.output import AnalysisRequest, output_plan, saved_fraction

FIDELITIES = ("auto", "full", "chain", "continuum")


class PlanError(ValueError):
    """A plan that cannot be made as asked (a user error; the CLI exits with status 2)."""


@dataclass
class PlanStep:
    """One decision: ``name`` (dimension/domain/continuum/output/accuracy), ``action``, notes, attrs."""

    name: str
    action: str
    notes: list[str]
    attrs: dict = field(default_factory=dict)


@dataclass
class Plan:
    source: object  # the Scene as given
    scene: object  # the Scene that runs
    fidelity: str
    steps: list[PlanStep]
    prediction: ContinuumPrediction | None = None
    choice: acc_mod.Choice | None = None
    accuracy: float | None = None
    plan_s: float = 0.0
    problem: object | None = None  # the built Problem of ``scene`` when planning made it already

    @property
    def skip_discrete(self) -> bool:
        return self.fidelity == "continuum"

    def step(self, name: str) -> PlanStep | None:
        return next((s for s in self.steps if s.name == name), None)

    def lines(self) -> list[str]:
        out = [f"plan ({self.fidelity}, {self.plan_s:.2f} s):"]
        for s in self.steps:
            out += [f"  {s.name}: {n}" for n in s.notes]
        return out

    def attrs(self) -> dict:
        """Flat attributes for the dataset (str, float, int)."""
        from flexmm.io.provenance import config_hash, config_text

        a = {"plan_fidelity": self.fidelity, "plan_time_s": self.plan_s,
             "plan": "\n".join(self.lines()),
             "plan_source_config_sha256": config_hash(self.source)}
        if self.scene is not self.source:
            a["plan_source_config"] = config_text(self.source)
        for s in self.steps:
            a[f"plan_{s.name}"] = s.action
            a.update({k: (int(v) if isinstance(v, bool) else v) for k, v in s.attrs.items() if v is not None})
        return a

    def finisher(self, problem):
        """Callback for ``run_problem(on_finish=...)``: the step-doubling accuracy check."""
        if self.accuracy is None or self.choice is None:
            return None

        def on_finish(q, v, h, say) -> dict:
            chk = acc_mod.check(problem, self.choice.integrator, h, problem.duration, q, self.choice.order)
            ok = chk.estimate <= self.accuracy
            say(f"accuracy check ({chk.method}, dt {chk.companion_dt * problem.system.scales.time_s:.4g} s): "
                f"estimated error {chk.estimate:.3g} {'meets' if ok else 'MISSES'} the requested {self.accuracy:g}")
            return {"accuracy_requested": self.accuracy, "accuracy_estimate": chk.estimate,
                    "accuracy_met": int(ok), "accuracy_check": chk.method,
                    "accuracy_check_dt_s": chk.companion_dt * problem.system.scales.time_s,
                    "accuracy_check_wall_s": chk.wall_s}

        return on_finish


def _replace(scene, section: str, **values):
    from flexmm.config import scene_from_dict

    data = scene.model_dump(mode="json")
    data[section] = {**(data.get(section) or {}), **values}
    return scene_from_dict(data, source=f"<plan: {section}>")


def _dimension(scene, fidelity: str):
    if fidelity == "full":
        return scene, PlanStep("dimension", "kept", ["--fidelity full: the lattice runs as declared"])
    how = "chain" if fidelity == "chain" else "strip"
    reduced, note = reduce_dimension(scene, how)
    if reduced is None:
        return scene, PlanStep("dimension", "kept", [note])
    lat = scene.lattice
    factor = lat.n_units / reduced.lattice.n_units
    return reduced, PlanStep("dimension", f"reduced to the {how}", [note],
                             {"plan_dimension_from": lat.kind, "plan_dimension_factor": factor})


def _trimmable(scene) -> str | None:
    """None if the lattice can be trimmed along x, else why not."""
    lat = scene.lattice
    if length_key(lat) is None:
        return f"{lat.kind} has no single length along x"
    if getattr(lat, "variation", None) or getattr(lat, "predeform", None):
        return "parameters vary along x or the lattice is predeformed"
    return None


def _domain(scene, fidelity: str):
    system, terms = built_system(scene)
    sc = system.scales
    duration = scene.solver.duration_s / sc.time_s
    try:
        reach = wave_reach(scene, system, terms, duration)
    except (ValueError, IndexError, np.linalg.LinAlgError) as exc:
        return scene, PlanStep("domain", "kept", [f"reach not computed ({exc}): lattice kept as declared"])
    attrs = {"plan_reach_speed_m_s": reach.speed_m_s, "plan_reach_units": reach.sites_reached,
             "plan_units_declared": reach.n_declared, "plan_units_needed": reach.n_needed}
    head = (f"fastest linear group speed {reach.speed_m_s:.4g} m/s ({reach.speed_sites:.4g} units per "
            f"{sc.time_s:.3g} s{'' if not reach.strain else f', at strain {reach.strain:.3g}'}): "
            f"waves cover {reach.sites_reached:.0f} units in {scene.solver.duration_s:.4g} s")
    if reach.keep is None:
        return scene, PlanStep("domain", "kept", [head + "; sources everywhere (random imperfection "
                                                  "or no excitation): nothing to trim"], attrs)
    if reach.waste < TRIM_WASTE:
        notes = [head + f"; all {reach.n_declared} units needed"]
        if reach.sites_reached > reach.n_declared and scene.damping.absorbing is None:
            t_end = reach.n_declared / reach.speed_sites * sc.time_s
            notes.append(f"the fastest waves reach an end within {t_end:.3g} s: damping.absorbing "
                         "{end: ...} emulates an unbounded lattice if reflections are unwanted")
        return scene, PlanStep("domain", "kept", notes, attrs)
    waste = (f"{reach.n_declared - reach.n_needed} of {reach.n_declared} units "
             f"({100 * reach.waste:.0f} %) are never reached")
    why_not = _trimmable(scene)
    if fidelity == "full" or why_not:
        reason = "--fidelity full" if fidelity == "full" else why_not
        return scene, PlanStep("domain", "warning", [head, f"WARNING: {waste} (not trimmed: {reason})"], attrs)
    lo, hi = reach.keep
    trimmed = trim_scene(scene, (lo, hi))
    attrs.update(plan_trim_first=lo, plan_trim_last=hi)
    return trimmed, PlanStep("domain", "trimmed", [head, f"{waste}: trimmed to units {lo}..{hi}"], attrs)


def _continuum(scene, fidelity: str):
    try:
        pred = predict(scene)
    except NeedsAmplitude as why:
        if fidelity == "continuum":
            return None, PlanStep("continuum", "after a formation pilot",
                                  [f"{why}: a short discrete pilot measures it, the continuum soliton "
                                   "of that amplitude replaces the rest of the run"])
        return None, PlanStep("continuum", "none", [str(why)])
    except NoContinuum as why:
        if fidelity == "continuum":
            raise PlanError(f"--fidelity continuum: {why}") from None
        return None, PlanStep("continuum", "none", [str(why)])
    if fidelity == "continuum" and not pred.complete:
        raise PlanError(f"--fidelity continuum: the theory does not fix the wave ({'; '.join(pred.notes)})")
    spans = "spans many units" if pred.spans_many_units else f"narrower than {5} units: discrete effects matter"
    notes = [pred.summary() + f" — {spans}"] + pred.notes
    action = "replaces the run" if fidelity == "continuum" else "reported"
    return pred, PlanStep("continuum", action, notes, pred.attrs())


def _output(scene, fidelity: str, request: AnalysisRequest | None, pred: ContinuumPrediction | None,
            user: set[str]):
    from flexmm.models import model_fields

    if fidelity == "full":
        return scene, PlanStep("output", "kept", ["--fidelity full: output as declared"])
    fields = model_fields(scene.lattice.kind)
    passage = pred.fwhm_m / pred.speed_m_s if pred is not None and pred.speed_m_s > 0 else None
    width = pred.width_sites if pred is not None else None
    upd, notes = output_plan(scene, request, fields, passage, width, user)
    if not upd:
        return scene, PlanStep("output", "kept", notes)
    frac = saved_fraction(scene, upd, fields)
    notes[-1 if len(notes) == 1 else 0] += f" ({100 * frac:.0f} % of the declared output)"
    return _replace(scene, "output", **upd), PlanStep("output", "pruned", notes, {"plan_output_fraction": frac})


def _accuracy(scene, integrator_set: bool):
    """(planned scene, choice, step, problem of the planned scene or None)."""
    from flexmm.assemble import build_problem

    target = scene.solver.accuracy
    if scene.solver.dt_s is not None:
        raise PlanError("solver.accuracy chooses dt: remove solver.dt_s (or solver.accuracy)")
    problem = build_problem(scene)
    only = scene.solver.integrator if integrator_set else None
    try:
        choice = acc_mod.choose(problem, target, only)
    except ValueError as exc:
        raise PlanError(f"solver.accuracy: {exc}") from None
    ts = problem.system.scales.time_s
    planned = _replace(scene, "solver", integrator=choice.integrator, dt_s=choice.dt * ts, accuracy=None)
    rows = "; ".join(f"{r['integrator']}: dt {r['dt'] * ts:.3g} s, {r['cost']:.3g} force evals"
                     for r in choice.table)
    note = (f"accuracy {target:g}: {choice.integrator} with dt = {choice.dt * ts:.4g} s "
            f"(predicted error {choice.predicted_error:.2g}, pilot over {choice.pilot_time * ts:.3g} s) — {rows}")
    notes = [note]
    row = next(r for r in choice.table if r["integrator"] == choice.integrator)
    if not choice.reachable:
        notes.append(f"WARNING: accuracy {target:g} looks out of reach ({row['why']}; pilot errors grow "
                     f"like t^{row['growth']:.1f}: the dynamics amplify perturbations); the run uses the "
                     "step above and the check after it reports the error reached")
    elif row["uncertain"]:
        notes.append(f"prediction uncertain: {row['uncertain']}; the check after the run reports the error reached")
    attrs = {"accuracy_integrator": choice.integrator, "accuracy_predicted_error": choice.predicted_error,
             "accuracy_pilot_s": choice.pilot_time * ts, "accuracy_reachable": int(choice.reachable)}
    if choice.integrator == scene.solver.integrator:  # same method: the built problem only changes dt
        problem.scene, problem.dt, problem.notes = planned, choice.dt, []
    else:
        problem = None
    return planned, choice, PlanStep("accuracy", "chosen", notes, attrs), problem


def make_plan(scene, fidelity: str = "auto", analysis: AnalysisRequest | None = None) -> Plan:
    """Plan a scene (module docstring); PlanError for impossible requests."""
    if fidelity not in FIDELITIES:
        raise PlanError(f"unknown fidelity {fidelity!r}; valid: {', '.join(FIDELITIES)}")
    t0 = time.perf_counter()
    steps = []
    cur, st = _dimension(scene, fidelity)
    steps.append(st)
    cur, st = _domain(cur, fidelity)
    steps.append(st)
    pred, st = _continuum(cur, fidelity)
    steps.append(st)
    if fidelity == "continuum":
        return Plan(scene, cur, fidelity, steps, pred, plan_s=time.perf_counter() - t0)
    cur, st = _output(cur, fidelity, analysis, pred, scene.output.model_fields_set)
    steps.append(st)
    choice = problem = None
    if cur.solver.accuracy is not None:
        cur, choice, st, problem = _accuracy(cur, "integrator" in scene.solver.model_fields_set)
        steps.append(st)
    plan = Plan(scene, cur, fidelity, steps, pred, choice, scene.solver.accuracy, problem=problem)
    plan.plan_s = time.perf_counter() - t0
    return plan
