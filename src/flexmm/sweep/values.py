"""Values of a varied parameter: explicit lists, linear and log ranges, the inline syntax.

Every parser returns ``(values, scale, error)``: a tuple of plain Python scalars, 'linear' or
'log' (how plots should space the axis), and an error message or None. Range values are rounded
to 12 significant digits so a point's config (and its hash) does not depend on floating-point
noise; integer bounds whose values are all integers give ints (``lattice.n_units=100:400:4``).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from flexmm.config.loader import parse_overrides

RANGE_KEYS = ("start", "stop", "num", "scale", "values")


def _round(x: float) -> float:
    return float(f"{x:.12g}")


def _yaml_scalar(text: str) -> Any:
    """A value read exactly as ``--set`` reads it (YAML scalar; 1e-3 is a float)."""
    return parse_overrides([f"_={text.strip()}"])[0][1]


def _range(start: Any, stop: Any, num: Any, scale: str) -> tuple[tuple, str | None]:
    """Values of a linear or log range, or (None, reason) if the bounds are unusable."""
    bad = [n for n, v in (("start", start), ("stop", stop)) if isinstance(v, bool) or not isinstance(v, (int, float))]
    if bad:
        return (), f"range {' and '.join(bad)} must be numbers"
    if isinstance(num, bool) or not isinstance(num, int) or num < 1:
        return (), f"range num must be an integer >= 1 (got {num!r})"
    if not (math.isfinite(start) and math.isfinite(stop)):
        return (), "range bounds must be finite"
    if scale == "log":
        if start <= 0 or stop <= 0:
            return (), f"a log range needs start > 0 and stop > 0 (got {start}, {stop})"
        vals = np.geomspace(start, stop, num)
    elif scale == "linear":
        vals = np.linspace(start, stop, num)
    else:
        return (), f"range scale must be 'linear' or 'log' (got {scale!r})"
    as_int = all(isinstance(v, int) for v in (start, stop)) and scale == "linear" and np.allclose(vals, np.round(vals))
    return tuple(int(round(v)) if as_int else _round(v) for v in vals), None


def parse_values(text: str) -> tuple[tuple, str, str | None]:
    """Parse ``start:stop:num``, ``log:start:stop:num`` or ``a,b,c`` -> (values, scale, error)."""
    text = str(text).strip()
    parts = text.split(":")
    if parts[0].strip().lower() in ("log", "lin", "linear") and len(parts) == 4:
        scale = "log" if parts[0].strip().lower() == "log" else "linear"
        parts = parts[1:]
    elif len(parts) == 3:
        scale = "linear"
    elif len(parts) == 1:
        vals = tuple(_yaml_scalar(p) for p in text.split(","))
        if any(v is None for v in vals):
            return (), "linear", "empty value in the list"
        return vals, "linear", None
    else:
        return (), "linear", "expected start:stop:num, log:start:stop:num or a,b,c"
    start, stop, num = (_yaml_scalar(p) for p in parts)
    vals, err = _range(start, stop, num, scale)
    return vals, scale, err



def values_of(spec: Any) -> tuple[tuple, str, str | None]:
    """Values from a sweep file entry: a list, {values, scale}, {start, stop, num, scale}, a string."""
    if isinstance(spec, list):
        return tuple(spec), "linear", None
    if isinstance(spec, dict):
        unknown = [k for k in spec if k not in RANGE_KEYS]
        if unknown:
            return (), "linear", f"unknown range key {unknown[0]!r}; expected {', '.join(RANGE_KEYS)}"
        if "values" in spec:
            scale = spec.get("scale", "linear")
            if set(spec) - {"values", "scale"} or not isinstance(spec["values"], list):
                return (), "linear", "give either `values: [...]` (and optionally `scale`) or start/stop/num"
            if scale not in ("linear", "log"):
                return (), "linear", f"scale must be 'linear' or 'log' (got {scale!r})"
            return tuple(spec["values"]), scale, None
        missing = [k for k in ("start", "stop", "num") if k not in spec]
        if missing:
            return (), "linear", f"range needs {', '.join(missing)}"
        scale = spec.get("scale", "linear")
        vals, err = _range(spec["start"], spec["stop"], spec["num"], scale)
        return vals, scale, err
    if isinstance(spec, str):
        return parse_values(spec)
    return (spec,), "linear", None
