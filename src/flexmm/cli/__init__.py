"""The ``flexmm`` command line: a thin layer over the library, one module per command.

User errors (``flexmm.errors.FlexmmError``: bad config, unstable dt, bad option, unwritable
output) print ``error: <message>`` and exit with status 2 (``cli.common.UserErrorCommand`` is
the one place they are caught); a failed run exits with 1, an interrupted sweep with 130; only
genuine bugs show a traceback.

Start-up is kept short: the command modules import only typer and the standard library at
module level, and load the library (numpy, numba, xarray, matplotlib, scipy) inside the
command, so ``flexmm --help``, ``flexmm schema`` and ``flexmm validate`` never import plotting
or signal processing (``tests/test_cli_startup.py``).
"""

from __future__ import annotations

import typer

from flexmm import __version__
from flexmm.cli import analyze as _analyze
from flexmm.cli import bands as _bands
from flexmm.cli import bench as _bench
from flexmm.cli import compare as _compare
from flexmm.cli import design as _design
from flexmm.cli import export as _export
from flexmm.cli import fit as _fit
from flexmm.cli import plan as _plan
from flexmm.cli import render as _render
from flexmm.cli import run as _run
from flexmm.cli import schema as _schema
from flexmm.cli import stability as _stability
from flexmm.cli import sweep as _sweep
from flexmm.cli import validate as _validate
from flexmm.cli.common import FlexmmGroup, UserErrorCommand

app = typer.Typer(
    name="flexmm",
    cls=FlexmmGroup,
    help="Nonlinear waves in flexible mechanical metamaterials: run, validate and inspect scenes.",
    no_args_is_help=True,
    add_completion=True,
    pretty_exceptions_enable=False,
)


def _print_version(value: bool) -> None:
    if value:
        typer.echo(f"flexmm {__version__}")
        raise typer.Exit()


@app.callback()
def _main(
    version: bool = typer.Option(False, "--version", "-V", callback=_print_version, is_eager=True,
                                 help="Print the flexmm version and exit."),
) -> None:
    """Nonlinear waves in flexible mechanical metamaterials: run, validate and inspect scenes."""
    from flexmm import environment

    environment.check()  # a bad FLEXMM_* / NUMBA_NUM_THREADS value is refused before any command runs


for _name, _func in (
    ("run", _run.run),
    ("analyze", _analyze.analyze),
    ("validate", _validate.validate),
    ("schema", _schema.schema),
    ("sweep", _sweep.sweep),
    ("plan", _plan.plan),
    ("compare", _compare.compare),
    ("stability", _stability.stability),
    ("bands", _bands.bands),
    ("bench", _bench.bench),
    ("render", _render.render),
    ("export", _export.export),
    ("fit", _fit.fit),
    ("design", _design.design),
):
    app.command(_name, cls=UserErrorCommand)(_func)


def main() -> None:
    """The console script: run the command; after a success, end the process without the
    interpreter's teardown when nothing else runs (issue 37: freeing numba's, scipy's and
    xarray's modules costs ~0.25 s of CPU and more of wall time, a quarter of a small run). Exit
    handlers run and the output is flushed first. A failure, an interruption (a signal may have
    stopped a kernel mid-call) or other threads alive: the ordinary exit — after a signal, with every
    object alive frozen out of the collector (``gc.freeze``), whose passes over them were most of
    the ~0.4 s of CPU between the run's last output and the exit (``benchmarks/signal_latency.py``):
    the outputs are committed and closed by then, and module teardown still runs."""
    try:
        app()
        code = 0
    except SystemExit as exc:
        code = exc.code
    _end(code)


def _end(code) -> None:
    import atexit
    import gc
    import os
    import signal
    import sys
    import threading

    if code is None:
        code = 0
    elif not isinstance(code, int):  # sys.exit("message"): printed, status 1
        print(code, file=sys.stderr)
        code = 1
    writer = sys.modules.get("flexmm.io.run_dataset")
    if writer is not None:
        writer.leave(code)  # a dataset HDF5 could not write is never closed: exit without its crash
    if code != 0 or threading.active_count() > 1:
        if code in (128 + signal.SIGINT, 128 + signal.SIGTERM):
            gc.freeze()
        sys.exit(code)
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe (``flexmm ... | head``) or stream
            pass
    os._exit(code)


__all__ = ["app", "main"]
