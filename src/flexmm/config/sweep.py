"""Sweep specs as config models: a base scene, fixed overrides, the parameters to vary.

A sweep file is a ``SweepFile``, read and validated like a scene (``loader.validate``): a
mistake is reported at the file's line with the field and what was expected. The points the
spec stands for are scenes, validated when ``flexmm.sweep.spec`` expands it.

The values of a varied parameter (``VaryValues``) are written as a list, ``{values: [...],
scale: log}``, a range ``{start, stop, num, scale}``, the inline string ``start:stop:num``,
``log:start:stop:num`` or ``a,b,c`` (as ``--vary``), or a single scalar. Range values are
rounded to 12 significant digits so a point's config (and its hash) does not depend on
floating-point noise; integer bounds whose values are all integers give ints
(``lattice.n_units=100:400:4``).
"""

from __future__ import annotations

import math
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import (
    Field,
    PlainValidator,
    StrictInt,
    WithJsonSchema,
    field_validator,
    model_validator,
)

from flexmm.config.analysis import AnalysisOptions
from flexmm.config.base import Strict
from flexmm.config.condition import Condition
from flexmm.config.loader import parse_overrides

#: how a plot spaces the axis of a varied parameter
Scale = Literal["linear", "log"]
INLINE_FORMS = "start:stop:num, log:start:stop:num or a,b,c"
_NAME = r"^[A-Za-z0-9_.-]+$"
#: ``keep:`` of a sweep: all, none, every N (points 0, N, 2N, ... in C order keep their dataset)
#: or ``where <condition>`` on the point's observables (``flexmm.config.condition``)
KEEP_PATTERN = r"^(all|none|every [1-9][0-9]*|where .+)$"
KEEP_FORMS = "all, none, 'every N' (N ≥ 1) or 'where <condition on observables>'"


def keep_every(keep: str) -> int:
    """The stride of a ``keep:`` value: 1 for all, 0 for none (and where), N for 'every N'."""
    if keep.startswith("where "):
        return 0
    return {"all": 1, "none": 0}.get(keep) if keep in ("all", "none") else int(keep.split()[1])


def keep_condition(keep: str) -> Condition | None:
    """The condition of ``keep: where <condition>`` (ValueError if malformed), else None."""
    return Condition.parse(keep[len("where "):]) if keep.startswith("where ") else None


