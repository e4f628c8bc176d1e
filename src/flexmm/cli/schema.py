"""``flexmm schema``: print the JSON schema of scene configs."""

from __future__ import annotations

import json


def schema() -> None:
    """Print the JSON schema of a scene config (for editors and documentation)."""
    from flexmm.config import Scene

    print(json.dumps(Scene.model_json_schema(), indent=2))
