"""The package's structure stays as declared: layered, acyclic, one kernel table.

The import-linter contracts in pyproject.toml ([tool.importlinter]) list the layers top to
bottom and forbid cycles between sibling modules; this test runs them, so a new upward or
circular import fails CI with the offending import chain.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path
from typing import get_args

import pytest

from flexmm.config.lattice import LatticeConfig
from flexmm.models import MODELS, model_fields

ROOT = Path(__file__).resolve().parents[1]


def test_import_contracts_hold() -> None:
    exe = shutil.which("lint-imports", path=str(Path(sys.executable).parent))
    assert exe is not None, "import-linter is a test dependency (pyproject [test] extra)"
    out = subprocess.run([exe, "--no-cache"], cwd=ROOT, capture_output=True, text=True)
    assert out.returncode == 0, out.stdout[-4000:] + out.stderr[-2000:]
    assert "2 kept, 0 broken" in out.stdout


def _lattice_classes() -> dict[str, type]:
    classes = {}
    for cls in get_args(LatticeConfig):
        kind = get_args(cls.model_fields["kind"].annotation)[0]
        classes[kind] = cls
    return classes


@pytest.mark.parametrize("kind", sorted(MODELS))
def test_config_declares_the_fields_its_model_builds(kind: str) -> None:
    """The config layer names each kind's fields (to validate output.fields without importing
    the models); the model's FieldSpecs must agree."""
    assert _lattice_classes()[kind].FIELD_NAMES == model_fields(kind)
