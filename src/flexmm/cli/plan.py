"""``flexmm plan CONFIG``: show what a run would model, in what size, with which step."""

from __future__ import annotations

import typer

from flexmm.cli.common import OverrideOption, analysis_request, error, load_or_exit

FidelityOption = typer.Option(
    "auto", "--fidelity", "-f",
    help="auto (reduce what keeps the answer), full (as declared), chain (a sheet's planar wave on its two-row "
         "chain, approximate), continuum (docs/fidelity.md).")


def check_fidelity(value: str) -> None:
    """A UsageError under ``--fidelity`` naming the valid values (``plan.FIDELITIES``, each in
    the option's help) unless ``value`` is one of them."""
    from flexmm.plan import FIDELITIES

    if value not in FIDELITIES:
        raise error(f"--fidelity {value!r}: expected one of {', '.join(FIDELITIES)} (docs/fidelity.md)")

AnalysisOption = typer.Option(
    None, "--analysis", "-a", help="What the run is for: pulse[:FIELD], front[:FIELD], energy (prunes the output)."
)


def plan(
    config: str = typer.Argument(..., help="Scene YAML file."),
    overrides: list[str] = OverrideOption,
    fidelity: str = FidelityOption,
    analysis: str = AnalysisOption,
    show_config: bool = typer.Option(False, "--show-config", help="Also print the planned scene as YAML."),
) -> None:
    """Plan a scene: domain reach and trimming, planar chain, continuum, output, integrator and dt,
    and what the planned run would cost (steps, memory, output size; flexmm.plan.cost)."""
    from flexmm.io.provenance import config_text
    from flexmm.plan.cost import check
    from flexmm.prepare import resolve

    check_fidelity(fidelity)
    request = analysis_request(analysis)
    scene = load_or_exit(config, overrides)
    rp = resolve(scene, fidelity, request)  # the accuracy pilots run to choose the step; nothing is written
    for line in rp.plan.lines() + rp.lines():
        typer.echo(line)
    if rp.cost is not None:
        for w in check(rp.cost):
            typer.echo(f"plan: WARNING: {w}")
    if show_config:
        typer.echo(config_text(rp.plan.scene))
