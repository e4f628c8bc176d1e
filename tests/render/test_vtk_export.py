"""``flexmm export RUN --format vtk``: read back with an independent reader (meshio for the .vtu
files, the standard library's XML parser for the .pvd collection) and compared with the dataset."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pytest
import xarray as xr
from conftest import LEGO_CHAIN
from render_helpers import build, export, random_fields, write_run


meshio = pytest.importorskip("meshio")

CHAIN = dict(LEGO_CHAIN, n_units=12, theta0_rad=0.1)
MASSES = {"kind": "mass_chain", "n_units": 10, "spacing_m": 0.01, "mass_kg": 0.01,
          "bond": {"law": "linear", "k_n_per_m": 100.0}}


def read_series(pvd):
    """[(time, meshio.Mesh)] of a ParaView collection."""
    root = ET.parse(pvd).getroot()
    assert root.get("type") == "Collection"
    return [(float(d.get("timestep")), meshio.read(pvd.parent / d.get("file")))
            for d in root.find("Collection").findall("DataSet")]


def test_rigid_chain_units_and_fields_per_frame(tmp_path):
    _, system = build(CHAIN)
    run = write_run(tmp_path / "chain", CHAIN, system, random_fields(system, 6)).parent
    result = export(run, "--format", "vtk", "-q")
    assert result.exit_code == 0, result.output
    pvd = run / "vtk" / "render_test.pvd"
    assert result.output.strip() == str(pvd)
    ds = xr.load_dataset(run / "dataset.nc", engine="h5netcdf")
    series = read_series(pvd)
    assert [t for t, _ in series] == ds["time"].values.tolist()
    for k, (_, mesh) in enumerate(series):
        u, theta = ds["u"].values[k], ds["theta"].values[k]
        assert np.array_equal(mesh.points[:, 0], ds["x"].values + u)
        assert np.array_equal(mesh.points[:, 1:], np.zeros((12, 2)))
        for name in ("u", "theta", "u_dot", "theta_dot"):
            assert np.array_equal(mesh.point_data[name], ds[name].values[k]), name
        assert np.array_equal(mesh.point_data["site"], np.arange(12))
        phi = mesh.point_data["orientation_rad"]  # neighbours counter-rotate: ±(θ0 + θ)
        assert np.allclose(np.abs(phi), np.abs(0.1 + theta), rtol=0, atol=1e-15)
        sign = np.sign(phi * (0.1 + theta))
        assert np.all(sign[1:] == -sign[:-1])
        assert mesh.cells[0].type == "vertex" and len(mesh.cells[0].data) == 12


def test_mass_chain_window_and_every(tmp_path):
    """Bodies at x + u; --start/--stop/--every choose the frames; --out names the directory."""
    _, system = build(MASSES)
    run = write_run(tmp_path / "masses", MASSES, system, random_fields(system, 9)).parent
    result = export(run, "--out", tmp_path / "series", "--start", "2ms", "--stop", "7ms", "--every", "2", "-q")
    assert result.exit_code == 0, result.output
    ds = xr.load_dataset(run / "dataset.nc", engine="h5netcdf")
    series = read_series(tmp_path / "series" / "render_test.pvd")
    assert [t for t, _ in series] == pytest.approx([2e-3, 4e-3, 6e-3], abs=1e-12)
    for (t, mesh), k in zip(series, (2, 4, 6)):
        assert t == ds["time"].values[k]
        assert np.array_equal(mesh.points[:, 0], ds["x"].values + ds["u"].values[k])
        assert np.array_equal(mesh.point_data["u_dot"], ds["u_dot"].values[k])
        assert "orientation_rad" not in mesh.point_data


def test_bad_format_and_missing_run_are_usage_errors(tmp_path):
    _, system = build(CHAIN)
    run = write_run(tmp_path / "chain", CHAIN, system, random_fields(system, 3)).parent
    result = export(run, "--format", "ovito")
    assert result.exit_code == 2 and "--format 'ovito': expected one of vtk" in result.output
    result = export(tmp_path / "nothing")
    assert result.exit_code == 2 and "no such run directory" in result.output
    result = export(run, "--every", "0")
    assert result.exit_code == 2 and "--every must be ≥ 1" in result.output
    assert not (run / "vtk" / "render_test.pvd").exists()