def _number(value: Any) -> int | float:
    """An int or a finite float, kept as given (integer bounds give integer ranges)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError("a finite number")
    return value


#: a range bound: an int stays an int
Number = Annotated[Any, PlainValidator(_number), WithJsonSchema({"type": "number"})]


def _round(x: float) -> float:
    return float(f"{x:.12g}")


def _yaml_scalar(text: str) -> Any:
    """A value read exactly as ``--set`` reads it (YAML scalar; 1e-3 is a float)."""
    return parse_overrides([f"_={text.strip()}"])[0][1]


def parse_inline(text: str) -> dict:
    """``start:stop:num``, ``log:start:stop:num`` or ``a,b,c`` as the mapping of ``VaryValues``;
    ValueError if it is none of them."""
    text = str(text).strip()
    parts = text.split(":")
    if parts[0].strip().lower() in ("log", "lin", "linear") and len(parts) == 4:
        scale = "log" if parts[0].strip().lower() == "log" else "linear"
        parts = parts[1:]
    elif len(parts) == 3:
        scale = "linear"
    elif len(parts) == 1:
        vals = [_yaml_scalar(p) for p in text.split(",")]
        if any(v is None for v in vals):
            raise ValueError("a list without empty values")
        return {"values": vals}
    else:
        raise ValueError(INLINE_FORMS)
    start, stop, num = (_yaml_scalar(p) for p in parts)
    return {"start": start, "stop": stop, "num": num, "scale": scale}


class VaryValues(Strict):
    """The values of one varied parameter: explicit ``values``, or a range ``start``, ``stop``,
    ``num`` (both ends included; geometric with ``scale: log``)."""

    values: list[Any] | None = Field(None, min_length=1, description="explicit values")
    start: Number | None = Field(None, description="first value of a range")
    stop: Number | None = Field(None, description="last value of a range")
    num: StrictInt | None = Field(None, ge=1, description="number of values of a range")
    scale: Scale = Field("linear", description="range spacing, and how plots space the axis")

    @model_validator(mode="before")
    @classmethod
    def _shorthand(cls, data: Any) -> Any:
        if isinstance(data, list):
            return {"values": data}
        if isinstance(data, str):
            return parse_inline(data)
        if isinstance(data, dict) or data is None:
            return data
        return {"values": [data]}

    @model_validator(mode="after")
    def _one_form(self) -> VaryValues:
        bounds = {"start": self.start, "stop": self.stop, "num": self.num}
        if self.values is not None:
            given = [k for k, v in bounds.items() if v is not None]
            if given:
                raise ValueError(f"either values or start, stop and num (got values and {', '.join(given)})")
            return self
        missing = [k for k, v in bounds.items() if v is None]
        if missing:  # names no given key: the loader points at the entry itself
            raise ValueError(f"{', '.join(missing)}, which a range also needs (or explicit values: [...])")
        if self.scale == "log" and (self.start <= 0 or self.stop <= 0):
            raise ValueError(f"a log range with start > 0 and stop > 0 (got {self.start}, {self.stop})")
        return self

    def expand(self) -> tuple:
        """The values, as plain Python scalars."""
        if self.values is not None:
            return tuple(self.values)
        start, stop, num = self.start, self.stop, self.num
        vals = np.geomspace(start, stop, num) if self.scale == "log" else np.linspace(start, stop, num)
        as_int = (isinstance(start, int) and isinstance(stop, int) and self.scale == "linear"
                  and np.allclose(vals, np.round(vals)))
        return tuple(round(v) if as_int else _round(float(v)) for v in vals)


def _check_paths(section: dict[str, Any] | None) -> dict[str, Any] | None:
    """A section keyed by dotted config paths, each of non-empty keys."""
    for key in section or {}:
        if not key or any(not k for k in key.split(".")):
            raise ValueError(f"dotted paths of non-empty keys (got {key!r})")
    return section


class Vary(Strict):
    """The varied parameters, by dotted config path: a Cartesian ``grid`` or paired lists (``zip``)."""

    grid: dict[str, VaryValues] | None = Field(None, min_length=1, description="Cartesian product")
    zip: dict[str, VaryValues] | None = Field(None, min_length=1,
                                              description="lists of equal length, paired element-wise")

    _paths = field_validator("grid", "zip")(_check_paths)

    @model_validator(mode="after")
    def _one_mode(self) -> Vary:
        if (self.grid is None) == (self.zip is None):
            raise ValueError("exactly one of grid (a Cartesian product) or zip (paired lists)")
        if self.zip is not None and len({len(v.expand()) for v in self.zip.values()}) > 1:
            lens = ", ".join(f"{k}: {len(v.expand())}" for k, v in self.zip.items())
            raise ValueError(f"zipped lists of equal lengths (got {lens})")
        return self

    @property
    def mode(self) -> str:
        return "grid" if self.grid is not None else "zip"

    @property
    def axes(self) -> dict[str, VaryValues]:
        return self.grid if self.grid is not None else self.zip


class SweepFile(Strict):
    """A sweep spec file (``flexmm sweep SPEC``); docs/sweeps.md."""

    name: str | None = Field(None, pattern=_NAME, description="default: the file's stem")
    description: str = ""
    base: str | dict[str, Any] = Field(description="scene file (relative to this file) or an inline scene")
    set: dict[str, Any] = Field(default_factory=dict, description="fixed overrides, dotted.path: value (as --set)")
    vary: Vary
    analysis: AnalysisOptions = Field(default_factory=AnalysisOptions, description="how each point is measured")
    keep: str = Field("none", pattern=KEEP_PATTERN,
                      description="which points keep their full run directory: all, none, 'every N' or "
                                  "'where <condition on observables>'")

    _set_paths = field_validator("set")(_check_paths)

    @field_validator("keep")
    @classmethod
    def _keep_condition(cls, keep: str) -> str:
        keep_condition(keep)  # a malformed condition: ValueError, reported at the line of keep:
        return keep

    @field_validator("base", mode="before")
    @classmethod
    def _base_form(cls, v: Any) -> Any:
        if not isinstance(v, (str, dict)):
            raise ValueError("a scene file path (relative to this file) or an inline scene mapping")
        return v
