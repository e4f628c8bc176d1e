"""The sweep's one observables store: lazy planning, invalid points recorded as failed, another
spec's store refused, its size per point, resume from the status array alone."""

from __future__ import annotations

import os
import textwrap
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from flexmm.errors import UsageError
from flexmm.sweep import load_sweep, run_sweep
from flexmm.sweep.execute import prepare
from flexmm.sweep.observe import OBSERVABLES
from flexmm.sweep.spec import SweepSpec
from flexmm.sweep.store import SweepStore

REPO = Path(__file__).resolve().parents[2]
LEGO = REPO / "configs" / "lego_vector_soliton.yaml"

BASE = f"""\
    name: store_test
    base: {LEGO}
    set:
      lattice.left: free
      damping.absorbing: null
      excitation: {{kind: soliton, amplitude_rad: 0.4, center_site: 8}}
      solver.duration_s: 0.02
      solver.dt_fraction: 0.5
      output.n_frames: 21
    """


def spec_file(tmp_path: Path, vary: str, name: str = "s.yaml"):
    p = tmp_path / name
    p.write_text(textwrap.dedent(BASE) + textwrap.dedent(vary))
    return load_sweep(p)



def test_a_point_whose_own_values_are_invalid_is_recorded_failed_not_a_crash(tmp_path, in_process_scheduler):
    # each value is valid with the other axis at its first value (the up-front check passes);
    # only the combination n_units=40, center_site=50 is not a scene
    spec = spec_file(tmp_path, """\
        vary:
          grid:
            lattice.n_units: [60, 40]
            excitation.center_site: [8, 50]
        """)
    report = run_sweep(spec, tmp_path / "sw", scheduler=in_process_scheduler)
    assert report.n_finished == 3 and report.n_failed == 1 and report.n_pending == 0
    ds = xr.load_dataset(tmp_path / "sw" / "sweep.nc", engine="h5netcdf")
    assert ds["status"].values.tolist() == [["finished", "finished"], ["finished", "failed"]]
    note = str(ds["note"].values[1, 1])
    assert note.startswith("invalid point:") and "outside 0..39" in note and "s.yaml:" in note
    assert np.isnan(ds["speed"].values[1, 1]) and np.isfinite(ds["amplitude"].values[0, 0])


def test_planning_validates_each_axis_value_once_not_every_point(tmp_path, monkeypatch):
    spec = spec_file(tmp_path, """\
        vary:
          grid:
            excitation.amplitude_rad: {start: 0.3, stop: 0.6, num: 1000}
            damping.viscous.damping_ratio: {start: 1e-4, stop: 1e-2, num: 1000, scale: log}
        """)
    calls = []
    real = SweepSpec.point_at
    monkeypatch.setattr(SweepSpec, "point_at", lambda self, i: calls.append(i) or real(self, i))
    plan = prepare(spec, tmp_path / "sw")
    assert spec.n_points == 10**6 and len(plan.tasks) == 10**6
    assert len(calls) == 2 * 256 - 1  # the first 256 values of each axis, the corner once
    assert not (tmp_path / "sw").exists()  # planning writes nothing


def test_a_bad_axis_value_is_still_an_up_front_error(tmp_path):
    from flexmm.config.loader import ConfigError

    spec = spec_file(tmp_path, """\
        vary:
          grid:
            lattice.n_units: [60, 40]
            excitation.amplitude_rad: [0.3, big]
        """)
    with pytest.raises(ConfigError) as exc:
        prepare(spec, tmp_path / "sw")
    [msg] = [str(i) for i in exc.value.issues]
    assert msg.startswith(f"{tmp_path / 's.yaml'}:13: excitation.amplitude_rad:") and "'big'" in msg


def test_a_store_of_another_spec_is_refused(tmp_path):
    one = spec_file(tmp_path, "vary: {grid: {excitation.amplitude_rad: [0.3, 0.4]}}\n")
    other = spec_file(tmp_path, "vary: {grid: {excitation.amplitude_rad: [0.3, 0.5]}}\n", "o.yaml")
    plan = prepare(one, tmp_path / "sw")
    plan.store.create_or_check(plan.fingerprint, one.n_points, list(OBSERVABLES), one.name)
    prepare(one, tmp_path / "sw")  # the same spec: fine
    with pytest.raises(UsageError, match="another sweep"):
        prepare(other, tmp_path / "sw")


def test_store_size_per_point_and_resume_reads_the_status_array(tmp_path):
    n = 20_000
    store = SweepStore(tmp_path)
    assert store.create_or_check("f" * 64, n, list(OBSERVABLES), "x")
    size = sum(os.path.getsize(p) for p in (tmp_path / "store").iterdir())
    assert size / n <= 2048
    store.write_point(7, "finished", np.arange(len(OBSERVABLES), dtype=float), "a note", ("pulse", "theta", "rad"))
    store.write_point(11, "failed", None, "invalid point: x")
    again = SweepStore(tmp_path)
    assert not again.create_or_check("f" * 64, n, list(OBSERVABLES), "x")  # opened, not laid out again
    status = again.status()
    assert status[7] == 1 and status[11] == 2 and np.count_nonzero(status) == 2
    arrays = again.read()
    np.testing.assert_array_equal(arrays["observables"][7], np.arange(len(OBSERVABLES)))
    assert np.isnan(arrays["observables"][11]).all() and arrays["note"][11] == b"invalid point: x"
    assert arrays["label"][7].tolist() == [b"pulse", b"theta", b"rad"]
