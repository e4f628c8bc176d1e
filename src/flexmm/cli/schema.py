"""``flexmm schema``: print the JSON schema of scene configs."""

from __future__ import annotations

import json

from flexmm.config import Scene


def schema() -> None:
    """Print the JSON schema of a scene config (for editors and documentation)."""
    print(json.dumps(Scene.model_json_schema(), indent=2))
