"""Library entry points: load a scene, run it, measure it, draw it.

The notebook API (``flexmm.run``, ``flexmm.analyze``, ``flexmm.render``, re-exported at the top
of the package; docs/api.md) is a thin layer over what the command line runs: ``run_scene``
(``flexmm run``), ``analysis.report.analyze`` (``flexmm analyze``) and ``render.api`` (``flexmm render``).
"""

from __future__ import annotations

import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

from flexmm.assemble import build_problem
from flexmm.checkpoint import DEFAULT_EVERY_S, Checkpointing
from flexmm.config import Scene, load_scene
from flexmm.controller import RunResult, run_problem
from flexmm.io.atomic import write_text_atomic
from flexmm.io.provenance import config_hash, config_text
from flexmm.io.rundir import RunDirectory

if TYPE_CHECKING:
    import xarray as xr
    from matplotlib.figure import Figure

    from flexmm.analysis.report.analyze import RunAnalysis


class _InPlace:
    """``RunDirectory``'s interface for writing straight into a directory the caller owns."""

    def __init__(self, out: Path):
        self.stage = out

    def __enter__(self) -> _InPlace:
        self.stage.mkdir(parents=True, exist_ok=True)
        return self

    def commit(self, status: str) -> Path:
        return self.stage

    def __exit__(self, *exc) -> None:
        pass


def run_dir_for(scene: Scene, root: str | Path | None = None) -> Path:
    """Where a scene's outputs go: ``<output.directory>/<name>`` unless ``root`` is given (``~`` expanded)."""
    return (Path(root) if root is not None else Path(scene.output.directory) / scene.name).expanduser()


def run_scene(scene: Scene, *, run_dir: str | Path | None = None, progress: bool = False,
              log: Callable[[str], None] | None = None, fidelity: str = "full",
              analysis: str | None = None, force_limits: bool = False, atomic: bool = True,
              in_memory: bool = False, checkpoint_s: float | None = None,
              announce: Callable[[list[str]], None] | None = None) -> RunResult:
    """Plan, build (once) and integrate a scene; publish dataset.nc, config.yaml and run.log together.

    The plan is ``prepare.resolve(scene, fidelity, analysis)`` ('full' runs the scene as declared;
    the CLI uses 'auto'), the one every verb shows: ``announce(lines)`` (if given) receives its
    lines — method, step, stable limit, frames, domain, cost and every change to what the scene
    asked — before the run; the planner's decisions are logged, and the dataset attrs hold both
    (``plan_summary``, ``plan_changes``, ``plan``); config.yaml holds the scene
    that actually ran. The outputs are written in a private staging
    directory and committed with one rename (``io.rundir.RunDirectory``): a finished run becomes
    ``run_dir``; a failed or interrupted one goes to ``run_dir.failed`` / ``run_dir.interrupted``
    and never replaces a finished result. ``result.path`` is the committed dataset. A run of
    more steps than FLEXMM_MAX_STEPS is refused (``plan.cost.ResourceError``) unless
    ``force_limits``. ``atomic=False`` writes straight into ``run_dir`` for a caller that owns
    the directory and publishes its own markers (sweep points). ``in_memory`` keeps the dataset
    in ``result.dataset`` instead of writing dataset.nc (a sweep point measured and dropped; a
    continuum-only run still writes its file). ``checkpoint_s``: seconds of wall time between
    checkpoints (``flexmm.checkpoint``; also one when the run ends or a signal stops it; ``flexmm
    run`` gives ``checkpoint.DEFAULT_EVERY_S``), which ``continue_run`` continues from; None (the
    default: sweep points, fidelity runs): none, and none for ``atomic=False`` or ``in_memory``.
    """
    from flexmm.continuum_run import run_continuum
    from flexmm.plan.cost import check_steps
    from flexmm.plan.output import parse_analysis
    from flexmm.prepare import accuracy_check, resolve

    from flexmm.prepare import error_check_of

    out = run_dir_for(scene, run_dir)
    keep = atomic and not in_memory and checkpoint_s is not None
    with (RunDirectory(out, checkpoints=keep) if atomic else _InPlace(out)) as rd:
        for old in getattr(rd, "discarded", []):
            if log:
                log(f"discarded the checkpoints of an earlier run into {out} ({old.name}; flexmm run --resume "
                    "would have continued it)")
        rp = resolve(scene, fidelity, parse_analysis(analysis),
                     lambda steps, dt_s, n: check_steps(steps, dt_s, n, force_limits))
        summary = rp.lines()
        if announce is not None:
            announce(summary)
        plan = rp.plan
        if plan.skip_discrete:
            result = run_continuum(plan.scene, plan.prediction, rd.stage, extra_attrs=rp.attrs(), log=log)
        else:
            problem = rp.problem
            check_steps(problem.duration / problem.dt, problem.dt * problem.system.scales.time_s,
                        problem.system.n_sites, force_limits)
            ckpt = None if not keep else Checkpointing(rd.stage, checkpoint_s, {
                "source_config": config_text(scene), "source_sha256": config_hash(scene),
                "planned_config": config_text(plan.scene),
                "plan_attrs": rp.attrs(), "error_check": error_check_of(plan)})
            result = run_problem(problem, rd.stage, progress=progress, log=log, extra_attrs=rp.attrs(),
                                 on_finish=accuracy_check(plan, problem), in_memory=in_memory, checkpoints=ckpt)
        write_text_atomic(rd.stage / "config.yaml", config_text(plan.scene))
        write_text_atomic(rd.stage / "run.log", "\n".join(result.log) + "\n")
        where = rd.commit(result.status)
    result.path = None if result.dataset is not None or result.path is None else where / "dataset.nc"
    return result


