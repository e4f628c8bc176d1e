"""The one base of user errors, and the CLI's own user-error classes.

``FlexmmError`` is the base of every error caused by the user's input or environment: a config
that does not validate (``ConfigError``), a scene that cannot be built (``SceneError``), a time
step above the stable limit (``UnstableStepError``), a plan that cannot be made
(``PlanError``), a field or run that does not exist (``FieldError``, ``RunNotFound``), a bad
command line (``UsageError``), outputs that cannot be written (``OutputError``). ``str()`` of
each is a complete, readable message.

The command line catches ``FlexmmError`` in one place (``flexmm.cli.common.UserErrorCommand``)
and prints ``error: <message>`` on stderr, without a traceback, and exits with status 2. Any
other exception is a bug and keeps its traceback. Library code raises the specific subclass;
callers that only want "the user has to fix something" catch ``FlexmmError``.

This module imports nothing, so any module can import it without cost or cycles.
"""

from __future__ import annotations


class FlexmmError(Exception):
    """Base of every error caused by the user's input or environment, not by a bug in flexmm.

    The CLI catches it once, prints ``error: <message>`` (no traceback) and exits with status 2.
    """


class UsageError(FlexmmError):
    """The command line asks for something impossible: an unknown option value, options that
    conflict, or an input path that does not exist."""


class OutputError(FlexmmError):
    """Outputs cannot be written: the output path is an existing file, a directory is not
    writable, or writing failed (disk full, permissions)."""


class PlanError(FlexmmError, ValueError):
    """A plan that cannot be made as asked (``flexmm.plan``): too small a lattice to probe, no
    integrator that can be costed, an unknown analysis, a lattice that cannot be trimmed."""


__all__ = ["FlexmmError", "OutputError", "PlanError", "UsageError"]
