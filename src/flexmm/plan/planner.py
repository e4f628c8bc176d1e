"""The plan of a scene: what to model, in what size, what to save, with which step.

``make_plan(scene, fidelity)`` returns a ``Plan`` whose ``scene`` is what actually runs, plus
one ``PlanStep`` per decision (dimension, domain, continuum, output, accuracy) with the numbers
behind it. Fidelities:

- ``auto`` (``flexmm run``, ``flexmm plan``): every reduction that keeps the answer — a planar
  sheet as its chain, a lattice trimmed to the reach of its waves, output pruned to the
  requested analysis; ``solver.accuracy`` asks for pilots to pick integrator and dt;
- ``full``: the scene as declared (warnings say what is wasted); accuracy still honoured;
- ``chain``: as ``auto`` but a planar sheet runs as the n_lateral = 2 chain (docs/physics.md §1.2)
  (approximate, see ``dimension``) instead of the exact 2-row strip;
- ``continuum``: no discrete run; the continuum wave is sampled (only where the theory fixes it).

Planning is pure: it builds the lattice to linearise it (the domain step) but never advances
time or writes. What needs a run — the accuracy pilots, a continuum formation pilot — happens in
``flexmm.prepare`` and ``flexmm.continuum_run``; the run reuses the plan's build
(``Plan.built_for``). The scene that finally runs is explicit (sizes, dt, integrator set;
``solver.accuracy`` cleared), so the config recorded with a run reproduces it exactly.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from flexmm.errors import PlanError
from flexmm.io.pause import pause_point
from flexmm.plan.continuum import ContinuumPrediction, NeedsAmplitude, NoContinuum, predict
from flexmm.plan.dimension import reduce_dimension
from flexmm.assemble import build_system
from flexmm.plan.domain import TRIM_WASTE, length_key, trim_scene, wave_reach
from flexmm.plan.output import AnalysisRequest, output_plan, saved_fraction

FIDELITIES = ("auto", "full", "chain", "continuum")


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
    choice: object | None = None  # accuracy.Choice, once ``flexmm.prepare`` has chosen
    accuracy: float | None = None
    plan_s: float = 0.0
    built: tuple | None = None  # (scene, system, terms) the domain step built (``built_for``)
    error_check: str | None = None  # 'pilot' or 'run', once ``flexmm.prepare`` has decided (None: no estimate)
    frames: object | None = None  # ``flexmm.frames.FrameTimes``, once ``flexmm.prepare`` has fitted the step to them

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

    def built_for(self, scene) -> tuple | None:
        """The (system, terms) planning built, if ``scene`` builds to the same system, else None.

        The domain step builds the lattice with its excitation and imperfection applied; when
        later steps changed only the output (or nothing), the run reuses that build.
        """
        if self.built is None:
            return None
        src = self.built[0]
        same = all(getattr(scene, k) == getattr(src, k) for k in ("lattice", "excitation", "imperfection"))
        return self.built[1:] if same else None


def replace_section(scene, section: str, **values):
    """A copy of ``scene`` with ``values`` set in one section (validated again)."""
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
    if getattr(lat, "trim_issue", None):
        return lat.trim_issue
    if getattr(lat, "variation", None) or getattr(lat, "predeform", None):
        return "parameters vary along x or the lattice is predeformed"
    if getattr(lat, "left", None) == "periodic":
        return "the lattice is periodic along x (a ring): waves come round"
    return None


def _domain(scene, fidelity: str):
    system, terms = build_system(scene)
    built = (scene, system, terms)
    scene, step = _reach(scene, fidelity, system, terms)
    return scene, step, built


#: a trimmable lattice of more sites along x than this takes its bands from a copy of this length
BANDS_COPY_SITES = 256


def _bands_copy(scene, system):
    """(system, terms) of a ``BANDS_COPY_SITES`` copy of a long uniform lattice, else None: the
    bands' Hessian columns then cost force evaluations on a few hundred sites, not the lattice."""
    ix, _ = system.site_grid()
    if int(ix.max()) + 1 <= BANDS_COPY_SITES or _trimmable(scene) is not None:
        return None
    return build_system(trim_scene(scene, (0, BANDS_COPY_SITES - 1), probe=True))


def _reach(scene, fidelity: str, system, terms):
    sc = system.scales
    duration = scene.solver.duration_s / sc.time_s
    try:
        reach = wave_reach(scene, system, terms, duration, _bands_copy(scene, system))
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
        if not why_not:  # the pilots measure the waves where they are (``prepare._pilot_problem``)
            attrs.update(plan_pilot_first=reach.keep[0], plan_pilot_last=reach.keep[1])
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
    return replace_section(scene, "output", **upd), PlanStep("output", "pruned", notes, {"plan_output_fraction": frac})


def _accuracy(scene):
    """The accuracy step as planned: pilots choose integrator and dt at run time (``flexmm.prepare``)."""
    target = scene.solver.accuracy
    if scene.solver.dt_s is not None:
        return PlanStep("accuracy", "pending", [f"accuracy {target:g}: solver.dt_s = {scene.solver.dt_s:.4g} s "
                                                f"({scene.solver.integrator}) is honoured and its error estimated"])
    return PlanStep("accuracy", "pending", [f"accuracy {target:g}: integrator and dt chosen by pilot runs "
                                            "before the run (flexmm.prepare)"])


def method(scene, cur):
    """``cur`` with the method that runs set: a scene with an accuracy target that names no integrator
    runs ``DEFAULT_METHOD`` whether or not it sets ``dt_s`` (halving a default run's step keeps its
    method); ``accuracy: null`` keeps the field's default (docs/physics.md §3)."""
    from flexmm.config.scene import DEFAULT_METHOD

    if cur.solver.accuracy is None or "integrator" in scene.solver.model_fields_set \
            or cur.solver.integrator == DEFAULT_METHOD:
        return cur
    return replace_section(cur, "solver", integrator=DEFAULT_METHOD)


def make_plan(scene, fidelity: str = "auto", analysis: AnalysisRequest | None = None) -> Plan:
    """Plan a scene (module docstring); PlanError for impossible requests."""
    if fidelity not in FIDELITIES:
        raise PlanError(f"unknown fidelity {fidelity!r}; valid: {', '.join(FIDELITIES)}")
    pause_point("plan")
    t0 = time.perf_counter()
    steps = []
    cur, st = _dimension(scene, fidelity)
    steps.append(st)
    cur, st, built = _domain(cur, fidelity)
    steps.append(st)
    pred, st = _continuum(cur, fidelity)
    steps.append(st)
    if fidelity == "continuum":
        return Plan(scene, cur, fidelity, steps, pred, plan_s=time.perf_counter() - t0, built=built)
    cur, st = _output(cur, fidelity, analysis, pred, scene.output.model_fields_set)
    steps.append(st)
    cur = method(scene, cur)
    if cur.solver.accuracy is not None:
        steps.append(_accuracy(cur))
    plan = Plan(scene, cur, fidelity, steps, pred, None, scene.solver.accuracy, built=built)
    plan.plan_s = time.perf_counter() - t0
    return plan
