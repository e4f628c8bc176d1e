"""The ``flexmm`` command line: a thin layer over the library, one module per command.

User errors (bad config, unstable dt) print a clear message and exit with status 2;
a failed run exits with 1; only genuine bugs show a traceback.
"""

from __future__ import annotations

import typer

from flexmm.cli import analyze as _analyze
from flexmm.cli import bench as _bench
from flexmm.cli import compare as _compare
from flexmm.cli import plan as _plan
from flexmm.cli import run as _run
from flexmm.cli import schema as _schema
from flexmm.cli import stability as _stability
from flexmm.cli import sweep as _sweep
from flexmm.cli import validate as _validate

app = typer.Typer(
    name="flexmm",
    help="Nonlinear waves in flexible mechanical metamaterials: run, validate and inspect scenes.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
app.command("run")(_run.run)
app.command("analyze")(_analyze.analyze)
app.command("validate")(_validate.validate)
app.command("schema")(_schema.schema)
app.command("sweep")(_sweep.sweep)
app.command("plan")(_plan.plan)
app.command("compare")(_compare.compare)
app.command("stability")(_stability.stability)
app.command("bench")(_bench.bench)


def main() -> None:
    app()
