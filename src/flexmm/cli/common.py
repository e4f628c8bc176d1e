"""Helpers shared by CLI commands: the one user-error handler, loading a scene, output paths.

Every command is a ``UserErrorCommand``: a ``flexmm.errors.FlexmmError`` raised anywhere in it
(bad config, scene that cannot be built, unstable dt, impossible plan, unknown field, bad option,
unwritable output) is printed as ``error: <message>`` on stderr and exits with status 2, without
a traceback. Commands therefore raise user errors and never catch them to exit.

This module is imported for ``flexmm --help``: it must stay light (typer and the standard
library only; flexmm.config and heavier modules are imported inside functions).
"""

from __future__ import annotations

import os
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

import typer
from typer.core import TyperCommand, TyperGroup

from flexmm.errors import FlexmmError, OutputError, UsageError

if TYPE_CHECKING:
    from flexmm.config import Scene

EXIT_USER_ERROR = 2
EXIT_FAILED_RUN = 1
EXIT_INTERRUPTED = 130

OverrideOption = typer.Option(
    None, "--set", "-s", help="Override a config value, e.g. --set solver.dt_s=1e-6 (repeatable)."
)


def user_error_message(exc: FlexmmError, ctx: typer.Context | None = None) -> str:
    """``error: ...`` text of a user error, as printed by the CLI.

    A config error lists its issues (each ``file:line: path: got ...; expected ...``) under a
    count; an error about the scene (it cannot be built, dt too large, no plan) is prefixed with
    the CONFIG argument of the command; command-line and output errors name what they concern.
    """
    issues = getattr(exc, "issues", None)
    if issues:
        n = len(issues)
        what = ("command-line options" if all(i.source.startswith("--") for i in issues)
                else "sweep" if ctx is not None and ctx.command.name == "sweep" else "config")
        return "\n".join([f"error: {n} problem{'s' if n > 1 else ''} in the {what}:"]
                         + [f"  {issue}" for issue in issues])
    config = ctx.params.get("config") if ctx is not None else None
    if config and not isinstance(exc, UsageError | OutputError):
        return f"error: {config}: {exc}"
    return f"error: {exc}"


class _FlagsAsFlags:
    """Help shows ``--force``, not ``--force <bool>``: flags take no value, so they get no metavar.

    (Typer's rich help prints the type of every option, ``<bool>`` for flags included.)
    """

    def get_params(self, ctx: typer.Context) -> list:
        params = super().get_params(ctx)
        for param in params:
            if getattr(param, "is_flag", False) and param.metavar is None:
                param.metavar = ""
        return params


@contextmanager
def user_errors(ctx: typer.Context | None) -> Iterator[None]:
    """Turn a user error into ``error: <message>`` on stderr and exit status 2.

    This is the only place the CLI catches ``FlexmmError`` (the commands' ``invoke`` and the
    group's, which checks the environment before any command); everything else propagates (a
    failed run exits 1 via ``typer.Exit``, an interrupted sweep 130, a bug keeps its traceback).
    """
    try:
        yield
    except FlexmmError as exc:
        typer.echo(user_error_message(exc, ctx), err=True)
        raise typer.Exit(EXIT_USER_ERROR) from None


class UserErrorCommand(_FlagsAsFlags, TyperCommand):
    """A typer command that turns user errors into ``error: <message>`` and exit status 2
    (``user_errors``)."""

    def invoke(self, ctx: typer.Context):
        with user_errors(ctx):
            return super().invoke(ctx)


class FlexmmGroup(_FlagsAsFlags, TyperGroup):
    """The ``flexmm`` group: its own flags (``--version``, ``--help``, completion) shown as flags;
    a user error of its callback (a bad environment variable) reported like a command's."""

    def invoke(self, ctx: typer.Context):
        with user_errors(None):
            return super().invoke(ctx)


def error(message: str) -> UsageError:
    """A command-line error to raise: ``raise error("give --a or --b, not both")``."""
    return UsageError(message)


def load_or_exit(path: str, overrides: list[str] | None, options: dict | None = None) -> Scene:
    """Load and validate a scene; ``ConfigError`` (a user error: exit 2) if it does not validate.
    ``options``: config values set by other options, reported under their names (``load_scene``)."""
    from flexmm.config import load_scene

    return load_scene(path, overrides or [], options)


def analysis_request(spec: str | None):
    """Parse ``--analysis`` (pulse[:FIELD], front[:FIELD], energy, none); a ConfigError (a user
    error naming the option, the field and what was expected) if it is none of them."""
    from flexmm.plan.output import parse_analysis

    return parse_analysis(spec)


def check_output_dir(path: str | Path) -> Path:
    """An output directory that exists or can be created, checked before any work is done.

    ``OutputError`` if the path is an existing file, a parent is a file, or the nearest existing
    directory is not writable (tried with a temporary directory, removed at once).
    """
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise OutputError(f"output path {p} exists and is not a directory")
    probe = p.absolute()
    while not probe.exists():
        probe = probe.parent
    if not probe.is_dir():
        raise OutputError(f"cannot create output directory {p}: {probe} is not a directory")
    if not os.access(probe, os.W_OK | os.X_OK):
        raise OutputError(f"cannot create output directory {p}: {probe} is not writable")
    try:  # permissions are not enough (/proc, /sys, read-only mounts): try it
        tempfile.TemporaryDirectory(dir=probe, prefix=".flexmm-probe-").cleanup()
    except OSError as exc:
        raise OutputError(f"cannot create output directory {p}: cannot write in {probe} "
                          f"({exc.strerror or exc})") from None
    return p


def output_dir(path: str | Path) -> Path:
    """``check_output_dir``, then create the directory (and its parents)."""
    p = check_output_dir(path)
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot create output directory {p}: {exc.strerror or exc}") from None
    return p


@contextmanager
def writing(where: str | Path) -> Iterator[None]:
    """Turn an ``OSError`` while writing outputs into ``OutputError`` naming where and why."""
    try:
        yield
    except OSError as exc:
        name = f" {exc.filename}:" if exc.filename else ""
        raise OutputError(f"cannot write outputs in {where}:{name} {exc.strerror or exc}") from None


def stderr_is_tty() -> bool:
    return sys.stderr.isatty()


__all__ = ["EXIT_FAILED_RUN", "EXIT_INTERRUPTED", "EXIT_USER_ERROR", "FlexmmGroup", "OverrideOption",
           "UserErrorCommand", "analysis_request", "check_output_dir", "error", "load_or_exit", "output_dir",
           "stderr_is_tty", "user_error_message", "user_errors", "writing"]


def print_plan(lines: list[str], quiet: bool = False) -> None:
    """The plan's lines (``prepare.RunPlan.lines``) on stdout; with ``-q`` only its changes, on stderr."""
    for line in lines:
        if not quiet or line.startswith("plan: change:"):
            typer.echo(line, err=quiet)


def planned(scene: Scene, quiet: bool = False):
    """The problem ``flexmm run`` would integrate for ``scene`` (``prepare.resolve``, auto fidelity),
    its plan printed first (``print_plan``)."""
    from flexmm.prepare import resolve

    rp = resolve(scene, "auto")
    print_plan(rp.lines(), quiet)
    return rp.problem
