"""The streaming dataset writer: declared frame count (fixed time dimension), early stops, units.

Oracle: what was appended is what is read back (values, order, units), whatever the number of
frames written against the number declared; no temporary file is left beside the result.
"""

from __future__ import annotations

import h5netcdf
import numpy as np
import pytest

from flexmm.io.run_dataset import DatasetWriter, open_run


@pytest.mark.parametrize("declared, written", [(6, 6), (6, 4), (6, 0), (None, 5)])
def test_frames_read_back_as_written(tmp_path, declared, written) -> None:
    path = tmp_path / "dataset.nc"
    w = DatasetWriter(path, 3, {"u": ("m", "displacement")}, {"energy": ("J", "total energy")},
                      {"x": (np.array([0.0, 0.5, 1.0]), "m", "rest x position")}, n_frames=declared)
    rng = np.random.default_rng(written)
    frames = [(0.1 * k, rng.standard_normal(3), float(rng.standard_normal())) for k in range(written)]
    for t, u, e in frames:
        w.append(t, {"u": u}, {"energy": e})
    w.close({"status": "finished" if written == declared else "failed"})
    ds = open_run(tmp_path)
    assert ds.sizes["time"] == written and ds.sizes["site"] == 3
    if written:
        np.testing.assert_array_equal(ds["time"].values, [f[0] for f in frames])
        np.testing.assert_array_equal(ds["u"].values, np.stack([f[1] for f in frames]))
        np.testing.assert_array_equal(ds["energy"].values, [f[2] for f in frames])
    assert ds["u"].attrs["units"] == "m" and ds["energy"].attrs["units"] == "J" and ds["x"].attrs["units"] == "m"
    assert ds.attrs["status"] in ("finished", "failed")
    with h5netcdf.File(path, "r") as f:  # a declared count gives a fixed (fast to open) time dimension
        assert f.dimensions["time"].isunlimited() == (declared is None or written == 0)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dataset.nc"]


def test_more_frames_than_declared_is_an_error(tmp_path) -> None:
    w = DatasetWriter(tmp_path / "d.nc", 1, {"u": ("m", "u")}, {}, {}, n_frames=1)
    w.append(0.0, {"u": [1.0]}, {})
    with pytest.raises(ValueError, match="more frames"):
        w.append(1.0, {"u": [2.0]}, {})
        w.flush()
    w.abort()


def test_quick_reader_gives_the_dataset_open_run_gives(tmp_path) -> None:
    """``load_run_quickly`` (h5py alone, what a sweep's points are measured from) reads a real run
    as the same Dataset as ``open_run`` (h5netcdf through xarray): values, dims, coords, attrs."""
    import xarray as xr

    from flexmm.api import run_scene
    from flexmm.config import load_scene
    from flexmm.io.run_dataset import load_run_quickly
    from pathlib import Path

    demo = Path(__file__).resolve().parents[2] / "configs" / "lego_vector_soliton.yaml"
    # as many frames as sites: the dimensions are told apart by name, not by length
    scene = load_scene(demo, ["lattice.n_units=20", "damping.absorbing=null", "solver.duration_s=0.002", "output.n_frames=20"])
    path = run_scene(scene, run_dir=tmp_path / "r").path
    a, b = open_run(path), load_run_quickly(path)
    xr.testing.assert_identical(a, b)
    assert list(a.coords) == list(b.coords) and a["u"].dims == b["u"].dims == ("time", "site")
    assert all(type(a.attrs[k]) is type(b.attrs[k]) for k in a.attrs)


def test_a_run_kept_in_memory_is_the_dataset_its_file_would_hold(tmp_path) -> None:
    """``run_scene(in_memory=True)`` (a sweep point that is measured and dropped) writes no
    dataset.nc, and its ``result.dataset`` is what reading the written file gives: values,
    dimensions, coordinates, attributes and their types (all but the wall-clock ones)."""
    import xarray as xr

    from flexmm.api import run_scene
    from flexmm.config import load_scene
    from flexmm.io.run_dataset import load_run_quickly
    from pathlib import Path

    demo = Path(__file__).resolve().parents[2] / "configs" / "lego_vector_soliton.yaml"
    scene = load_scene(demo, ["lattice.n_units=20", "damping.absorbing=null", "solver.duration_s=0.002", "output.n_frames=20"])
    on_disk = load_run_quickly(run_scene(scene, run_dir=tmp_path / "file").path)
    result = run_scene(scene, run_dir=tmp_path / "mem", in_memory=True, atomic=False)
    assert result.path is None and not (tmp_path / "mem" / "dataset.nc").exists()
    mem = result.dataset
    clock = [k for k in on_disk.attrs if k.endswith(("wall_s", "_time_s", "check_s")) or k in ("history", "log", "plan")]
    assert "wall_time_s" in clock and "history" in clock
    a, b = on_disk.copy(), mem.copy()
    for ds in (a, b):
        for k in clock:
            ds.attrs.pop(k)
    xr.testing.assert_identical(a, b)
    assert set(on_disk.attrs) == set(mem.attrs)
    assert all(type(a.attrs[k]) is type(b.attrs[k]) for k in a.attrs)
    assert all(a[k].dtype == b[k].dtype and type(a[k].attrs.get("units")) is type(b[k].attrs.get("units"))
               for k in a.variables)


def test_attributes_as_stored_are_what_hdf5_gives_back_with_and_without_the_cache(monkeypatch) -> None:
    """``_as_stored`` converts each distinct scalar once; what it returns is what an HDF5 file
    gives back (type and value), also when its cache fills up and is emptied mid-run."""
    import io

    import h5py

    from flexmm.io import run_dataset

    def through_hdf5(attrs: dict) -> dict:
        with h5py.File(io.BytesIO(), "w") as f:
            for k, v in attrs.items():
                f.attrs[k] = v
            return {k: run_dataset._attr_value(f.attrs[k]) for k in attrs}

    monkeypatch.setattr(run_dataset, "_STORED", {})
    monkeypatch.setattr(run_dataset, "_STORED_MAX", 5)  # emptied every few calls
    for i in range(12):
        attrs = {"Conventions": "CF-1.10", "units": "m", "n": i, "x": 0.5 * i, "ok": i % 2 == 0,
                 "f32": np.float32(i), "vec": [1.0, float(i)], "s": f"point {i}"}
        got = run_dataset._as_stored({"": attrs, "u": {"units": "m", "long_name": "displacement"}})
        want = {"": through_hdf5(attrs), "u": through_hdf5({"units": "m", "long_name": "displacement"})}
        for group in want:
            assert list(got[group]) == list(want[group])
            for k in want[group]:
                assert type(got[group][k]) is type(want[group][k]), (k, got[group][k], want[group][k])
                np.testing.assert_array_equal(got[group][k], want[group][k])
