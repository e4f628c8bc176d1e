"""No silent changes: the step used is the step requested and reported; frames sit at multiples of it."""

from __future__ import annotations

import math

import pytest

from flexmm.controller import schedule


def test_schedule_keeps_the_step_and_rounds_the_frame_interval() -> None:
    s = schedule(1.5e-3, 3e-4 / 1.0, 601, None)  # interval 2.5e-6 < dt: one step per frame
    assert s.h == 3e-4
    assert s.chunks == [1] * 5 and math.isclose(s.interval, 3e-4)
    assert any("rounded" in n for n in s.notes)
    s = schedule(1.0, 0.03, 11, None)  # duration 34 steps, interval 0.1 = 3.4 steps -> 3 steps
    assert s.h == 0.03 and s.chunks == [3] * 12  # uniform frames, the last one at or past the duration
    assert math.isclose(s.interval, 0.09) and 1.0 <= s.t_end < 1.0 + s.interval
    assert any("rounded up to 12 frame intervals" in n for n in s.notes)
    s = schedule(1.0, 0.001, 41, None)  # 1000 steps, 25 a frame
    assert s.chunks == [25] * 40 and s.notes == []
    s = schedule(1.0, 0.00097, 41, None)  # 1031 steps, 25.8 a frame -> 26: 40 uniform intervals of 26
    assert s.chunks == [26] * 40 and s.t_end >= 1.0
    s = schedule(1.0, 0.03, 11, 0.1)  # every_s: nearest whole number of steps
    assert s.chunks == [3] * 12 and s.t_end >= 1.0
    assert any("frame interval" in n for n in s.notes) and any("duration" in n for n in s.notes)
    s = schedule(1.0, 0.025, 11, None)  # divides: nothing to report
    assert s.chunks == [4] * 10 and s.notes == []


def test_exact_frame_times_shorten_the_step_and_say_so() -> None:
    s = schedule(1.0, 0.03, 11, None, exact=True)
    assert s.chunks == [4] * 10 and math.isclose(s.h, 0.025) and math.isclose(s.interval, 0.1)
    assert any("reduced" in n for n in s.notes)


@pytest.fixture(scope="module")
def small_hertz():
    from flexmm.config import load_scene

    return load_scene("configs/hertz_granular_impact.yaml",
                      ["lattice.n_units=12", "solver.duration_s=2e-5", "output.n_frames=9",
                       "solver.integrator=velocity_verlet", "solver.accuracy=null"])


def test_requested_step_is_the_step_in_attrs_and_log(tmp_path, small_hertz) -> None:
    """A given step that divides the frame interval is the step used; one that does not is refused
    with the nearest that do (it used to round the frame interval: frames off the requested times)."""
    from flexmm.api import run_scene
    from flexmm.errors import PlanError
    from flexmm.io.run_dataset import open_run
    from flexmm.plan.planner import replace_section

    with pytest.raises(PlanError, match=r"solver.dt_s = 3e-07 s does not divide the frame interval 2.5e-06 s.*"
                                        r"2.77778e-07 s \(9 steps per frame\) or 3.125e-07 s \(8 steps per frame\)"):
        run_scene(replace_section(small_hertz, "solver", dt_s=3e-7), run_dir=tmp_path / "r")
    res = run_scene(replace_section(small_hertz, "solver", dt_s=2.5e-7), run_dir=tmp_path / "r")
    ds = open_run(res.path)
    assert ds.attrs["dt_s"] == pytest.approx(2.5e-7, rel=1e-12)
    assert res.dt_s == pytest.approx(2.5e-7, rel=1e-12)
    assert "steps of 2.5e-07 s" in ds.attrs["log"]
    assert ds["time"].values == pytest.approx([k * 2.5e-6 for k in range(9)], abs=1e-15)
    assert ds.attrs["frame_interval_s"] == pytest.approx(2.5e-6) and ds.attrs["plan_changes"] == ""