def continue_run(run_dir: str | Path, scene: Scene | None = None, *, extend: bool = False, progress: bool = False,
                 log: Callable[[str], None] | None = None, allow_version: bool = False,
                 checkpoint_s: float | None = DEFAULT_EVERY_S) -> RunResult:
    """Continue the run in ``run_dir`` from its newest valid checkpoint (``flexmm run --resume/--extend``).

    Resume (``extend=False``): the run was interrupted, failed or killed; its checkpoints are in
    ``<run_dir>.interrupted``, ``<run_dir>.failed`` or the work directory a killed run left. The
    run goes on from the checkpoint and publishes what an uninterrupted run would have (the same
    frames and state, bit for bit; ``resumed`` in the dataset attrs). ``scene``, if given, must be
    the scene the run was started with (``CheckpointError`` listing what changed otherwise).

    Extend (``extend=True``): ``run_dir`` is a finished run and ``scene`` its config.yaml (the scene
    that ran) with a longer ``solver.duration_s``, the only change allowed. The run goes on from
    its end on the same time axis with the same step and frame interval, and replaces
    ``run_dir``: the result equals that scene run from t = 0 with ``output.every_s`` set to the
    run's frame interval.

    A checkpoint written by another flexmm version or commit is refused unless ``allow_version``.
    """
    from flexmm import checkpoint as ck
    from flexmm.plan.planner import replace_section
    from flexmm.prepare import whole_run_check

    final = Path(run_dir).expanduser()
    for status in ("interrupted", "failed", "inaccurate"):
        if final.name.endswith("." + status):
            final = final.with_name(final.name[: -len(status) - 1])
    say = log or (lambda _m: None)
    with RunDirectory(final, checkpoints=checkpoint_s is not None, keep_work=True) as rd:
        partial = [final.with_name(f"{final.name}.{status}") for status in ("interrupted", "failed")]
        ended_dirs = [final, final.with_name(f"{final.name}.inaccurate")]  # where a run that ended is published
        sources = ended_dirs if extend else [*rd.work_dirs(), *partial]
        found, refused = ck.best([d for d in sources if d.is_dir()])
        for note in refused:
            say(note)
        meta = found.meta
        planned, source = ck.continuation(found, scene, extend=extend, allow_version=allow_version,
                                          from_work=found.directory in rd.work_dirs())
        problem = build_problem(planned)
        if extend:
            every_s = meta["interval"] * problem.system.scales.time_s
            planned = source = replace_section(planned, "output", every_s=every_s)
            problem = build_problem(planned, built=(problem.system, problem.terms))
        else:
            problem.duration = meta["duration"]
        problem.dt = meta["problem_dt"]
        check = meta.get("error_check")
        ckpt = None if checkpoint_s is None else Checkpointing(rd.stage, checkpoint_s, {
            "source_config": config_text(source), "source_sha256": config_hash(source),
            "planned_config": config_text(planned),
            "plan_attrs": meta["plan_attrs"], "error_check": check})
        result = run_problem(problem, rd.stage, progress=progress, log=log, extra_attrs=meta["plan_attrs"],
                             on_finish=whole_run_check(problem, **check) if check else None, checkpoints=ckpt,
                             resume=found)
        write_text_atomic(rd.stage / "config.yaml", config_text(planned))
        write_text_atomic(rd.stage / "run.log", "\n".join(result.log) + "\n")
        where = rd.commit(result.status)
        if (where / ck.NAME).is_file():  # the run's own checkpoint supersedes the ones it came from
            for old in rd.work_dirs():
                shutil.rmtree(old, ignore_errors=True)
            if result.status == "finished":
                for old in partial:
                    shutil.rmtree(old, ignore_errors=True)
    result.path = None if result.path is None else where / "dataset.nc"
    return result


