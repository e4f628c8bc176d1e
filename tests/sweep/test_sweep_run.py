"""Running sweeps: idempotent reruns, a real Dask LocalCluster, failed points, the sweep dataset."""

from __future__ import annotations

import json
import textwrap
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from flexmm.io.run_dataset import open_run
from flexmm.sweep import load_sweep, plot_sweep, run_sweep
from flexmm.sweep.store import SweepStore, dataset_status

REPO = Path(__file__).resolve().parents[2]
LEGO = REPO / "configs" / "lego_vector_soliton.yaml"

# A tiny, shortened LEGO chain: 60 units, launched solitons, 480 steps per point.
TINY = f"""\
    name: tiny_lego
    base: {LEGO}
    set:
      lattice.n_units: 60
      lattice.left: free
      damping.absorbing: null
      excitation: {{kind: soliton, amplitude_rad: 0.4, center_site: 8}}
      solver.duration_s: 0.06
      solver.dt_fraction: 0.5
      output.n_frames: 61
    keep: all
    vary:
      grid:
        excitation.amplitude_rad: [0.3, 0.45, 0.6]
    """


def tiny_spec(tmp_path: Path, text: str = TINY):
    p = tmp_path / "tiny.yaml"
    p.write_text(textwrap.dedent(text))
    return load_sweep(p)


def snapshot(sweep_dir: Path) -> dict[str, float]:
    """mtime of every file under points/ and store/ (what a recomputation would touch)."""
    return {str(p.relative_to(sweep_dir)): p.stat().st_mtime_ns
            for sub in ("points", "store") for p in (sweep_dir / sub).rglob("*") if p.is_file()}


@pytest.fixture(scope="module")
def local_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("local")
    spec = tiny_spec(tmp)
    outcomes = []
    report = run_sweep(spec, tmp / "sweep", workers=1, on_outcome=outcomes.append)
    report.outcomes = outcomes
    return spec, tmp / "sweep", report


def test_analysis_options_reach_the_measurement(local_run):
    """A spec's ``analysis:`` (an AnalysisOptions, carried to workers as a dict) decides what is measured."""
    from flexmm.config.analysis import AnalysisOptions
    from flexmm.sweep.observe import observe_run

    spec, d, _ = local_run
    point = SweepStore(d).point_dir(spec.points()[1].hash)
    auto = observe_run(point)
    assert auto["kind"] == "pulse" and auto["field"] == "theta" and auto["amplitude_units"] == "rad"
    u = observe_run(point, {"field": "u_dot"})
    assert u["kind"] == "pulse" and u["field"] == "u_dot" and u["amplitude_units"] == "m/s"
    front = observe_run(point, AnalysisOptions(kind="front"))  # fronts are measured on the displacement
    assert front["kind"] == "front" and front["field"] == "u" and front["amplitude_units"] == "m"


def test_local_sweep_runs_every_point_and_combines(local_run):
    spec, d, report = local_run
    assert report.ok and report.n_run == 3 and report.n_cached == 0
    ds = xr.load_dataset(d / "sweep.nc", engine="h5netcdf")
    assert ds["speed"].dims == ("amplitude_rad",)
    assert list(ds["amplitude_rad"].values) == [0.3, 0.45, 0.6]
    assert ds["amplitude_rad"].attrs["parameter"] == "excitation.amplitude_rad"
    assert ds["amplitude_rad"].attrs["units"] == "rad"
    assert (ds["status"].values == "finished").all()
    assert np.isfinite(ds["speed"]).all() and np.isfinite(ds["width"]).all()
    # larger solitons are slower; this 60-unit, 480-step chain only roughly follows the speed law
    assert np.all(np.diff(ds["speed"].values) < 0)
    np.testing.assert_allclose(ds["speed"], ds["speed_theory"], rtol=0.25)
    np.testing.assert_allclose(ds["amplitude"], ds["amplitude_rad"], rtol=0.05)
    store = SweepStore(d)
    assert sorted(o["index"] for o in report.outcomes) == [0, 1, 2]
    assert all(o["numba_threads"] == 1 and o["kept"] for o in report.outcomes)
    for p in spec.points():  # keep: all -> every point's run directory, sharded by hash prefix
        pd = store.point_dir(p.hash)
        assert pd.name == p.hash and pd.parent.name == p.hash[:2]
        assert ds["run"].values[p.index] == f"points/{p.hash[:2]}/{p.hash}"
        assert dataset_status(pd / "dataset.nc") == "finished"
        # the point's config as declared (the run's own config is the planned one: its dt chosen)
        assert open_run(pd).attrs["plan_source_config_sha256"] == p.hash


def test_second_run_does_no_work(local_run):
    spec, d, _ = local_run
    before = snapshot(d)
    report = run_sweep(spec, d, workers=1)
    assert report.ok and report.n_run == 0 and report.n_cached == 3
    assert snapshot(d) == before


