"""Library entry points: load a scene, run it, summarise the result."""

from __future__ import annotations

from pathlib import Path
from typing import Callable

from flexmm.assemble import build_problem
from flexmm.config import Scene, load_scene
from flexmm.controller import RunResult, run_problem
from flexmm.io.provenance import config_text


def run_dir_for(scene: Scene, root: str | Path | None = None) -> Path:
    """Where a scene's outputs go: ``<output.directory>/<name>`` unless ``root`` is given."""
    return Path(root) if root is not None else Path(scene.output.directory) / scene.name


def run_scene(scene: Scene, *, run_dir: str | Path | None = None, progress: bool = False,
              log: Callable[[str], None] | None = None) -> RunResult:
    """Build and integrate a scene; write dataset.nc, config.yaml and run.log in its run dir."""
    out = run_dir_for(scene, run_dir)
    out.mkdir(parents=True, exist_ok=True)
    problem = build_problem(scene)
    result = run_problem(problem, out, progress=progress, log=log)
    _atomic_write(out / "config.yaml", config_text(scene))
    _atomic_write(out / "run.log", "\n".join(result.log) + "\n")
    return result


def _atomic_write(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(text)
    tmp.replace(path)


__all__ = ["load_scene", "run_scene", "run_dir_for", "build_problem"]
