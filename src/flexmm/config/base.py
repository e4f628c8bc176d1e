"""Shared pieces of the config schema: the strict base model and common field types."""

from __future__ import annotations

import importlib
import types
import typing
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator
from pydantic_core import PydanticCustomError

Positive = Annotated[float, Field(gt=0, allow_inf_nan=False)]
NonNegative = Annotated[float, Field(ge=0, allow_inf_nan=False)]
Finite = Annotated[float, Field(allow_inf_nan=False)]
End = Literal["left", "right", "bottom", "top"]  # bottom/top: edges of 2D lattices
#: what holds an end of a lattice: nothing, a wall, or a drive of the excitation
EndCondition = Literal["free", "fixed", "driven"]
#: an edge of a 2D lattice may also wrap around to the opposite edge
EdgeCondition = Literal[EndCondition, "periodic"]


def check_periodic(cfg, a: str, b: str, n: int, what: str, even: str | None = None) -> bool:
    """Whether edges ``a``/``b`` of ``cfg`` wrap around (both 'periodic'); ValueError if only one
    does, or, when the units alternate (``even``: why), if the ``n`` units (``what``) are odd."""
    pa, pb = getattr(cfg, a) == "periodic", getattr(cfg, b) == "periodic"
    if pa != pb:
        raise ValueError(f"{a} and {b} must both be periodic or neither")
    if pa and even is not None and (n < 2 or n % 2):
        raise ValueError(f"periodic {a}/{b} needs an even {what} ≥ 2 ({even}), got {n}")
    return pa


def _scalar_types(annotation) -> set:
    """The plain types an annotation admits (through Optional/Union, Annotated, list, tuple)."""
    origin = typing.get_origin(annotation)
    if origin is Annotated:
        return _scalar_types(typing.get_args(annotation)[0])
    if origin in (typing.Union, types.UnionType, list, tuple, set, frozenset):
        return set().union(*(_scalar_types(a) for a in typing.get_args(annotation) if a is not Ellipsis))
    if origin is Literal:
        return {type(a) for a in typing.get_args(annotation)}
    return {annotation} if isinstance(annotation, type) else {object}


def _scalars(value):
    """``value`` and, for a list or tuple, its items (recursively)."""
    if isinstance(value, list | tuple):
        for item in value:
            yield from _scalars(item)
    else:
        yield value


#: pydantic error type of ``_check_numbers`` (the loader reports it at the field, with the value given)
COERCED_NUMBER = "coerced_number"


def _check_numbers(annotation, value) -> str | None:
    """What is wrong with ``value`` that pydantic's lax mode would quietly turn into a number (None
    if nothing): a boolean where a number is expected (``n_units: true`` would be 1), a float where
    only a whole number is (``n_frames: 1e7``, ``n_units: 2.0``)."""
    kinds = _scalar_types(annotation)
    if object in kinds or typing.Any in kinds:
        return None
    for v in _scalars(value):
        if isinstance(v, bool) and bool not in kinds and kinds & {int, float}:
            return "an integer (a boolean is not a number)" if float not in kinds else \
                "a number (a boolean is not a number)"
        if isinstance(v, float) and int in kinds and float not in kinds:
            example = f", e.g. {int(v)}" if v.is_integer() and abs(v) < 1e18 else ""
            return f"an integer, written without a decimal point or exponent{example}"
    return None


class Strict(BaseModel):
    """Frozen, closed model: unknown keys are errors, values are never silently coerced to str,
    and never to numbers either: a boolean where a number is expected and a float where an
    integer is are refused (``_check_numbers``), where pydantic's lax mode would accept them."""

    model_config = ConfigDict(extra="forbid", frozen=True, str_strip_whitespace=True)

    @model_validator(mode="before")
    @classmethod
    def _no_coerced_numbers(cls, data):
        if isinstance(data, dict):
            for name, field in cls.model_fields.items():
                key = field.alias or name
                if key in data and field.annotation is not None:
                    expected = _check_numbers(field.annotation, data[key])
                    if expected:
                        raise PydanticCustomError(COERCED_NUMBER, "{field}: got {given!r}; expected {expected}",
                                                  {"field": key, "given": data[key], "expected": expected})
        return data


class GridUnits(Strict):
    """Units on an n_rows × n_cols grid (site = row · n_cols + col) with four edges: the shape
    fields shared by the sheet-like lattices (rigid networks, the kagome of triangles)."""

    n_rows: int = Field(ge=1, le=100_000)
    n_cols: int = Field(ge=2, le=100_000)
    left: EdgeCondition = "free"
    right: EdgeCondition = "free"
    bottom: EdgeCondition = "free"
    top: EdgeCondition = "free"

    @property
    def n_sites(self) -> int:
        return self.n_rows * self.n_cols

    @property
    def n_units(self) -> int:
        return self.n_rows * self.n_cols

    def grid_copy(self, n: int, even: bool = False):
        """The same lattice cut to at most about ``n`` units (square, an even side if ``even``),
        for cheap estimates; not validated."""
        side = max(2, int(n**0.5))
        side += side % 2 if even else 0
        return self.model_copy(update={"n_rows": min(self.n_rows, side), "n_cols": min(self.n_cols, side),
                                       **({"variation": []} if "variation" in type(self).model_fields else {})})


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
