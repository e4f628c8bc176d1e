"""Helpers shared by CLI commands: loading a scene with user-facing errors."""

from __future__ import annotations

import sys

import typer

from flexmm.config import ConfigError, Scene, load_scene

EXIT_USER_ERROR = 2
EXIT_FAILED_RUN = 1

OverrideOption = typer.Option(
    None, "--set", "-s", help="Override a config value, e.g. --set solver.dt_s=1e-6 (repeatable)."
)


def error(message: str, code: int = EXIT_USER_ERROR) -> typer.Exit:
    typer.echo(f"error: {message}", err=True)
    return typer.Exit(code)


def load_or_exit(path: str, overrides: list[str] | None) -> Scene:
    try:
        return load_scene(path, overrides or [])
    except ConfigError as exc:
        n = len(exc.issues)
        typer.echo(f"error: {n} problem{'s' if n > 1 else ''} in the config:", err=True)
        for issue in exc.issues:
            typer.echo(f"  {issue}", err=True)
        raise typer.Exit(EXIT_USER_ERROR) from None


def stderr_is_tty() -> bool:
    return sys.stderr.isatty()
