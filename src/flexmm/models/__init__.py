"""Model registry: ``MODELS[kind]`` builds a System from a lattice config.

Each entry is a plain record (no import side effects); tests parametrise over it so a new
model is checked automatically (force = −∇E, compiled = numpy reference).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from flexmm.models import linkage, mass_chain, rotating_chain, rotating_sheet, rotating_triangles
from flexmm.models.base import FieldSpec, System


@dataclass(frozen=True)
class ModelEntry:
    """How to build one lattice kind, and what it offers."""

    build: Callable[..., System]
    fields: tuple[FieldSpec, ...]
    launch_soliton: Callable[..., None] | None = None
    #: the launcher knows the prestressed theory (solitons on a predeformed lattice)
    soliton_on_predeformed: bool = False


MODELS: dict[str, ModelEntry] = {
    "rotating_squares_chain": ModelEntry(
        rotating_chain.build, rotating_chain.FIELDS, rotating_chain.launch_soliton, True
    ),
    "rotating_squares_sheet": ModelEntry(
        rotating_sheet.build, rotating_sheet.FIELDS, rotating_sheet.launch_soliton
    ),
    "rotating_triangles_chain": ModelEntry(rotating_triangles.build_chain, rotating_triangles.FIELDS),
    "rotating_triangles_sheet": ModelEntry(rotating_triangles.build_sheet, rotating_triangles.FIELDS),
    "bistable_linkage": ModelEntry(linkage.build, rotating_sheet.FIELDS),
    "mass_chain": ModelEntry(mass_chain.build, mass_chain.FIELDS),
    "mass_network": ModelEntry(mass_chain.build, mass_chain.FIELDS),
    "mass_grid": ModelEntry(mass_chain.build, mass_chain.FIELDS),
}


def model_fields(kind: str) -> tuple[str, ...]:
    """Names of the per-site coordinates of a model kind."""
    return tuple(f.name for f in MODELS[kind].fields)


__all__ = ["MODELS", "ModelEntry", "System", "FieldSpec", "model_fields"]
