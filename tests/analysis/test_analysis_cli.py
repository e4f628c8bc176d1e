"""``flexmm analyze`` end to end on synthetic run directories (no simulation needed)."""

from __future__ import annotations

import csv
import io
import json
import math

import numpy as np
import pytest
import xarray as xr
import yaml
from typer.testing import CliRunner

from synthetic import SynthPulse, pulse_dataset
from flexmm.cli import app
from flexmm.config import scene_from_dict
from flexmm.io.provenance import config_text
from flexmm.models.rotating_chain import nondimensional
from flexmm.theory import rotating as rt

runner = CliRunner()


def _lego_soliton_run(path, lego_config, A: float, n_sites: int = 160, n_frames: int = 401):
    """A run directory whose θ field is the exact soliton of amplitude A moving at c(A)."""
    cfg = dict(lego_config, name=f"exact_{A:g}")
    cfg["lattice"] = dict(cfg["lattice"], n_units=n_sites, left="free")
    cfg["excitation"] = {"kind": "soliton", "amplitude_rad": A, "center_site": 20}
    scene = scene_from_dict(cfg)
    lat = scene.lattice
    nd = nondimensional(lat)
    p = rt.RotatingChainND(0.0, nd["Ks"], nd["Ktheta"], nd["alpha2"], lat.n_lateral, 0)
    T = math.sqrt(lat.mass_kg / lat.k_long_n_per_m)
    c = float(rt.soliton_speed(p, A))
    t = np.linspace(0.0, 110.0 / c * T, n_frames)
    x = np.arange(n_sites) * lat.a_m
    zeta = (x[None, :] - 20 * lat.a_m - c * lat.a_m / T * t[:, None]) / lat.a_m
    theta = rt.exact_soliton(p, A, zeta.ravel())[0].reshape(zeta.shape)
    ds = xr.Dataset({"theta": (("time", "site"), theta, {"units": "rad"})},
                    coords={"time": ("time", t, {"units": "s"}), "x": ("site", x, {"units": "m"})},
                    attrs={"model": lat.kind, "config": config_text(scene), "spacing_m": lat.a_m,
                           "title": scene.name})
    path.mkdir(parents=True)
    ds.to_netcdf(path / "dataset.nc", engine="h5netcdf")
    return path, c * lat.a_m / T, rt.soliton_width(p, c) * lat.a_m


def test_analyze_exact_soliton_matches_theory(tmp_path, lego_config):
    run, v, W = _lego_soliton_run(tmp_path / "runs" / "a", lego_config, 0.35)
    out = tmp_path / "out.json"
    res = runner.invoke(app, ["analyze", str(run), "--json", str(out), "--csv", str(tmp_path / "t.csv"), "--plot"])
    assert res.exit_code == 0, res.output
    assert "exact law" in res.output and "speed" in res.output
    summary = json.loads(out.read_text())
    rows = {r["quantity"]: r for r in summary["runs"][0]["comparisons"]}
    assert abs(rows["speed"]["rel_diff"]) < 1e-3
    assert rows["speed"]["predicted"] == pytest.approx(v, rel=1e-3)
    assert abs(rows["FWHM"]["rel_diff"]) < 0.01
    assert abs(rows["width W (sech fit)"]["measured"] - W) < 0.3 * 0.016  # well inside one site
    table = list(csv.DictReader(io.StringIO((tmp_path / "t.csv").read_text())))
    assert {"run", "quantity", "measured", "predicted", "rel_diff"} <= set(table[0])
    ana = xr.load_dataset(run / "analysis.nc", engine="h5netcdf")
    assert ana.attrs["model"] == "rotating_squares_chain" and ana.sizes["pulse"] == 1
    assert float(ana["pulse_speed_m_s"][0]) == pytest.approx(v, rel=1e-3)
    assert np.isfinite(ana["arrival_time"].values).sum() > 50
    for png in ("space_time_theta.png", "profile_theta_0.png"):
        assert (run / png).stat().st_size > 1000


def test_analyze_several_runs_plots_speed_against_amplitude(tmp_path, lego_config):
    runs = [_lego_soliton_run(tmp_path / "runs" / f"r{A}", lego_config, A, n_frames=201)[0] for A in (0.3, 0.5)]
    res = runner.invoke(app, ["analyze", *map(str, runs), "--plot", "--no-save"])
    assert res.exit_code == 0, res.output
    assert "pulse runs" in res.output
    assert (tmp_path / "runs" / "speed_amplitude.png").is_file()
    assert not (runs[0] / "analysis.nc").exists()


