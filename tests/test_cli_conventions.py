"""CLI conventions: --version, shell completion, flags shown as flags, -q, and user errors.

User errors of every kind derive from ``flexmm.errors.FlexmmError`` and are caught in one place
(``cli.common.UserErrorCommand``): ``error: <message>`` on stderr, exit status 2, no traceback.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest
from typer.testing import CliRunner

import flexmm
from flexmm.cli import app
from flexmm.errors import FlexmmError, OutputError, UsageError

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "configs" / "lego_vector_soliton.yaml"
COMMANDS = ["run", "analyze", "validate", "schema", "sweep", "plan", "compare", "stability", "bench", "bands"]
runner = CliRunner()


def invoke(*args):
    result = runner.invoke(app, [str(a) for a in args])
    assert "Traceback" not in result.output
    return result


@pytest.mark.parametrize("flag", ["--version", "-V"])
def test_version(flag):
    result = invoke(flag)
    assert result.exit_code == 0
    assert result.output.strip() == f"flexmm {flexmm.__version__}"


def test_completion_options_are_offered(monkeypatch):
    result = invoke("--help")
    assert result.exit_code == 0
    assert "--install-completion" in result.output and "--show-completion" in result.output
    # the user's shell, as typer detects it from the parent processes (none when the suite is
    # started from a script or a scheduler: detection then fails, whatever flexmm does)
    import typer.completion

    monkeypatch.setattr(typer.completion, "_get_shell_name", lambda: "bash")
    result = invoke("--show-completion")
    assert result.exit_code == 0 and "complete" in result.output and "flexmm" in result.output.lower()


@pytest.mark.parametrize("command", [None, *COMMANDS])
def test_flags_have_no_value_metavar(command):
    result = invoke(*([command] if command else []), "--help")
    assert result.exit_code == 0, result.output
    assert "<bool>" not in result.output and "BOOLEAN" not in result.output


@pytest.mark.parametrize("command", ["run", "sweep", "analyze", "bench", "stability", "bands"])
def test_writing_verbs_have_quiet(command):
    result = invoke(command, "--help")
    assert re.search(r"--quiet\s+-q", result.output), result.output


def test_user_error_classes_share_one_base():
    from flexmm.analysis.features.fields import FieldError
    from flexmm.analysis.report.analyze import RunNotFound
    from flexmm.assemble import SceneError
    from flexmm.config import ConfigError
    from flexmm.plan import PlanError
    from flexmm.stability import UnstableStepError

    for cls in (ConfigError, SceneError, UnstableStepError, PlanError, FieldError, RunNotFound, UsageError,
                OutputError):
        assert issubclass(cls, FlexmmError), cls
    for cls in (SceneError, PlanError, FieldError):  # callers that catch ValueError still do
        assert issubclass(cls, ValueError), cls


def test_cli_catches_user_errors_in_one_place():
    """No command module catches a user-error class to print and exit: only cli/common.py does."""
    names = {"FlexmmError", "ConfigError", "SceneError", "UnstableStepError", "PlanError", "FieldError",
             "RunNotFound", "UsageError", "OutputError"}
    catchers = []
    for path in sorted((ROOT / "src" / "flexmm" / "cli").glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ExceptHandler) and node.type is not None:
                caught = {n.id if isinstance(n, ast.Name) else getattr(n, "attr", "") for n in ast.walk(node.type)}
                # re-raising unchanged (``except FlexmmError: raise``) is not handling
                reraises = len(node.body) == 1 and isinstance(node.body[0], ast.Raise) and node.body[0].exc is None
                if caught & names and not reraises:
                    catchers.append(f"{path.name}:{node.lineno}")
    assert len(catchers) == 1 and catchers[0].startswith("common.py:"), catchers


def test_unknown_option_value_is_a_user_error():
    result = invoke("plan", CONFIG, "--analysis", "bogus")
    assert result.exit_code == 2
    assert ("error: 1 problem in the command-line options:\n  --analysis bogus: kind: got 'bogus' (str); "
            "expected: input should be 'pulse', 'front' or 'energy'") in result.output


def test_output_path_that_is_a_file_exits_2(tmp_path):
    blocker = tmp_path / "blocker"
    blocker.write_text("not a directory")
    result = invoke("run", CONFIG, "--out", blocker, "--fidelity", "full")
    assert result.exit_code == 2, result.output
    assert f"error: output path {blocker} exists and is not a directory" in result.output
    assert blocker.read_text() == "not a directory"
    result = invoke("run", CONFIG, "--out", blocker / "run", "--fidelity", "full")
    assert result.exit_code == 2 and "is not a directory" in result.output


def test_analyze_quiet_prints_only_paths(tmp_path):
    from synthetic import SynthPulse, pulse_dataset

    run = tmp_path / "run"
    run.mkdir()
    pulse_dataset([SynthPulse(0.2, 1.0, 3.0, 20.0)]).to_netcdf(run / "dataset.nc", engine="h5netcdf")
    result = invoke("analyze", run, "-q", "--json", tmp_path / "summary.json")
    assert result.exit_code == 0, result.output
    assert result.output.split() == [str(run / "analysis.nc"), str(tmp_path / "summary.json")]
    assert (run / "analysis.nc").exists() and (tmp_path / "summary.json").exists()


def test_run_quiet_prints_only_the_dataset_path(tmp_path):
    import yaml

    cfg = yaml.safe_load(CONFIG.read_text())
    cfg["lattice"]["n_units"] = 30
    cfg["damping"] = {}
    cfg["solver"]["duration_s"] = 2e-3
    cfg["output"] = {"n_frames": 5}
    path = tmp_path / "small.yaml"
    path.write_text(yaml.safe_dump(cfg))
    result = invoke("run", path, "--out", tmp_path / "run", "--fidelity", "full", "-q")
    assert result.exit_code == 0, result.output
    assert result.output.strip() == str(tmp_path / "run" / "dataset.nc")
