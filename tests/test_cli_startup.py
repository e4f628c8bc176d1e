"""``flexmm --help``, ``validate`` and ``schema`` start fast: no plotting, xarray or signal processing.

Each case runs in a fresh interpreter (the test process has imported everything already) and
lists the heavy modules that are loaded after the command ran through Typer's CliRunner.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "lego_vector_soliton.yaml"

PROBE = """
import json, sys
from typer.testing import CliRunner
from flexmm.cli import app
result = CliRunner().invoke(app, json.loads(sys.argv[1]))
assert result.exit_code == 0, result.output
heavy = sorted(m for m in sys.modules
               if m.split('.')[0] in ('matplotlib', 'xarray', 'pandas') or m.startswith('scipy.signal'))
print(json.dumps({"heavy": heavy, "scipy": 'scipy' in sys.modules, "numba": 'numba' in sys.modules}))
"""


def loaded_after(*args: str) -> dict:
    proc = subprocess.run([sys.executable, "-c", PROBE, json.dumps(list(args))],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("args", [["--help"], ["--version"], ["schema"], ["run", "--help"], ["analyze", "--help"],
                                  ["validate", str(CONFIG)], ["validate", str(CONFIG), "--no-build"]],
                         ids=["help", "version", "schema", "run-help", "analyze-help", "validate", "validate-no-build"])
def test_no_plotting_xarray_or_signal_imports(args):
    assert loaded_after(*args)["heavy"] == []


def test_help_imports_neither_scipy_nor_numba():
    loaded = loaded_after("--help")
    assert not loaded["scipy"] and not loaded["numba"]