def test_generic_model_without_theory(tmp_path):
    ds = pulse_dataset([SynthPulse(-0.01, 2.0, 3.0, 20.0, "sech2")], field="strain_like", units="1")
    (tmp_path / "run").mkdir()
    ds.to_netcdf(tmp_path / "run" / "dataset.nc", engine="h5netcdf")
    res = runner.invoke(app, ["analyze", str(tmp_path / "run"), "-f", "strain_like", "--json", "-"])
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout[res.stdout.index("{"):])
    p = data["runs"][0]["pulses"][0]
    assert p["speed_m_s"] == pytest.approx(2.0, rel=2e-3) and p["polarity"] == -1
    assert all(r["predicted"] is None for r in data["runs"][0]["comparisons"])


@pytest.mark.parametrize("args, message", [
    (["does/not/exist"], "no such run directory"),
    (["{empty}"], "no dataset.nc"),
    (["{run}", "-f", "nonsense"], "no field 'nonsense'"),
    (["{run}", "--analysis", "bogus"], ("--analysis bogus: kind: got 'bogus' (str); expected: input should be "
                                       "'auto', 'pulse', 'front', 'driven' or 'modes'")),
    (["{run}", "--threshold", "2"], ("--threshold 2.0: threshold_fraction: got 2.0 (float); expected: input "
                                    "should be less than or equal to 1")),
    (["{run}", "--row", "-1"], "--row -1: row: got -1 (int); expected: input should be greater than or equal to 0"),
    (["{run}", "-f", "theta;u"], ("--field theta;u: field: got 'theta;u' (str); expected: a field name: theta, u, "
                                 "u_dot, strain[:NAME] or velocity[:NAME]")),
])
def test_user_errors_exit_2_without_traceback(tmp_path, args, message):
    (tmp_path / "empty").mkdir()
    (tmp_path / "run").mkdir()
    pulse_dataset([SynthPulse(0.2, 1.0, 3.0, 20.0)]).to_netcdf(tmp_path / "run" / "dataset.nc", engine="h5netcdf")
    args = [a.format(empty=tmp_path / "empty", run=tmp_path / "run") for a in args]
    res = runner.invoke(app, ["analyze", *args])
    assert res.exit_code == 2
    assert message in res.output and "Traceback" not in res.output


def test_no_pulse_exits_1(tmp_path):
    (tmp_path / "quiet").mkdir()
    pulse_dataset([], noise=1e-9).to_netcdf(tmp_path / "quiet" / "dataset.nc", engine="h5netcdf")
    res = runner.invoke(app, ["analyze", str(tmp_path / "quiet"), "--json", str(tmp_path / "o.json")])
    assert res.exit_code == 1
    assert "no pulse" in res.output and "Traceback" not in res.output
    assert json.loads((tmp_path / "o.json").read_text())["errors"][0]["run"].endswith("quiet")


def test_driven_run_table_and_analysis_file(tmp_path):
    from synthetic import driven_dataset

    (tmp_path / "d").mkdir()
    driven_dataset(harmonic=0.05).to_netcdf(tmp_path / "d" / "dataset.nc", engine="h5netcdf")
    res = runner.invoke(app, ["analyze", str(tmp_path / "d"), "--plot"])
    assert res.exit_code == 0, res.output
    assert "transmission" in res.output
    ana = xr.load_dataset(tmp_path / "d" / "analysis.nc", engine="h5netcdf")
    assert float(ana["driven_transmission"]) == pytest.approx(math.exp(-0.02 * 59), rel=1e-6)
    assert (tmp_path / "d" / "spectrum_u.png").is_file()
    assert yaml.safe_load(ana.attrs["analysis"]) == "driven"


def test_analyze_without_plot_does_not_import_matplotlib(tmp_path, lego_config):
    """Figures only when asked for: importing matplotlib costs more than the demo's analysis (issue 37)."""
    import subprocess
    import sys

    run, _, _ = _lego_soliton_run(tmp_path / "run", lego_config, -0.4)
    code = ("import sys; from typer.testing import CliRunner; from flexmm.cli import app; "
            f"r = CliRunner().invoke(app, ['analyze', {str(run)!r}, '--no-save']); assert r.exit_code == 0, r.output; "
            "print(sorted(m for m in sys.modules if m.split('.')[0] == 'matplotlib'))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().splitlines()[-1] == "[]"