@dataclass
class Result:
    """What ``flexmm.run`` returns: the run's dataset and how the run went.

    ``dataset``: the run's ``xarray.Dataset``, loaded in memory (SI units; the layout of
    docs/architecture.md "Dataset layout"); ``status``: 'finished', 'failed' or 'interrupted';
    ``message``: why a run did not finish ('' if it did); ``error_estimate``: the estimated
    relative error of the wave amplitudes and speeds (None for a run without one), ``accuracy``
    the full estimate and its target (the dataset's ``accuracy_*`` attributes); ``path``: the
    dataset file when the run was written to a directory (``out``), else None; ``scene``: the
    validated scene that was asked for; ``log``: the run's log lines.
    """

    dataset: xr.Dataset
    status: str
    message: str
    error_estimate: float | None
    accuracy: dict
    path: Path | None
    scene: Scene
    log: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        """True when the run finished."""
        return self.status == "finished"

    def __repr__(self) -> str:
        sizes = ", ".join(f"{k}: {self.dataset.sizes[k]}" for k in ("time", "site") if k in self.dataset.sizes)
        est = "" if self.error_estimate is None else f", error estimate {self.error_estimate:.3g}"
        why = f" ({self.message})" if self.message else ""
        where = f", written to {self.path}" if self.path is not None else ""
        return f"<flexmm.Result {self.scene.name!r}: {self.status}{why}; dataset ({sizes}){est}{where}>"

    def analyze(self, **options: Any) -> Measurements:
        """``flexmm.analyze`` of this run's dataset."""
        return analyze(self.dataset, **options)

    def render(self, t: float | None = None, **options: Any) -> Figure:
        """``flexmm.render`` of this run's dataset."""
        return render(self.dataset, t=t, **options)


def run(scene: Scene | dict | str | Path, out: str | Path | None = None, *, overrides: dict[str, Any] | None = None,
        fidelity: str = "auto", analysis: str | None = None, progress: bool = False,
        **dotted: Any) -> Result:
    """Run a scene and return its dataset in memory, its status and its error estimate.

    ``scene``: the path of a YAML file, YAML text, a dict of the same content, or a ``Scene``.
    Overrides are dotted keys, given as ``overrides={"solver.duration_s": 0.1}`` and/or as
    keyword arguments (``**{"solver.duration_s": 0.1}``; the keyword form wins on a clash).
    ``out``: a run directory to write (dataset.nc, config.yaml, run.log, as ``flexmm run --out``);
    None runs in a temporary directory that is removed once the dataset is loaded.
    ``fidelity`` and ``analysis`` are ``flexmm run``'s options of the same names.

    Any change the plan makes to what was asked (a lattice trimmed, a step shortened to the frame
    times) is printed as a ``plan: change: ...`` line and stored in ``dataset.attrs["plan_changes"]``.
    A mistake in the scene or an override raises ``flexmm.errors.FlexmmError`` (``ConfigError``
    naming the source, the dotted field and what was expected); a run that fails or is
    interrupted returns with ``status`` and ``message`` saying so.
    """
    from flexmm.analysis.report.analyze import open_dataset
    from flexmm.config import resolve_scene
    from flexmm.plan.cost import EXACT_SITES, enforce
    from flexmm.plan.output import parse_analysis

    parse_analysis(analysis)  # an unknown analysis is an error before anything runs
    sc = resolve_scene(scene, {**(overrides or {}), **dotted})
    tmp = None if out is not None else Path(tempfile.mkdtemp(prefix="flexmm-run-"))
    try:
        run_dir = Path(out).expanduser() if out is not None else tmp / sc.name
        enforce(sc, run_dir, step=sc.lattice.n_sites > EXACT_SITES)
        res = run_scene(sc, run_dir=run_dir, progress=progress, fidelity=fidelity, analysis=analysis,
                        announce=_print_changes)
        ds = open_dataset(res.path)
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
    return Result(dataset=ds, status=res.status, message=res.reason,
                  error_estimate=res.accuracy.get("accuracy_estimate"), accuracy=dict(res.accuracy),
                  path=res.path if out is not None else None, scene=sc, log=list(res.log))


