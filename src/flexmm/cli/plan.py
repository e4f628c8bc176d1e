"""``flexmm plan CONFIG``: show what a run would model, in what size, with which step."""

from __future__ import annotations

import typer

from flexmm.assemble import UnstableStepError
from flexmm.cli.common import OverrideOption, error, load_or_exit

FidelityOption = typer.Option("auto", "--fidelity", "-f", help="auto (reduce what keeps the answer), full, continuum.")
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
    """Plan a scene: domain reach and trimming, planar chain, continuum, output, integrator and dt."""
    from flexmm.assemble import SceneError
    from flexmm.io.provenance import config_text
    from flexmm.plan import PlanError, make_plan
    from flexmm.plan.output import parse_analysis

    scene = load_or_exit(config, overrides)
    try:
        p = make_plan(scene, fidelity, parse_analysis(analysis))
    except (PlanError, UnstableStepError, SceneError, ValueError) as exc:
        raise error(f"{config}: {exc}") from None
    for line in p.lines():
        typer.echo(line)
    if show_config:
        typer.echo(config_text(p.scene))
