"""Shared pieces of the config schema: the strict base model and common field types."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field

Positive = Annotated[float, Field(gt=0, allow_inf_nan=False)]
NonNegative = Annotated[float, Field(ge=0, allow_inf_nan=False)]
Finite = Annotated[float, Field(allow_inf_nan=False)]
End = Literal["left", "right", "bottom", "top"]  # bottom/top: edges of 2D lattices


class Strict(BaseModel):
    """Frozen, closed model: unknown keys are errors, values are never silently coerced to str."""

    model_config = ConfigDict(extra="forbid", frozen=True, str_strip_whitespace=True)
