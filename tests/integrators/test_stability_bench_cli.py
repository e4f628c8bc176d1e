"""``flexmm stability`` and ``flexmm bench`` end to end on a tiny scene (typer's CliRunner)."""

from __future__ import annotations

import json

import pytest
import xarray as xr
import yaml
from integrator_helpers import LEGO
from typer.testing import CliRunner

from flexmm.cli import app

runner = CliRunner()


@pytest.fixture()
def tiny_config(tmp_path):
    scene = {
        "name": "tiny",
        "lattice": dict(LEGO, n_units=20),
        "excitation": {"kind": "soliton", "amplitude_rad": 0.4, "center_site": 6},
        "solver": {"duration_s": 0.01},
        "output": {"n_frames": 11, "directory": str(tmp_path / "runs")},
    }
    path = tmp_path / "tiny.yaml"
    path.write_text(yaml.safe_dump(scene))
    return path


def test_stability_command(tiny_config, tmp_path) -> None:
    out = tmp_path / "stab"
    res = runner.invoke(app, ["stability", str(tiny_config), "--methods", "velocity_verlet", "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "velocity_verlet" in res.output and "measured" in res.output
    rows = json.loads((out / "stability.json").read_text())
    assert rows[0]["method"] == "velocity_verlet" and 0.9 < rows[0]["ratio"] < 1.5
    assert (out / "stability.png").stat().st_size > 1000


def test_stability_linear_uses_the_growth_criterion(tiny_config, tmp_path) -> None:
    out = tmp_path / "lin"
    res = runner.invoke(app, ["stability", str(tiny_config), "--methods", "velocity_verlet", "--linear",
                              "--growth-threshold", "1e-3", "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "amplitude growth above 0.001 per step" in res.output and "not |R| > 1" in res.output
    row = json.loads((out / "stability.json").read_text())[0]
    assert abs(row["ratio"] - 1.0) < 0.01 and abs(row["ratio_to_threshold"] - 1.0) < 0.01


def test_growth_threshold_needs_linear(tiny_config) -> None:
    res = runner.invoke(app, ["stability", str(tiny_config), "--growth-threshold", "1e-4"])
    assert res.exit_code == 2 and "only with --linear" in res.output


def test_stability_rejects_unknown_method(tiny_config) -> None:
    res = runner.invoke(app, ["stability", str(tiny_config), "--methods", "euler"])
    assert res.exit_code == 2 and "unknown integrator" in res.output


def test_bench_command(tiny_config, tmp_path) -> None:
    out = tmp_path / "bench"
    res = runner.invoke(app, ["bench", str(tiny_config), "--methods", "velocity_verlet", "--ivp", "RK45",
                              "--repeats", "1", "--out", str(out)])
    assert res.exit_code == 0, res.output
    ds = xr.open_dataset(out / "workprecision.nc", engine="h5netcdf")
    assert set(ds.method.values) == {"velocity_verlet", "RK45"}
    assert "11 frames" in res.output  # the scene's output.n_frames
    assert (ds.final_error.values > 0).all() and (ds.force_evaluations.values > 0).all()
    assert (ds.quantity_error.values > 0).all()  # the chart's error: the reported amplitudes and speeds
    assert "faster" in res.output and (out / "workprecision.png").exists()
