"""``flexmm compare CONFIG --fidelity A,B``: run two fidelities, report observables and cost."""

from __future__ import annotations

from pathlib import Path

import typer

from flexmm.cli.common import (
    OverrideOption, analysis_request, check_output_dir, error, load_or_exit, print_plan, writing,
)


def compare(
    config: str = typer.Argument(..., help="Scene YAML file."),
    fidelity: str = typer.Option("full,auto", "--fidelity", "-f", help="Two fidelities, e.g. full,auto or full,continuum."),
    overrides: list[str] = OverrideOption,
    analysis: str = typer.Option("pulse", "--analysis", "-a", help="pulse[:FIELD] or front[:FIELD]."),
    out: str = typer.Option(None, "--out", "-o", help="Directory for the runs (default output.directory/NAME/compare)."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Print only the comparison."),
) -> None:
    """Run a scene at two fidelities and report differences in speed, amplitude, width and cost.

    Each fidelity's plan (`flexmm plan --fidelity F`'s lines) is printed before its run."""
    from flexmm.fidelity import compare_fidelities
    from flexmm.plan import FIDELITIES

    pair = tuple(f.strip() for f in fidelity.split(","))
    if len(pair) != 2 or any(f not in FIDELITIES for f in pair):
        raise error(f"--fidelity takes two of {', '.join(FIDELITIES)} separated by a comma, got {fidelity!r}")
    request = analysis_request(analysis)
    if request is None or request.kind not in ("pulse", "front"):
        raise error("--analysis must be pulse[:FIELD] or front[:FIELD]")
    scene = load_or_exit(config, overrides)
    root = check_output_dir(Path(out) if out else Path(scene.output.directory) / scene.name / "compare")
    log = None if quiet else (lambda m: typer.echo(m, err=True))
    def announce(fid: str, lines: list[str]) -> None:  # with -q only the changes, on stderr
        if not quiet or any(ln.startswith("plan: change:") for ln in lines):
            typer.echo(f"fidelity {fid}:", err=quiet)
        print_plan(lines, quiet)

    with writing(root):
        cmp = compare_fidelities(scene, pair, root, request, log=log, announce=announce)
    for line in cmp.table():
        typer.echo(line)
