"""``flexmm plan``, ``flexmm compare`` and ``flexmm run --fidelity`` (CliRunner)."""

from __future__ import annotations

from pathlib import Path

import yaml
from conftest import LEGO_CHAIN
from typer.testing import CliRunner

from flexmm.cli import app

ROOT = Path(__file__).resolve().parents[2]
runner = CliRunner()
LEGO = LEGO_CHAIN


def write(tmp_path, data) -> str:
    path = tmp_path / "scene.yaml"
    path.write_text(yaml.safe_dump(data))
    return str(path)


def test_plan_prints_every_decision():
    res = runner.invoke(app, ["plan", str(ROOT / "configs" / "lego_vector_soliton.yaml"), "-a", "pulse"])
    assert res.exit_code == 0, res.output
    for step in ("dimension:", "domain:", "continuum:", "output:"):
        assert step in res.output
    assert "output.fields = ['theta']" in res.output


def test_plan_trims_a_long_chain(tmp_path):
    cfg = write(tmp_path, {"name": "long", "lattice": {**LEGO, "n_units": 3000, "left": "driven"},
                           "excitation": {"kind": "impact", "velocity_m_s": 1.0},
                           "solver": {"duration_s": 0.01}})
    res = runner.invoke(app, ["plan", cfg, "--show-config"])
    assert res.exit_code == 0, res.output
    assert "trimmed to units 0.." in res.output
    res = runner.invoke(app, ["plan", cfg, "--fidelity", "full"])
    assert "WARNING" in res.output and "never reached" in res.output


def test_bad_fidelity_is_a_user_error():
    """Reported under --fidelity, listing the valid values, each of which the option's help documents."""
    from flexmm.plan import FIDELITIES

    for verb in ("plan", "run"):
        res = runner.invoke(app, [verb, str(ROOT / "configs" / "lego_vector_soliton.yaml"), "-f", "half"])
        assert res.exit_code == 2 and res.stderr.startswith("error: --fidelity 'half': expected one of "
                                                            f"{', '.join(FIDELITIES)}"), res.stderr
        usage = " ".join(runner.invoke(app, [verb, "--help"], env={"COLUMNS": "400"}).output.split())
        for value in FIDELITIES:
            assert f"{value} (" in usage or f"{value}." in usage, (value, usage)
    res = runner.invoke(app, ["compare", str(ROOT / "configs" / "lego_vector_soliton.yaml"), "-f", "full"])
    assert res.exit_code == 2


def test_compare_full_and_continuum(tmp_path):
    cfg = write(tmp_path, {"name": "sol", "lattice": {**LEGO, "n_units": 160},
                           "excitation": {"kind": "soliton", "amplitude_rad": 0.4, "center_site": 30},
                           "solver": {"duration_s": 0.25}, "output": {"n_frames": 101}})
    res = runner.invoke(app, ["compare", cfg, "-f", "full,continuum", "-o", str(tmp_path / "cmp"), "-q"])
    assert res.exit_code == 0, res.output
    assert "speed (m/s)" in res.output and "solve + plan" in res.output
    speed = next(line for line in res.output.splitlines() if "speed" in line)
    assert abs(float(speed.split()[-1].rstrip("%"))) < 1.0


def test_run_records_the_plan(tmp_path):
    from flexmm.io.run_dataset import open_run

    cfg = write(tmp_path, {"name": "r", "lattice": {**LEGO, "n_units": 400, "left": "driven"},
                           "excitation": {"kind": "impact", "velocity_m_s": 1.0, "angular_velocity_rad_s": 100.0},
                           "solver": {"duration_s": 0.005}, "output": {"n_frames": 11}})
    res = runner.invoke(app, ["run", cfg, "-o", str(tmp_path / "run"), "-a", "pulse", "-q"])
    assert res.exit_code == 0, res.output
    ds = open_run(tmp_path / "run")
    assert ds.attrs["plan_fidelity"] == "auto" and ds.attrs["plan_domain"] == "trimmed"
    assert ds.sizes["site"] < 400 and "u" not in ds and "theta" in ds
    assert "plan (auto" in (tmp_path / "run" / "run.log").read_text()
    assert yaml.safe_load((tmp_path / "run" / "config.yaml").read_text())["lattice"]["n_units"] == ds.sizes["site"]
