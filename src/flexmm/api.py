"""Library entry points: load a scene, run it, summarise the result."""

from __future__ import annotations

from pathlib import Path
from typing import Callable

from flexmm.assemble import build_problem
from flexmm.config import Scene, load_scene
from flexmm.controller import RunResult, run_problem
from flexmm.io.atomic import write_text_atomic
from flexmm.io.provenance import config_text


def run_dir_for(scene: Scene, root: str | Path | None = None) -> Path:
    """Where a scene's outputs go: ``<output.directory>/<name>`` unless ``root`` is given."""
    return Path(root) if root is not None else Path(scene.output.directory) / scene.name


def run_scene(scene: Scene, *, run_dir: str | Path | None = None, progress: bool = False,
              log: Callable[[str], None] | None = None, fidelity: str = "full",
              analysis: str | None = None) -> RunResult:
    """Plan, build (once) and integrate a scene; write dataset.nc, config.yaml and run.log in its run dir.

    ``fidelity`` and ``analysis`` go to ``flexmm.plan.make_plan`` ('full' runs the scene as
    declared; the CLI uses 'auto'); the plan is logged and stored in the dataset attrs, and
    config.yaml holds the scene that actually ran.
    """
    from flexmm.continuum_run import run_continuum
    from flexmm.plan import make_plan
    from flexmm.plan.output import parse_analysis
    from flexmm.prepare import accuracy_check, prepare

    out = run_dir_for(scene, run_dir)
    out.mkdir(parents=True, exist_ok=True)
    plan = make_plan(scene, fidelity, parse_analysis(analysis))
    if plan.skip_discrete:
        result = run_continuum(plan.scene, plan.prediction, out, extra_attrs=plan.attrs(), log=log)
    else:
        problem = prepare(plan)
        result = run_problem(problem, out, progress=progress, log=log, extra_attrs=plan.attrs(),
                             on_finish=accuracy_check(plan, problem))
    scene = plan.scene
    write_text_atomic(out / "config.yaml", config_text(scene))
    write_text_atomic(out / "run.log", "\n".join(result.log) + "\n")
    return result


__all__ = ["load_scene", "run_scene", "run_dir_for", "build_problem"]
