"""``flexmm fit``: specs, exact Jacobians, the recovery of known parameters, --check-gradient."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import LEGO_CHAIN
from typer.testing import CliRunner

from flexmm.cli import app
from flexmm.config import ConfigError
from flexmm.config.loader import read_yaml
from flexmm.design.fit import load_fit, solve, synthetic_table, write_table
from flexmm.design.variables import finite_difference

DESIGNS = Path(__file__).resolve().parents[2] / "designs"
SCENE = {"name": "small", "lattice": {
    **LEGO_CHAIN, "n_units": 8, "theta0_rad": 0.0, "left": "driven", "right": "free"},
    "excitation": {"kind": "impact", "end": "left", "velocity_m_s": 3.0, "angular_velocity_rad_s": 300.0},
    "damping": {"viscous": {"damping_ratio": 0.01}}, "solver": {"duration_s": 0.01}}
TRUE = {"k_rot": LEGO_CHAIN["k_rot_n_m_per_rad"], "zeta": 0.01}


def _spec(tmp_path: Path, noise: float = 0.0, **changes) -> Path:
    (tmp_path / "scene.yaml").write_text(yaml.safe_dump(SCENE))
    table = synthetic_table(copy.deepcopy(SCENE), "theta", [2, 4, 6], 2.5e-4, 41, noise=noise, seed=3)
    write_table(table, tmp_path / "trace.csv", "mrad")
    spec = {"name": "small_fit", "scene": "scene.yaml",
            "data": {"file": "trace.csv", "field": "theta", "unit": "mrad", "sigma": max(noise, 1e-6) * 1e3},
            "parameters": [{"name": "k_rot", "target": "k_rot_n_m_per_rad", "initial": 8.5e-4, "bounds": [1e-4, 5e-3]},
                           {"name": "zeta", "path": "damping.viscous.damping_ratio", "initial": 0.02,
                            "bounds": [0.0, 0.2]}]}
    spec.update(changes)
    path = tmp_path / "fit.yaml"
    path.write_text(yaml.safe_dump(spec, sort_keys=False))
    return path


def test_jacobian_is_the_derivative_of_the_residuals(tmp_path):
    fit = load_fit(_spec(tmp_path))
    x0 = fit.design.x0
    J = fit.jacobian(x0)
    r0 = fit.residuals(x0)
    for k in range(x0.size):
        column = np.array([finite_difference(lambda x: fit.residuals(x)[i], x0, k) for i in range(0, r0.size, 7)])
        np.testing.assert_allclose(J[::7, k], column, rtol=1e-6, atol=1e-7 * np.abs(column).max())


def test_noise_free_fit_recovers_the_parameters(tmp_path):
    fit = load_fit(_spec(tmp_path))
    result = solve(fit)
    np.testing.assert_allclose(result.x, [TRUE["k_rot"], TRUE["zeta"]], rtol=1e-6)
    assert result.cost < 1e-8 * result.cost0


def test_check_gradient_prints_the_worst_error_last(tmp_path):
    res = CliRunner().invoke(app, ["fit", str(_spec(tmp_path)), "--check-gradient"])
    assert res.exit_code == 0, res.output
    last = res.output.strip().splitlines()[-1]
    assert last.startswith("worst relative error:")
    assert float(last.split(":")[1]) < 1e-6


def test_spec_errors_name_file_and_line(tmp_path):
    path = _spec(tmp_path)
    text = path.read_text().replace("bounds:", "bound:", 1)
    path.write_text(text)
    with pytest.raises(ConfigError) as err:
        load_fit(path)
    line = next(i for i, t in enumerate(text.splitlines(), 1) if "bound:" in t)
    assert f"{path}:{line}" in str(err.value)
    res = CliRunner().invoke(app, ["fit", str(path)])
    assert res.exit_code == 2 and "bound" in res.output


@pytest.mark.slow
def test_lego_showcase_recovers_the_parameters_within_one_percent(tmp_path):
    """designs/lego_fit.yaml: k_θ, k_s and ζ from a trace with 0.005 rad noise, starting 20-30 % off."""
    data, _ = read_yaml(DESIGNS / "lego_chain_scene.yaml")
    truth = np.array([data["lattice"]["k_rot_n_m_per_rad"], data["lattice"]["k_shear_n_per_m"],
                      data["damping"]["viscous"]["damping_ratio"]])
    res = CliRunner().invoke(app, ["fit", str(DESIGNS / "lego_fit.yaml"), "--out", str(tmp_path)])
    assert res.exit_code == 0, res.output
    import xarray as xr

    with xr.open_dataset(tmp_path / "fit.nc") as ds:
        value, stderr, chi2 = ds["value"].values, ds["stderr"].values, ds.attrs["reduced_chi2"]
    assert np.all(np.abs(value / truth - 1) < 0.01), value / truth - 1
    assert np.all(np.abs(value - truth) < 4 * stderr)  # the covariance is an honest uncertainty
    assert 0.8 < chi2 < 1.2  # σ of the spec is the noise of the trace
    assert (tmp_path / "fitted_scene.yaml").exists() and (tmp_path / "fit.png").exists()


def test_netcdf_table_reads_like_the_csv(tmp_path):
    """A (time, site) netCDF variable (the layout of a flexmm dataset), in degrees, with a site subset."""
    import xarray as xr

    csv_fit = load_fit(_spec(tmp_path))
    m = csv_fit.measured
    ds = xr.Dataset({"theta": (("time", "site"), np.degrees(m.values), {"units": "deg"}),
                     "u": (("time", "site"), np.zeros_like(m.values), {"units": "m"})},
                    coords={"time": m.times, "site": m.sites})
    ds.to_netcdf(tmp_path / "trace.nc", engine="h5netcdf")
    spec = yaml.safe_load((tmp_path / "fit.yaml").read_text())
    spec["data"] = {"file": "trace.nc", "field": "theta", "unit": "deg", "sites": [2, 6],
                    "sigma": float(np.degrees(1e-6))}
    (tmp_path / "fit_nc.yaml").write_text(yaml.safe_dump(spec))
    nc_fit = load_fit(tmp_path / "fit_nc.yaml")
    keep = [0, 2]  # sites 2 and 6 of (2, 4, 6)
    np.testing.assert_allclose(nc_fit.measured.values, m.values[:, keep], rtol=1e-12)
    r_csv = csv_fit.residuals(csv_fit.design.x0).reshape(m.values.shape)[:, keep]
    np.testing.assert_allclose(nc_fit.residuals(nc_fit.design.x0).reshape(-1, 2), r_csv, rtol=1e-9)
