"""``flexmm schema [scene|sweep]``: print the JSON schema of scene configs or sweep specs."""

from __future__ import annotations

import json

import typer

from flexmm.cli.common import error


def schema(
    what: str = typer.Argument("scene", help="scene (a scene config) or sweep (a sweep spec)."),
) -> None:
    """Print the JSON schema of a scene config or a sweep spec (for editors and documentation)."""
    if what == "scene":
        from flexmm.config import Scene as model
    elif what == "sweep":
        from flexmm.config.sweep import SweepFile as model
    else:
        raise error(f"schema of {what!r}: choose scene or sweep")
    print(json.dumps(model.model_json_schema(), indent=2))