def test_same_sweep_on_a_dask_local_cluster_gives_the_same_results(local_run, tmp_path):
    distributed = pytest.importorskip("distributed")
    spec, d_local, _ = local_run
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                                  dashboard_address=None) as cluster:
        report = run_sweep(spec, tmp_path / "dask", scheduler=cluster.scheduler_address)
    assert report.ok and report.n_run == 3 and report.backend.startswith("dask")
    a = xr.load_dataset(d_local / "sweep.nc", engine="h5netcdf")
    b = xr.load_dataset(tmp_path / "dask" / "sweep.nc", engine="h5netcdf")
    for p in spec.points():  # the integration is bit-for-bit the same
        ra, rb = open_run(SweepStore(d_local).point_dir(p.hash)), open_run(SweepStore(tmp_path / "dask").point_dir(p.hash))
        np.testing.assert_array_equal(ra["theta"].values, rb["theta"].values)
    when = {"history": ""}  # the only attribute that differs: when each file was written
    xr.testing.assert_identical(a[["status", "run"]].assign_attrs(when), b[["status", "run"]].assign_attrs(when))
    # fitted observables: equal to the last bits (once, in a full-suite run on a fresh clone, they
    # differed there — pool workers run with one BLAS thread, the in-process cluster with several)
    xr.testing.assert_allclose(a[["speed", "speed_stderr", "amplitude", "width"]],
                               b[["speed", "speed_stderr", "amplitude", "width"]], rtol=1e-12, atol=0)



def test_failed_points_are_recorded_and_retried_only_on_request(tmp_path, in_process_scheduler):
    spec = tiny_spec(tmp_path, TINY.replace("excitation.amplitude_rad: [0.3, 0.45, 0.6]",
                                            "solver.dt_s: [1e-4, 1e-3]"))
    d = tmp_path / "sweep"
    opts = {"scheduler": in_process_scheduler}
    report = run_sweep(spec, d, **opts)
    assert not report.ok and report.n_finished == 1 and report.n_failed == 1
    bad = [p for p in spec.points() if p.params["solver.dt_s"] == 1e-3][0]
    ds = xr.load_dataset(d / "sweep.nc", engine="h5netcdf")
    assert list(ds["status"].values) == ["finished", "failed"]
    assert "UnstableStepError" in str(ds["note"].values[1]) and "stable limit" in str(ds["note"].values[1])
    before = snapshot(d)
    again = run_sweep(spec, d, **opts)
    assert again.n_run == 0 and again.n_skipped_failed == 1 and snapshot(d) == before
    retried = run_sweep(spec, d, retry_failed=True, **opts)
    assert retried.n_run == 1 and retried.n_failed == 1
    after = snapshot(d)
    good = [k for k in before if k.startswith("points/") and bad.hash not in k]
    assert good and all(after[k] == before[k] for k in good)


def test_reanalyse_measures_again_without_rerunning(local_run):
    from flexmm.sweep.execute import prepare, reanalyse

    spec, d, _ = local_run
    datasets = {k: v for k, v in snapshot(d).items() if k.endswith("dataset.nc")}
    before = np.array(SweepStore(d).read()["observables"])
    assert reanalyse(prepare(spec, d)) == 3
    assert {k: v for k, v in snapshot(d).items() if k.endswith("dataset.nc")} == datasets
    np.testing.assert_array_equal(np.array(SweepStore(d).read()["observables"]), before)


def test_plot_sweep_writes_a_png(local_run, tmp_path):
    _, d, _ = local_run
    out = plot_sweep(d, tmp_path / "fig" / "tiny.png")
    assert out.is_file() and out.read_bytes()[:4] == b"\x89PNG"


def test_analyze_cli_tabulates_and_plots_a_sweep_dir(local_run, tmp_path):
    from typer.testing import CliRunner

    from flexmm.cli import app

    _, d, _ = local_run
    res = CliRunner().invoke(app, ["analyze", str(d), "--plot-dir", str(tmp_path)])
    assert res.exit_code == 0, res.output
    assert "amplitude_rad" in res.output and "finished" in res.output
    assert (tmp_path / "sweep.png").read_bytes()[:4] == b"\x89PNG"


def test_zip_sweep_has_a_point_dimension(tmp_path, in_process_scheduler):
    text = TINY.replace("grid:\n        excitation.amplitude_rad: [0.3, 0.45, 0.6]",
                        "zip:\n        excitation.amplitude_rad: [0.3, 0.6]\n"
                        "        excitation.center_site: [8, 10]")
    spec = tiny_spec(tmp_path, text)
    report = run_sweep(spec, tmp_path / "zip", scheduler=in_process_scheduler)
    assert report.ok
    ds = xr.load_dataset(tmp_path / "zip" / "sweep.nc", engine="h5netcdf")
    assert ds["speed"].dims == ("point",)
    assert list(ds["center_site"].values) == [8, 10] and list(ds["amplitude_rad"].values) == [0.3, 0.6]
