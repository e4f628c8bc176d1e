"""Frame times and the step that reaches them: frames land on the requested times, or the request is refused.

A run saves frames at t = 0, Δ, 2Δ, …, T with Δ = ``output.every_s`` or T/(``output.n_frames`` − 1)
and T = ``solver.duration_s``. A fixed-step method reaches them only with a step that divides Δ, so
``frame_times(...)`` decides, once, for every verb (``flexmm.prepare.resolve``) and for a problem run
without the plan (``controller.schedule``):

- a step flexmm chose (accuracy pilots, ``solver.dt_fraction``), or a given ``solver.dt_s`` with
  ``output.exact_frame_times: true``: the largest step ≤ it that divides Δ — a change of step,
  returned as a change line (printed on stdout and stored in the dataset's ``plan_changes``);
- a given ``solver.dt_s`` that does not divide Δ (without ``exact_frame_times``): refused, naming
  the nearest steps that do;
- ``every_s`` longer than T or not dividing T: refused, naming the nearest durations and intervals
  (the last frame is the run's end; earlier versions rounded the duration up silently).

An adaptive method steps to each frame time itself (nothing to change).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from flexmm.errors import PlanError

#: relative tolerance of "divides" (a step a few ulps off a divisor divides)
TOL = 1e-9


@dataclass(frozen=True)
class FrameTimes:
    """Frames at ``k · interval_s``, k = 0 … ``n_frames`` − 1, the last at ``t_end_s``; ``dt_s`` the step
    (None: adaptive) and ``steps_per_frame`` whole steps between frames."""

    n_frames: int
    interval_s: float
    t_end_s: float
    dt_s: float | None
    steps_per_frame: int | None

    @property
    def n_steps(self) -> int | None:
        return None if self.steps_per_frame is None else self.steps_per_frame * (self.n_frames - 1)


def _g(x: float) -> str:
    return f"{x:.6g}"


def interval(duration_s: float, n_frames: int, every_s: float | None) -> tuple[float, int]:
    """(Δ in s, frame count) of the request; PlanError if ``every_s`` does not divide the duration."""
    if every_s is None:
        return duration_s / (n_frames - 1), n_frames
    k = duration_s / every_s
    if k < 1 - TOL:
        raise PlanError(f"output.every_s = {_g(every_s)} s is longer than solver.duration_s = {_g(duration_s)} s "
                        f"(no frame between the start and the end); nearest valid: output.every_s = "
                        f"{_g(duration_s)} s (2 frames) or solver.duration_s = {_g(every_s)} s")
    n = round(k)
    if abs(k - n) > TOL * k:
        lo, hi = math.floor(k), math.ceil(k)
        raise PlanError(f"output.every_s = {_g(every_s)} s does not divide solver.duration_s = {_g(duration_s)} s "
                        f"({k:.6g} intervals; the last frame is the run's end); nearest valid: solver.duration_s = "
                        f"{_g(lo * every_s)} or {_g(hi * every_s)} s, or output.every_s = {_g(duration_s / lo)} or "
                        f"{_g(duration_s / hi)} s (output.n_frames = {lo + 1} or {hi + 1})")
    return duration_s / n, n + 1


def frame_times(duration_s: float, n_frames: int, every_s: float | None, dt_s: float | None, *,
                given: bool, exact: bool, stable_dt_s: float | None = None) -> tuple[FrameTimes, list[str]]:
    """The frames and step of a run (module docstring) and the changes made to reach them.

    ``dt_s`` the step the run would take (None: adaptive), ``given`` True when it is the scene's own
    ``solver.dt_s``, ``exact`` ``output.exact_frame_times``; ``stable_dt_s`` keeps an unstable step out
    of the suggestions. PlanError for a request no step can meet.
    """
    every, n = interval(duration_s, n_frames, every_s)
    if dt_s is None:
        return FrameTimes(n, every, duration_s, None, None), []
    spf = max(1, round(every / dt_s))
    if abs(spf * dt_s - every) <= TOL * every:
        return FrameTimes(n, every, duration_s, dt_s, spf), []
    below = max(1, math.ceil(every / dt_s - TOL))
    h = every / below
    if given and not exact:
        above = math.floor(every / dt_s)
        options = [f"{_g(h)} s ({below} steps per frame)"]
        if above >= 1 and (stable_dt_s is None or every / above <= stable_dt_s):
            options.append(f"{_g(every / above)} s ({above} steps per frame)")
        raise PlanError(f"solver.dt_s = {_g(dt_s)} s does not divide the frame interval {_g(every)} s, so frames "
                        f"would fall off the requested times; nearest valid: solver.dt_s = {' or '.join(options)}, "
                        "or output.exact_frame_times: true (shortens the step to divide the interval)")
    why = "solver.dt_s" if given else "the chosen step"
    change = (f"step: {why} {_g(dt_s)} s shortened to {_g(h)} s so frames land on the requested times "
              f"({below} steps per frame interval of {_g(every)} s)")
    return FrameTimes(n, every, duration_s, h, below), [change]
