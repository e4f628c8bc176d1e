"""The environment variables flexmm reads, each checked with a message naming it.

``VARIABLES`` lists them with what a value must be; ``number(name, default)`` reads a numeric
limit (``EnvironmentError_`` — a user error — when it is set to something that is not what the
variable expects: ``FLEXMM_MAX_MEMORY_GIB=abc`` is refused, not ignored). ``check()`` validates
every one that is set; the command line calls it before any command runs, so a mistake is
reported once, up front, whatever the command (``flexmm.cli``). An empty value counts as unset.

This module imports only the standard library and ``flexmm.errors`` (the bottom layer): the
JIT layer reads ``FLEXMM_NO_JIT`` at import and cannot raise there, so the CLI's ``check()``
is what refuses a bad one.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from dataclasses import dataclass

from flexmm.errors import FlexmmError


class EnvironmentVariableError(FlexmmError):
    """An environment variable flexmm reads is set to a value it cannot use."""


def _positive_number(text: str) -> float:
    value = float(text)
    if not math.isfinite(value) or value <= 0:
        raise ValueError
    return value


def _positive_integer(text: str) -> int:
    value = int(text)
    if value < 1:
        raise ValueError
    return value


def _switch(text: str) -> bool:
    if text not in ("0", "1"):
        raise ValueError
    return text == "1"


@dataclass(frozen=True)
class Variable:
    """One environment variable: how its value is read and what it must be (for the message)."""

    name: str
    parse: Callable[[str], object]
    expected: str
    meaning: str


VARIABLES = {v.name: v for v in (
    Variable("FLEXMM_MAX_MEMORY_GIB", _positive_number, "a positive number of GiB, e.g. 8 or 0.5",
             "memory a run may use before it is refused (default: 80 % of this machine's memory)"),
    Variable("FLEXMM_MAX_OUTPUT_GIB", _positive_number, "a positive number of GiB, e.g. 100",
             "size of a run's dataset before it is refused (default 100)"),
    Variable("FLEXMM_MAX_STEPS", _positive_number, "a positive number of steps, e.g. 1e10",
             "time steps of a run before it is refused (default 1e10)"),
    Variable("FLEXMM_NO_JIT", _switch, "0 or 1", "1 runs every kernel as plain Python (slow; for debugging)"),
    Variable("NUMBA_NUM_THREADS", _positive_integer, "a positive whole number of threads",
             "the most threads a parallel kernel may use (numba's own variable)"),
)}


def _error(name: str, raw: str) -> EnvironmentVariableError:
    var = VARIABLES[name]
    return EnvironmentVariableError(f"environment variable {name}={raw!r}: expected {var.expected}; it sets "
                                    f"{var.meaning} (unset it for the default)")


def value(name: str, default):
    """The parsed value of variable ``name`` (one of ``VARIABLES``), ``default`` when unset or
    empty; ``EnvironmentVariableError`` when set to something it cannot be."""
    raw = os.environ.get(name, "")
    if not raw.strip():
        return default
    try:
        return VARIABLES[name].parse(raw.strip())
    except (ValueError, OverflowError):
        raise _error(name, raw) from None


def number(name: str, default: float) -> float:
    """``value`` of a numeric limit, as a float."""
    return float(value(name, default))


def check() -> None:
    """Validate every variable of ``VARIABLES`` that is set (the first bad one is raised)."""
    for name in VARIABLES:
        value(name, None)


__all__ = ["VARIABLES", "EnvironmentVariableError", "Variable", "check", "number", "value"]
