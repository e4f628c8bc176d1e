"""``keep: where <condition>``: the full runs of the points whose observables meet a condition."""

from __future__ import annotations

import math
import textwrap

import numpy as np
import pytest
import xarray as xr
from test_sweep_store import BASE

from flexmm.config.condition import Condition
from flexmm.config.loader import ConfigError
from flexmm.sweep import load_sweep, run_sweep
from flexmm.sweep.store import SweepStore



@pytest.mark.parametrize(("text", "values", "expected"), [
    ("speed > 1.5", {"speed": 2.0}, True),
    ("speed > 1.5", {"speed": 1.5}, False),
    ("speed > 1.5", {"speed": math.nan}, False),  # not measured: every comparison false
    ("0.2 <= amplitude < 0.4", {"amplitude": 0.3}, True),
    ("0.2 <= amplitude < 0.4", {"amplitude": 0.4}, False),
    ("abs(amplitude) > 0.3 and not width > 0.1", {"amplitude": -0.35, "width": 0.05}, True),
    ("abs(amplitude) > 0.3 and not width > 0.1", {"amplitude": -0.35, "width": 0.2}, False),
    ("speed > 3 or amplitude_max - amplitude_min > 0.01", {"speed": 1, "amplitude_max": 0.52,
                                                          "amplitude_min": 0.5}, True),
    ("speed / speed_theory > 1.05", {"speed": 2.2, "speed_theory": 2.0}, True),
    ("speed / speed_theory > 1.05", {"speed": 2.2, "speed_theory": 0.0}, False),  # x/0: NaN
    ("-amplitude >= 2 * 0.1", {"amplitude": -0.2}, True),
])
def test_conditions_evaluate_as_written(text, values, expected):
    c = Condition.parse(text)
    assert c(values) is expected
    assert c.names == set(values) - {"abs"}


@pytest.mark.parametrize(("text", "message"), [
    ("speed >", "cannot parse the condition"),
    ("__import__('os').system('true')", "the only function is abs"),
    ("speed.real > 1", "is not allowed in a condition"),
    ("speed > 'fast'", "only numbers are allowed"),
    ("[speed][0] > 1", "is not allowed in a condition"),
    ("max(speed, 1) > 1", "the only function is abs"),
])
def test_anything_else_is_refused(text, message):
    with pytest.raises(ValueError, match=message):
        Condition.parse(text)


SPEC = textwrap.dedent(BASE) + textwrap.dedent("""\
    vary:
      grid:
        excitation.amplitude_rad: [0.3, 0.35, 0.4, 0.45]
    """)


def test_spec_errors_name_the_keep_line(tmp_path):
    for keep, message in [("where speeed > 1", "unknown observable(s) speeed"),
                          ("where speed >", "cannot parse the condition"),
                          ("sometimes", "should match pattern")]:
        p = tmp_path / "k.yaml"
        p.write_text(textwrap.dedent(SPEC) + f"keep: {keep}\n")
        with pytest.raises(ConfigError) as exc:
            load_sweep(p)
        [issue] = exc.value.issues
        line = textwrap.dedent(SPEC).count("\n") + 1  # the keep: line, after the spec
        assert str(issue).startswith(f"{p}:{line}: keep:") and message in str(issue), str(issue)


def test_keep_where_keeps_exactly_the_points_meeting_the_condition(tmp_path, in_process_scheduler):
    p = tmp_path / "k.yaml"
    p.write_text(textwrap.dedent(SPEC) + "keep: where amplitude > 0.37\n")
    spec = load_sweep(p)
    report = run_sweep(spec, tmp_path / "sw", scheduler=in_process_scheduler)
    assert report.ok
    ds = xr.load_dataset(tmp_path / "sw" / "sweep.nc", engine="h5netcdf")
    amplitude = ds["amplitude"].values
    assert np.isfinite(amplitude).all()
    wanted = amplitude > 0.37  # the measured amplitudes, compared here
    assert 0 < wanted.sum() < len(wanted)
    store = SweepStore(tmp_path / "sw")
    for i, point in enumerate(spec.points()):
        kept = store.point_dir(point.hash) / "dataset.nc"
        assert kept.exists() == bool(wanted[i])
        assert ds["run"].values[i] == (str(store.point_dir(point.hash).relative_to(store.root)) if wanted[i] else "")
        if wanted[i]:
            with xr.open_dataset(kept, engine="h5netcdf") as run:
                assert run.attrs["status"] == "finished"
    dirs = [d for d in (tmp_path / "sw" / "points").glob("*/*") if not d.name.startswith(".")]  # not the locks
    assert len(dirs) == wanted.sum()
