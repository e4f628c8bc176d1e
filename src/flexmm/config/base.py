"""Shared pieces of the config schema: the strict base model and common field types."""

from __future__ import annotations

import importlib
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field

Positive = Annotated[float, Field(gt=0, allow_inf_nan=False)]
NonNegative = Annotated[float, Field(ge=0, allow_inf_nan=False)]
Finite = Annotated[float, Field(allow_inf_nan=False)]
End = Literal["left", "right", "bottom", "top"]  # bottom/top: edges of 2D lattices
#: what holds an end of a lattice: nothing, a wall, or a drive of the excitation
EndCondition = Literal["free", "fixed", "driven"]
#: an edge of a 2D lattice may also wrap around to the opposite edge
EdgeCondition = Literal[EndCondition, "periodic"]


class Strict(BaseModel):
    """Frozen, closed model: unknown keys are errors, values are never silently coerced to str."""

    model_config = ConfigDict(extra="forbid", frozen=True, str_strip_whitespace=True)


def exactly_one(model: Strict, a: str, b: str, meanings: tuple[str, str] | None = None) -> Strict:
    """Require exactly one of the optional fields ``a`` and ``b``; return the model.

    For use in ``model_validator(mode="after")``; the message names both fields (the loader
    uses the names to point at the right lines).
    """
    if (getattr(model, a) is None) == (getattr(model, b) is None):
        la, lb = (f"{a} ({meanings[0]})", f"{b} ({meanings[1]})") if meanings else (a, b)
        raise ValueError(f"give exactly one of {la} or {lb}")
    return model


def resolve(path: str) -> Any:
    """The object a registry hook names: ``"package.module:attribute"`` (or a bare module path).

    Registries live in the config layer but name behaviour of higher layers (builders, theories,
    continuum predictors, the assembler); a hook is imported only when the layer that uses it asks
    for it, so importing the config never imports those layers (docs/architecture.md, Registries).
    """
    module, _, attr = path.partition(":")
    obj = importlib.import_module(module)
    return getattr(obj, attr) if attr else obj
