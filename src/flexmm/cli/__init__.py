"""The ``flexmm`` command line: a thin layer over the library, one module per command.

User errors (bad config, unstable dt) print a clear message and exit with status 2;
a failed run exits with 1; only genuine bugs show a traceback.
"""

from __future__ import annotations

import typer

from flexmm.cli import run as _run
from flexmm.cli import schema as _schema
from flexmm.cli import validate as _validate

app = typer.Typer(
    name="flexmm",
    help="Nonlinear waves in flexible mechanical metamaterials: run, validate and inspect scenes.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
app.command("run")(_run.run)
app.command("validate")(_validate.validate)
app.command("schema")(_schema.schema)


def main() -> None:
    app()
