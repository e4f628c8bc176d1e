"""Model builders and kernels; ``MODELS[kind]`` is the model registry (``flexmm.config.lattice``).

Each registry entry names the builder here of its kind (its module declares ``FIELDS``); tests
parametrise over the registry so a new model is checked automatically (force = −∇E, compiled =
numpy reference).
"""

from __future__ import annotations

from flexmm.config.lattice import MODELS, ModelSpec
from flexmm.models.base import FieldSpec, System


def model_fields(kind: str) -> tuple[str, ...]:
    """Names of the per-site coordinates of a model kind."""
    return tuple(f.name for f in MODELS[kind].fields)


def lattice_hinges(cfg):
    """(a, b, axis, wrap) of the hinges of a lattice of rotating units, in its builder's order (its
    kind's ``hinges`` hook); ``wrap`` marks the periodic wraps (b before a)."""
    a, b, axis = MODELS[cfg.kind].hook("hinges")(cfg)
    return a, b, axis, b <= a


__all__ = ["MODELS", "ModelSpec", "System", "FieldSpec", "lattice_hinges", "model_fields"]
