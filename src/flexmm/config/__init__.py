"""Declarative scene configs: YAML in, frozen Pydantic models out, errors with file:line."""

from flexmm.config.loader import ConfigError, load_scene, parse_overrides, resolve_scene, scene_from_dict
from flexmm.config.scene import Scene

__all__ = ["ConfigError", "Scene", "load_scene", "parse_overrides", "resolve_scene", "scene_from_dict"]
