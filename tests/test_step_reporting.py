"""No silent changes: the step used is the step requested and reported; frames sit at multiples of it."""

from __future__ import annotations

import math

import pytest

from flexmm.controller import schedule


def test_schedule_lands_frames_on_the_requested_times() -> None:
    """A problem run directly (not through flexmm.prepare) follows the plan's rule: a step flexmm
    chose is shortened to divide the frame interval, and that change is returned; the duration and
    the frame times are never rounded (they used to be, silently: 0.03 over 11 frames of 1.0 ran to 1.08)."""
    s = schedule(1.0, 0.03, 11, None)  # interval 0.1 = 3.33 steps -> 4 steps of 0.025
    assert s.chunks == [4] * 10 and math.isclose(s.h, 0.025) and math.isclose(s.interval, 0.1)
    assert math.isclose(s.t_end, 1.0)
    assert len(s.notes) == 1 and "step: the chosen step 0.03 s shortened to 0.025 s" in s.notes[0]
    s = schedule(1.5e-3, 3e-4, 601, None)  # interval 2.5e-6 below the step: one shortened step per frame
    assert s.chunks == [1] * 600 and math.isclose(s.h, 2.5e-6) and math.isclose(s.t_end, 1.5e-3)
    s = schedule(1.0, 0.00097, 41, None)  # 25.8 steps a frame -> 26 shortened steps
    assert s.chunks == [26] * 40 and math.isclose(s.h, 0.025 / 26) and math.isclose(s.t_end, 1.0)
    s = schedule(1.0, 0.025, 11, None)  # divides: nothing changed
    assert s.chunks == [4] * 10 and s.h == 0.025 and s.notes == []
    s = schedule(2.0, 0.5, 11, None, time_s=0.1)  # in units of 0.1 s: the notes speak seconds
    assert s.chunks == [1] * 10 and math.isclose(s.h, 0.2) and "0.05 s shortened to 0.02 s" in s.notes[0]
    s = schedule(1.0, None, 11, None)  # adaptive: one call per frame
    assert s.chunks == [1] * 10 and math.isclose(s.h, 0.1) and s.notes == []


def test_schedule_refuses_what_no_step_can_meet() -> None:
    from flexmm.errors import PlanError

    with pytest.raises(PlanError, match=r"solver.dt_s = 0.03 s does not divide the frame interval 0.1 s"):
        schedule(1.0, 0.03, 11, None, given=True)  # a given step is the step used, or refused
    s = schedule(1.0, 0.03, 11, None, given=True, exact=True)  # ... unless exact_frame_times shortens it
    assert s.chunks == [4] * 10 and math.isclose(s.h, 0.025) and "solver.dt_s 0.03 s shortened" in s.notes[0]
    with pytest.raises(PlanError, match=r"output.every_s = 0.3 s does not divide solver.duration_s = 1 s"):
        schedule(1.0, 0.01, 11, 0.3)
    with pytest.raises(PlanError, match=r"output.every_s = 10 s is longer than solver.duration_s = 0.05 s"):
        schedule(0.05, 0.01, 11, 10.0)


def test_a_problem_run_directly_records_its_frame_change(tmp_path) -> None:
    """``run_problem`` on a problem built without the plan (the Python API): the step shortened to
    the frames is a ``plan: change:`` line of the log and a line of ``plan_changes``, as on the CLI."""
    from flexmm.assemble import build_problem
    from flexmm.config import load_scene
    from flexmm.controller import run_problem
    from flexmm.errors import PlanError
    from flexmm.io.run_dataset import open_run
    from flexmm.plan.planner import replace_section

    scene = load_scene("configs/hertz_granular_impact.yaml",
                       ["lattice.n_units=12", "solver.duration_s=2e-5", "output.n_frames=9",
                        "solver.integrator=velocity_verlet", "solver.accuracy=null", "solver.dt_fraction=0.3"])
    problem = build_problem(scene)
    dt_s = problem.dt * problem.system.scales.time_s
    assert abs(2.5e-6 / dt_s - round(2.5e-6 / dt_s)) > 1e-3  # the chosen step does not divide the interval
    res = run_problem(problem, tmp_path / "r")
    ds = open_run(res.path)
    changes = ds.attrs["plan_changes"].splitlines()
    assert len(changes) == 1 and changes[0].startswith(f"frames: step: the chosen step {dt_s:.6g} s shortened to")
    assert f"plan: change: {changes[0]}" in ds.attrs["log"].splitlines()
    assert ds["time"].values == pytest.approx([k * 2.5e-6 for k in range(9)], rel=1e-12, abs=1e-18)
    assert ds.attrs["dt_s"] < dt_s and res.dt_s == pytest.approx(ds.attrs["dt_s"], rel=1e-12)
    given = replace_section(scene, "solver", dt_s=3e-7)
    with pytest.raises(PlanError, match="solver.dt_s = 3e-07 s does not divide"):
        run_problem(build_problem(given), tmp_path / "g")
    assert not (tmp_path / "g" / "dataset.nc").exists()


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