def _print_changes(lines: list[str]) -> None:
    """The plan's changes to what the scene asked, printed (never silent; the whole plan is the
    dataset's ``plan_summary``)."""
    for line in lines:
        if line.startswith("plan: change:"):
            print(line)


@dataclass
class Measurements:
    """What ``flexmm.analyze`` returns: the measurements of one run against theory.

    ``kind``: the analysis made ('pulse', 'front', 'driven' or 'modes'); ``principal``: the
    feature the scene is about (the measurement ``flexmm run`` summarises: a ``PulseMeasurement``,
    ``FrontMeasurement``, ``WaveGroup`` or ``DrivenMeasurement``), None if nothing was measured;
    ``comparisons``: the rows of ``flexmm analyze``'s table (item, quantity, measured,
    predicted, units, rel_diff, note); ``dataset``: everything measured as an ``xarray.Dataset``
    (what ``flexmm analyze`` saves as analysis.nc); ``report``: the full ``RunAnalysis``.
    """

    report: RunAnalysis

    def __repr__(self) -> str:
        return f"<flexmm.Measurements {self.kind}: {self.report.name}>\n{self}"

    @property
    def kind(self) -> str:
        return self.report.kind

    @property
    def principal(self) -> Any:
        from flexmm.analysis.report.summary import principal

        pick = principal(self.report)
        return None if pick is None else pick[1]

    @property
    def speed_m_s(self) -> float | None:
        """The speed of the principal pulse, front or wave group in m/s (None: none measured)."""
        return getattr(self.principal, "speed_m_s", None)

    @property
    def comparisons(self) -> list[dict]:
        return [c.as_dict() for c in self.report.comparisons]

    @property
    def dataset(self) -> xr.Dataset:
        from flexmm.analysis.report.export import to_dataset

        return to_dataset(self.report)

    def __str__(self) -> str:
        from flexmm.analysis.report.summary import summary_lines

        return "\n".join(summary_lines(self.report))


def analyze(run: xr.Dataset | str | Path | Result, **options: Any) -> Measurements:
    """Measure a run as ``flexmm analyze`` does: its pulses, fronts, driven response or wave
    groups, compared with the model's theory.

    ``run``: the run's ``xarray.Dataset`` (e.g. ``flexmm.run(...).dataset``), a ``Result``, a
    run directory or its dataset.nc. ``options``: ``kind`` ('auto', 'pulse', 'front', 'driven',
    'modes'), ``field`` ('theta', 'u', 'strain', ...), ``row``, ``threshold_fraction``, ``jump``
    (``flexmm analyze``'s options; a mistake raises ``ConfigError``). Nothing to measure raises
    a ``FlexmmError`` subclass (``PulseNotFound``, ``FrontNotFound``, ...).
    """
    from flexmm.analysis.report.analyze import analyze_dataset, analyze_with
    from flexmm.config.analysis import AnalysisOptions
    from flexmm.config.loader import validate

    opts = validate(AnalysisOptions, options, source="flexmm.analyze")
    if isinstance(run, Result):
        run = run.dataset
    if hasattr(run, "data_vars"):
        return Measurements(analyze_dataset(run, field_spec=opts.field, kind=opts.kind, row=opts.row,
                                            threshold_fraction=opts.threshold_fraction, jump=opts.jump))
    return Measurements(analyze_with(run, opts))


def render(run: xr.Dataset | str | Path | Result, t: float | None = None, **options: Any) -> Figure:
    """One frame of a run as a matplotlib Figure: ``flexmm.render.api.figure`` (``flexmm.render``)."""
    from flexmm.render.api import figure

    return figure(run, t, **options)


__all__ = ["Measurements", "Result", "analyze", "build_problem", "continue_run", "load_scene", "render", "run",
           "run_dir_for", "run_scene"]
