"""Reading design and fit specs: YAML with file:line errors, the scene they refer to.

A spec names a scene file (``scene:``, relative to the spec) or holds it inline (a mapping);
both are validated like ``flexmm run`` scenes, errors pointing at the file and line.
"""

from __future__ import annotations

from pathlib import Path
from typing import TypeVar

from pydantic import BaseModel

from flexmm.config.loader import ConfigError, ConfigIssue, read_yaml, scene_from_dict, validate

M = TypeVar("M", bound=BaseModel)


def load_spec(path: str | Path, cls: type[M]) -> tuple[M, dict, Path]:
    """(validated spec, its raw dict, its directory)."""
    data, lines = read_yaml(path)
    spec = validate(cls, data, lines=lines, source=str(path))
    return spec, data, Path(path).resolve().parent


def scene_data_of(scene: str | dict, spec_path: str | Path, base_dir: Path) -> tuple[dict, str, Path]:
    """(scene dict, its source name, the directory its relative paths start from), validated once."""
    if isinstance(scene, dict):
        data, source, where = scene, f"{spec_path} (scene)", base_dir
        lines: dict = {}
    else:
        file = (base_dir / scene) if not Path(scene).is_absolute() else Path(scene)
        if not file.exists():
            raise ConfigError([ConfigIssue(str(spec_path), None, "scene", f"scene file {scene!r} not found "
                                                                           f"(looked in {base_dir})")])
        data, lines = read_yaml(file)
        source, where = str(file), file.resolve().parent
    scene_from_dict(data, lines=lines, source=source, base_dir=where)  # errors with the scene's lines
    return data, source, where
