"""Library entry points: load a scene, run it, summarise the result."""

from __future__ import annotations

from pathlib import Path
from typing import Callable

from flexmm.assemble import build_problem
from flexmm.config import Scene, load_scene
from flexmm.controller import RunResult, run_problem
from flexmm.io.atomic import write_text_atomic
from flexmm.io.provenance import config_text
from flexmm.io.rundir import RunDirectory


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
              in_memory: bool = False) -> RunResult:
    """Plan, build (once) and integrate a scene; publish dataset.nc, config.yaml and run.log together.

    ``fidelity`` and ``analysis`` go to ``flexmm.plan.make_plan`` ('full' runs the scene as
    declared; the CLI uses 'auto'); the plan is logged and stored in the dataset attrs, and
    config.yaml holds the scene that actually ran. The outputs are written in a private staging
    directory and committed with one rename (``io.rundir.RunDirectory``): a finished run becomes
    ``run_dir``; a failed or interrupted one goes to ``run_dir.failed`` / ``run_dir.interrupted``
    and never replaces a finished result. ``result.path`` is the committed dataset. A run of
    more steps than FLEXMM_MAX_STEPS is refused (``plan.cost.ResourceError``) unless
    ``force_limits``. ``atomic=False`` writes straight into ``run_dir`` for a caller that owns
    the directory and publishes its own markers (sweep points). ``in_memory`` keeps the dataset
    in ``result.dataset`` instead of writing dataset.nc (a sweep point measured and dropped; a
    continuum-only run still writes its file).
    """
    from flexmm.continuum_run import run_continuum
    from flexmm.plan import make_plan
    from flexmm.plan.cost import check_steps
    from flexmm.plan.output import parse_analysis
    from flexmm.prepare import accuracy_check, prepare

    out = run_dir_for(scene, run_dir)
    with (RunDirectory(out) if atomic else _InPlace(out)) as rd:
        plan = make_plan(scene, fidelity, parse_analysis(analysis))
        if plan.skip_discrete:
            result = run_continuum(plan.scene, plan.prediction, rd.stage, extra_attrs=plan.attrs(), log=log)
        else:
            problem = prepare(plan, lambda steps, dt_s, n: check_steps(steps, dt_s, n, force_limits))
            check_steps(problem.duration / problem.dt, problem.dt * problem.system.scales.time_s,
                        problem.system.n_sites, force_limits)
            result = run_problem(problem, rd.stage, progress=progress, log=log, extra_attrs=plan.attrs(),
                                 on_finish=accuracy_check(plan, problem), in_memory=in_memory)
        write_text_atomic(rd.stage / "config.yaml", config_text(plan.scene))
        write_text_atomic(rd.stage / "run.log", "\n".join(result.log) + "\n")
        where = rd.commit(result.status)
    result.path = None if result.dataset is not None or result.path is None else where / "dataset.nc"
    return result


__all__ = ["load_scene", "run_scene", "run_dir_for", "build_problem"]
