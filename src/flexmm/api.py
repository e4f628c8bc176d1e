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
from flexmm.errors import OutputError
from flexmm.io.atomic import write_text_atomic
from flexmm.io.pause import pause_point
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
              in_memory: bool = False, checkpoint_s: float | None = None, checkpoint_dir: str | Path | None = None,
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
    default: fidelity runs): none. A run written with ``atomic=False`` or kept ``in_memory`` writes
    them into ``checkpoint_dir`` (a sweep point's work directory: ``continue_point`` continues it), none
    without one. Outputs that cannot be published (a full disk when the run ends) raise
    ``OutputError`` saying what was kept: a checkpointed run's work directory, for ``--resume``.
    """
    from flexmm.continuum_run import run_continuum
    from flexmm.plan.cost import check_steps
    from flexmm.plan.output import parse_analysis
    from flexmm.prepare import accuracy_check, resolve

    from flexmm.prepare import error_check_of

    out = run_dir_for(scene, run_dir)
    keep = atomic and not in_memory and checkpoint_s is not None
    own_dir = None if checkpoint_s is None or keep or checkpoint_dir is None else Path(checkpoint_dir)
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
            where_ck = rd.stage if keep else own_dir
            ckpt = None if where_ck is None else Checkpointing(
                where_ck, checkpoint_s, _checkpoint_meta(scene, plan.scene, rp.attrs(), error_check_of(plan)))
            result = run_problem(problem, rd.stage, progress=progress, log=log, extra_attrs=rp.attrs(),
                                 on_finish=accuracy_check(plan, problem), in_memory=in_memory, checkpoints=ckpt)
        where = _publish(rd, out, plan.scene, result)
    result.path = None if result.dataset is not None or result.path is None else where / "dataset.nc"
    return result


def _checkpoint_meta(source: Scene, planned: Scene, plan_attrs: dict, error_check: dict | None) -> dict:
    """What every checkpoint of a run holds besides its state (``flexmm.checkpoint``)."""
    return {"source_config": config_text(source), "source_sha256": config_hash(source),
            "planned_config": config_text(planned), "plan_attrs": plan_attrs, "error_check": error_check}


def _publish(rd, out: Path, planned: Scene, result: RunResult) -> Path:
    """config.yaml and run.log beside the dataset, then the commit (``RunDirectory.commit``); a write
    that fails here (a full disk) is an ``OutputError`` saying when, why, and what was kept."""
    pause_point("commit")
    step = "writing config.yaml"
    try:
        write_text_atomic(rd.stage / "config.yaml", config_text(planned))
        step = "writing run.log"
        write_text_atomic(rd.stage / "run.log", "\n".join(result.log) + "\n")
        step = "the rename that publishes them"
        return rd.commit(result.status)
    except OSError as exc:
        from flexmm.checkpoint import NAME

        kept = (f"its outputs and its checkpoint are kept in {rd.stage}: make room, then run flexmm run --resume "
                f"{out}" if (rd.stage / NAME).is_file() else "nothing of it was kept")
        raise OutputError(f"the run ended ({result.status}, t = {result.t_end_s:.6g} s) but its outputs could not be "
                          f"published: {step} failed ({exc.strerror or exc}); {out} is as it was before the run; "
                          f"{kept}") from None


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
    from flexmm.prepare import whole_run_check

    final = Path(run_dir).expanduser()
    for status in ("interrupted", "failed", "inaccurate"):
        if final.name.endswith("." + status):
            final = final.with_name(final.name[: -len(status) - 1])
    say = log or (lambda _m: None)
    with RunDirectory(final, checkpoints=checkpoint_s is not None, keep_work=True) as rd:
        partial = [final.with_name(f"{final.name}.{status}") for status in ("interrupted", "failed")]
        ended_dirs = [final, final.with_name(f"{final.name}.inaccurate")]  # where a run that ended is published
        if extend:
            sources = [d for d in ended_dirs if d.is_dir()]
        else:
            sources = _current(final, [*rd.work_dirs(), *partial], say)
            if not sources and _published(final) is not None:
                say(f"nothing to resume: {final} holds a finished run newer than any checkpoint of it")
                return _published_result(final)
        found, refused = ck.best(sources)
        for note in refused:
            say(note)
        planned, source, problem, check = _continued(found, scene, extend=extend, allow_version=allow_version,
                                                     from_work=found.directory in rd.work_dirs())
        meta = found.meta
        ckpt = None if checkpoint_s is None else Checkpointing(
            rd.stage, checkpoint_s, _checkpoint_meta(source, planned, meta["plan_attrs"], check))
        result = run_problem(problem, rd.stage, progress=progress, log=log, extra_attrs=meta["plan_attrs"],
                             on_finish=whole_run_check(problem, **check) if check else None, checkpoints=ckpt,
                             resume=found)
        where = _publish(rd, final, planned, result)
        if (where / ck.NAME).is_file():  # the run's own checkpoint supersedes the ones it came from
            for old in rd.work_dirs():
                shutil.rmtree(old, ignore_errors=True)
            if result.status == "finished":
                for old in partial:
                    shutil.rmtree(old, ignore_errors=True)
    result.path = None if result.path is None else where / "dataset.nc"
    return result


def _continued(found, scene: Scene | None, *, extend: bool, allow_version: bool, from_work: bool) -> tuple:
    """(scene that runs, scene as asked, problem, whole-run error check) to continue checkpoint ``found``
    (``checkpoint.continuation`` refuses what must not be continued); rebuilt without planning again,
    with the step the checkpoint's run used."""
    from flexmm import checkpoint as ck
    from flexmm.plan.planner import replace_section

    meta = found.meta
    planned, source = ck.continuation(found, scene, extend=extend, allow_version=allow_version, from_work=from_work)
    problem = build_problem(planned)
    if extend:
        every_s = meta["interval"] * problem.system.scales.time_s
        planned = source = replace_section(planned, "output", every_s=every_s)
        problem = build_problem(planned, built=(problem.system, problem.terms))
    else:
        problem.duration = meta["duration"]
    problem.dt = meta["problem_dt"]
    return planned, source, problem, meta.get("error_check")


def _current(final: Path, candidates: list[Path], say: Callable[[str], None]) -> list[Path]:
    """The directories a resume of ``final`` may continue from: those holding a checkpoint newer than
    the finished run published in ``final`` (if any). A work directory holding no checkpoint, or only
    older ones — the previous result swapped out by a commit that was killed before removing it — is
    removed; an older partial run (``.interrupted``, ``.failed``) is left alone, and not continued."""
    from flexmm import checkpoint as ck

    published = _published(final)
    out = []
    for d in candidates:
        if not d.is_dir():
            continue
        stamps = [p.stat().st_mtime_ns for p in (d / ck.NAME, d / ck.PREVIOUS) if p.is_file()]
        if stamps and (published is None or max(stamps) > published):
            out.append(d)
        elif d.name.startswith("."):  # a work directory
            shutil.rmtree(d, ignore_errors=True)
            say(f"removed {d.name}: " + ("no checkpoint in it" if not stamps else
                                         f"older than the finished run in {final}"))
        else:
            say(f"not continued: {d} is older than the finished run in {final}")
    return out


def _published(final: Path) -> int | None:
    """When the finished run in ``final`` was written (its dataset's mtime, ns), None if there is none
    (only a finished run is published there: ``io.rundir``)."""
    try:
        return (final / "dataset.nc").stat().st_mtime_ns
    except OSError:
        return None


def _published_result(final: Path) -> RunResult:
    """The finished run published in ``final``, as the result of a run (nothing was run)."""
    import h5py

    def plain(v):
        v = v.item() if getattr(v, "size", 0) == 1 else v
        return v.decode() if isinstance(v, bytes) else v

    with h5py.File(final / "dataset.nc", "r") as f:
        a = {k: plain(v) for k, v in f.attrs.items()}
        t_end = float(f["time"][-1]) if f["time"].shape[0] else 0.0
    return RunResult("finished", "", final / "dataset.nc", int(a.get("n_steps", 0)), int(a.get("n_frames_written", 0)),
                     t_end, float(a.get("dt_s", 0.0)), float(a.get("stable_dt_s", 0.0)),
                     float(a.get("compile_time_s", 0.0)), 0.0, str(a.get("log", "")).splitlines(),
                     accuracy={k: v for k, v in a.items() if k.startswith("accuracy_") and "accuracy_estimate" in a})


def continue_point(found, scene: Scene, run_dir: str | Path, *, checkpoint_dir: str | Path,
                   checkpoint_s: float, log: Callable[[str], None] | None = None) -> RunResult:
    """Continue a sweep point kept in memory from checkpoint ``found`` (``run_scene`` with
    ``in_memory`` and ``checkpoint_dir``): its frames read back into memory, the run goes on writing
    checkpoints into ``checkpoint_dir``; config.yaml and run.log go to ``run_dir``. The dataset
    (``result.dataset``) is the one the point would have had run whole, bit for bit."""
    planned, source, problem, check = _continued(found, scene, extend=False, allow_version=False, from_work=True)
    from flexmm.prepare import whole_run_check

    meta = found.meta
    ckpt = Checkpointing(Path(checkpoint_dir), checkpoint_s, _checkpoint_meta(source, planned, meta["plan_attrs"], check))
    with _InPlace(Path(run_dir)) as rd:
        result = run_problem(problem, rd.stage, log=log, extra_attrs=meta["plan_attrs"], in_memory=True,
                             on_finish=whole_run_check(problem, **check) if check else None, checkpoints=ckpt,
                             resume=found)
        _publish(rd, rd.stage, planned, result)
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


__all__ = ["Measurements", "Result", "analyze", "build_problem", "continue_point", "continue_run", "load_scene", "render", "run",
           "run_dir_for", "run_scene"]
