"""No silent change of what was asked (issue 36): frames land on the requested times or the request
is refused with the nearest valid values; every change the plan makes to the lattice, the step or
the output is a ``plan: change:`` line on stdout and a line of the dataset's ``plan_changes``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

from flexmm.cli import app
from flexmm.errors import PlanError
from flexmm.frames import frame_times, interval

LEGO = str(Path(__file__).resolve().parents[2] / "configs" / "lego_vector_soliton.yaml")
SHORT = ["--set", "lattice.n_units=60", "--set", "damping.absorbing=null", "--set", "solver.duration_s=0.05", "--set", "output.n_frames=51"]


def run(tmp_path, *sets: str):
    out = tmp_path / "run"
    res = CliRunner().invoke(app, ["run", LEGO, "--out", str(out), *SHORT, *sets])
    return res, out / "dataset.nc"


def changes_of(stdout: str) -> list[str]:
    return [ln for ln in stdout.splitlines() if ln.startswith("plan: change: ")]


# -- frame times: the rules ------------------------------------------------------------------

def test_every_longer_than_the_duration_is_refused_with_the_nearest_values():
    with pytest.raises(PlanError, match=r"output.every_s = 10 s is longer than solver.duration_s = 0.05 s.*"
                                        r"nearest valid: output.every_s = 0.05 s \(2 frames\) or solver.duration_s = 10 s"):
        interval(0.05, 201, 10.0)


def test_every_that_does_not_divide_the_duration_is_refused_with_the_nearest_values():
    with pytest.raises(PlanError, match=r"solver.duration_s = 0.09 or 0.12 s, or output.every_s = 0.0333333 or "
                                        r"0.025 s \(output.n_frames = 4 or 5\)"):
        interval(0.1, 201, 0.03)
    assert interval(0.1, 201, 0.025) == pytest.approx((0.025, 5))
    assert interval(0.2, 201, None) == pytest.approx((0.001, 201))


def test_a_given_step_that_does_not_divide_the_interval_is_refused():
    with pytest.raises(PlanError, match=r"solver.dt_s = 3e-05 s does not divide the frame interval 0.001 s.*"
                                        r"solver.dt_s = 2.94118e-05 s \(34 steps per frame\) or 3.0303e-05 s"):
        frame_times(0.2, 201, None, 3e-5, given=True, exact=False)
    f, changes = frame_times(0.2, 201, None, 2.5e-5, given=True, exact=False)  # divides: kept, no change
    assert (f.dt_s, f.steps_per_frame, f.n_frames, changes) == (2.5e-5, 40, 201, [])


@pytest.mark.parametrize("given, exact", [(True, True), (False, False)])
def test_a_step_is_shortened_to_land_on_the_frames_and_the_change_is_said(given, exact):
    f, changes = frame_times(0.2, 201, None, 3e-5, given=given, exact=exact)
    assert f.steps_per_frame == 34 and f.dt_s == pytest.approx(0.001 / 34, rel=1e-12) and f.n_frames == 201
    assert len(changes) == 1 and "shortened to 2.94118e-05 s so frames land on the requested times" in changes[0]
    f, changes = frame_times(0.2, 201, None, 1.306e-3, given=given, exact=exact)  # a step above the interval
    assert (f.steps_per_frame, f.dt_s, f.n_frames) == (1, pytest.approx(0.001), 201) and changes


# -- end to end: refused, or announced on stdout and recorded ---------------------------------

def test_run_refuses_an_every_s_beyond_the_duration(tmp_path):
    res, path = run(tmp_path, "--set", "output.every_s=10")
    assert res.exit_code == 2, res.output
    assert "nearest valid: output.every_s = 0.05 s (2 frames) or solver.duration_s = 10 s" in res.output
    assert not path.exists()


def test_run_refuses_a_step_off_the_frames(tmp_path):
    res, path = run(tmp_path, "--set", "solver.dt_s=3e-5")
    assert res.exit_code == 2, res.output
    assert "solver.dt_s = 3e-05 s does not divide the frame interval 0.001 s" in res.output
    assert "output.exact_frame_times: true" in res.output


def test_exact_frame_times_shorten_a_given_step_announced_and_recorded(tmp_path):
    res, path = run(tmp_path, "--set", "solver.dt_s=3e-5", "--set", "output.exact_frame_times=true")
    assert res.exit_code == 0, res.output
    said = changes_of(res.stdout)
    assert any("solver.dt_s 3e-05 s shortened to 2.94118e-05 s" in ln for ln in said), res.stdout
    with xr.open_dataset(path) as ds:
        assert "solver.dt_s 3e-05 s shortened to 2.94118e-05 s" in ds.attrs["plan_changes"]
        assert ds.attrs["dt_s"] == pytest.approx(0.001 / 34, rel=1e-9)
        np.testing.assert_allclose(ds["time"].values, np.linspace(0, 0.05, 51), rtol=0, atol=1e-12)


def test_a_derived_step_lands_on_the_requested_frames(tmp_path):
    """accuracy: null takes dt_fraction of the stable limit: it used to round the frame interval
    to whole steps (frames off the requested times, the duration rounded up)."""
    res, path = run(tmp_path, "--set", "solver.accuracy=null", "--set", "output.n_frames=37")
    assert res.exit_code == 0, res.output
    with xr.open_dataset(path) as ds:
        np.testing.assert_allclose(ds["time"].values, np.linspace(0, 0.05, 37), rtol=0, atol=1e-12)
        recorded = ds.attrs["plan_changes"]
    said = changes_of(res.stdout)
    assert said and all(ln.removeprefix("plan: change: ") in recorded for ln in said)
    assert "so frames land on the requested times" in recorded


def test_pilot_step_longer_than_the_frame_interval_is_shortened_to_it(tmp_path):
    """The pilots' step (0.143 ms) above a 0.1 ms frame interval: frames used to be a step apart."""
    res, path = run(tmp_path, "--set", "output.n_frames=501")
    assert res.exit_code == 0, res.output
    assert any("shortened to 0.0001 s" in ln for ln in changes_of(res.stdout)), res.stdout
    with xr.open_dataset(path) as ds:
        assert ds.sizes["time"] == 501
        assert ds.attrs["dt_s"] == pytest.approx(1e-4, rel=1e-9)


def test_a_trimmed_lattice_is_announced_and_recorded(tmp_path):
    """The planner trims a lattice its waves never reach: a change of lattice size, said and stored."""
    res, path = run(tmp_path, "--set", "lattice.n_units=2000", "--set", "solver.duration_s=0.02",
                    "--set", "output.n_frames=21")
    assert res.exit_code == 0, res.output
    said = [ln for ln in changes_of(res.stdout) if ln.startswith("plan: change: domain: ")]
    assert len(said) == 1 and "trimmed to units" in said[0], res.stdout
    with xr.open_dataset(path) as ds:
        assert said[0].removeprefix("plan: change: ") in ds.attrs["plan_changes"].splitlines()
        assert ds.sizes["site"] < 2000


def test_a_run_as_asked_records_no_change(tmp_path):
    res, path = run(tmp_path)
    assert res.exit_code == 0, res.output
    assert changes_of(res.stdout) == []
    with xr.open_dataset(path) as ds:
        assert ds.attrs["plan_changes"] == ""
        assert ds.attrs["plan_summary"].splitlines() == [ln for ln in res.stdout.splitlines()
                                                         if ln.startswith("plan: ")]
