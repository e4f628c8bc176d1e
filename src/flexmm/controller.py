"""Advance a built problem in time, calling the compiled stepper between output times.

The controller owns the schedule (frames always include t = 0 and the final time), the
blow-up checks, progress reporting and the dataset writer; kernels only see arrays.
"""

from __future__ import annotations

import contextlib
import functools
import math
import signal
import time as _time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from flexmm._signals import absorbed, signal_of
from flexmm.assemble import Problem
from flexmm.checkpoint import Checkpoint, CheckpointError, Checkpointing
from flexmm.frames import frame_times
from flexmm.integrators import INTEGRATORS
from flexmm.integrators.dopri5 import S_ATOL, S_RTOL
from flexmm.integrators.parallel import available_threads
from flexmm.integrators.stepper import DEFAULT_RTOL, Outcome, Stepper, make_stepper
from flexmm.io.run_dataset import DatasetWriter, MemoryWriter, add_state, estimate_bytes, shape_variables
from flexmm.io.pause import pause_point
from flexmm.io.provenance import provenance_attrs
from flexmm.units import UNITS

#: seconds between progress lines when stderr is not a terminal (logs, batch jobs)
PROGRESS_EVERY_S = 10.0


#: a finished run is 'inaccurate' when its error estimate exceeds this × its target (solver.accuracy)
INACCURATE_FACTOR = 10.0
#: ... or, undriven and undamped, when its energy at the end differs from the start by more than this fraction
ENERGY_LIMIT = 1e-2
#: ... of its energy, or of this nondimensional energy if that is smaller: a run resting in its
#: ground state (E0 at round-off) does not change its energy by a fraction of nothing
ENERGY_FLOOR = 1e-12


def inaccuracy(attrs: dict, stepper: Stepper, problem: Problem) -> str | None:
    """Why a finished run is 'inaccurate' (docs/architecture.md, "Run statuses"), or None: its error
    estimate misses its target by more than ``INACCURATE_FACTOR``, or it conserves energy (no drive,
    no damping) and its energy at the end is off by more than ``ENERGY_LIMIT``."""
    est, target = attrs.get("accuracy_estimate"), attrs.get("accuracy_requested")
    # an estimate the pilots found not to shrink with the step measures a threshold's or a
    # collision's timing, not the integration error: the plan's warning says so, the status does not
    converges = attrs.get("accuracy_converges", 1)
    # an estimate extrapolated past the pilot (its error's growth, capped at t²) warns; only a
    # measured one decides the status
    measured = not attrs.get("accuracy_extrapolated", 0)
    if est is not None and target and converges and measured and not est <= INACCURATE_FACTOR * target:
        return (f"the error estimate {est:.3g} misses the target {target:g} by more than {INACCURATE_FACTOR:g}x "
                f"({est / target:.3g}x): the run is not resolved (smaller solver.dt_s, a higher-order method, or a "
                "gentler scene)")
    terms = problem.terms
    conservative = (terms.drv_dof.size == 0 and terms.dash_ij.shape[0] == 0 and not np.any(problem.damp))
    energies = stepper.energies() if conservative else None
    if energies is not None:
        e0, e = stepper.guard.e0, sum(energies)
        drift = abs(e - e0) / max(abs(e0), ENERGY_FLOOR)
        if drift > ENERGY_LIMIT:
            return (f"no drive or damping, yet its energy changed by {100 * drift:.3g} % (E = {e:.4g} from "
                    f"E0 = {e0:.4g}, nondimensional; at most {100 * ENERGY_LIMIT:g} %): the step does not resolve "
                    "the motion")
    return None


@dataclass
class RunResult:
    """Outcome of a run: status ('finished', 'inaccurate', 'failed', 'interrupted'), reason, counters.

    'inaccurate': the run went to its end but misses its accuracy by far (``inaccuracy``)."""

    status: str
    reason: str
    path: Path | None
    n_steps: int
    n_frames: int
    t_end_s: float
    dt_s: float
    stable_dt_s: float
    compile_s: float
    wall_s: float
    log: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return self.status == "finished"

    @property
    def signal(self) -> int | None:
        """The signal that interrupted the run (``signal.SIGINT``/``SIGTERM``), else None."""
        if self.status != "interrupted":
            return None
        return int(signal.SIGTERM) if "SIGTERM" in self.reason else int(signal.SIGINT)

    n_units: int = 0
    #: the run's error estimate and target (dataset attrs ``accuracy_*``), empty without one
    accuracy: dict = field(default_factory=dict)
    #: the run's dataset (xarray) when it was kept in memory instead of written (``in_memory``)
    dataset: Any = None

    @property
    def accuracy_missed(self) -> bool:
        """True when the run's error estimate exceeds its target."""
        return bool(self.accuracy) and not self.accuracy.get("accuracy_met", 1)


@dataclass(frozen=True)
class Schedule:
    """Step and frames of a run: ``h`` the step used, ``chunks`` the steps between successive
    frames, ``interval`` the frame interval (nondimensional), ``notes`` the changes made to land the frames on their times (``schedule``)."""

    h: float
    chunks: list[int]
    interval: float
    notes: list[str]

    @property
    def t_end(self) -> float:
        return self.h * sum(self.chunks)


def schedule(duration: float, dt: float | None, n_frames: int, every: float | None, *, exact: bool = False,
             given: bool = False, time_s: float = 1.0) -> Schedule:
    """The frames of a run and the step that lands on them, in the problem's time unit: the rule of
    every verb's plan (``flexmm.frames.frame_times``), for a problem run directly (``run_problem``
    without ``flexmm.prepare``, which has already fitted the step and changes nothing here).

    Frames at 0, Δ, …, T (Δ = ``every`` or ``duration``/(``n_frames`` − 1)). A step flexmm chose
    (``given`` False: ``solver.dt_fraction``), or any step with ``exact``, is shortened to the
    largest that divides Δ — a change, returned in ``notes`` (``run_problem`` prints it and records it
    in ``plan_changes``); a given step (``solver.dt_s``) that does not divide Δ, or an ``every`` that
    does not divide the duration, is refused (``PlanError`` naming the nearest valid values): the
    duration and the frame times are never rounded. ``dt`` None: an adaptive method, one call per
    frame. ``time_s`` converts to seconds for the rule and its messages.
    """
    frames, changes = frame_times(duration * time_s, n_frames, None if every is None else every * time_s,
                                  None if dt is None else dt * time_s, given=given, exact=exact)
    interval = frames.interval_s / time_s
    if frames.dt_s is None:
        return Schedule(interval, [1] * (frames.n_frames - 1), interval, changes)
    return Schedule(frames.dt_s / time_s, [frames.steps_per_frame] * (frames.n_frames - 1), interval, changes)


#: the step is reduced when it exceeds this fraction of the current state's stable limit ...
STIFF_TRIGGER = 0.9
#: ... to at most this fraction of it (frames stay where they were: the step becomes h0/m)
STIFF_TARGET = 0.7
#: the checks take at most this share of the time spent advancing (frames are skipped to keep it)
STIFF_SHARE = 0.05
STIFF_FLOOR_S = 0.05  # ... or this many seconds in all (a small run checks most frames)
#: the first check's cost in steps of the run per Lanczos iteration (2 force evaluations by the
#: unfused force kernel, the reorthogonalisation): ~47 measured at 3·10⁵ units with the fused chain
#: Verlet, so a 1,000-step run of a large lattice skips the check rather than spend 28 % on it
STIFF_FIRST_STEPS = 40
#: a step reduced more than this many times is a diagnosis, not a run
STIFF_MAX_REDUCTION = 1000


class _StepFollower:
    """The step follows the stiffness: at every frame, ω_max of the current state
    (``stability.StiffnessTracker``, warm-started Lanczos); when the step exceeds ``STIFF_TRIGGER``
    of the state's stable limit, a symplectic method's step is reduced to h0/m ≤ ``STIFF_TARGET``
    × that limit for the rest of the run (frames keep their times; logged, in attrs), any other
    fixed-step method stops with a diagnosis (time, step, stable limit). Frames are the cadence
    (a resolved run changes its stiffness little within a frame interval; each check costs
    2 × iters force evaluations plus Python overhead), thinned so the checks take at most
    ``STIFF_SHARE`` of the advancing time (count and seconds reported). Off for adaptive
    and A-stable methods and with ``solver.allow_unstable``.
    """

    def __init__(self, problem: Problem, spec, stepper: Stepper, say: Callable[[str], None]):
        self.problem, self.spec, self.say = problem, spec, say
        self.h0, self.m = stepper.h, 1
        self.on = spec.explicit_limit and not problem.scene.solver.allow_unstable and problem.omega_max > 0
        self.tracker = None
        if self.on:
            from flexmm.stability import StiffnessTracker

            self.tracker = StiffnessTracker(problem.system, problem.terms)
        self.w_top, self.checks, self.reductions = problem.omega_max, 0, 0
        self.failure = ""

    def chunks(self, chunks):
        for n in chunks:
            yield n * self.m

    def check(self, st: Stepper) -> bool:
        """True to stop the run (failure set)."""
        if not self.on:
            return False
        budget = max(STIFF_SHARE * st.wall_s, STIFF_FLOOR_S)
        if self.checks and self.tracker.seconds > budget:
            return False  # over its budget: wait until the run has advanced further
        if not self.checks and STIFF_FIRST_STEPS * self.tracker.iters * st.wall_s / max(st.steps, 1) > budget:
            return False  # a large lattice: the first check too waits until the run has paid for it
        w = self.tracker.omega(st.q)
        self.checks += 1
        self.w_top = max(self.w_top, w)
        lim = self.spec.stability_limit / w if w > 0 else math.inf
        if st.h <= STIFF_TRIGGER * lim:
            return False
        ts = self.problem.system.scales.time_s
        at = (f"at t = {st.t * ts:.6g} s the state's stable limit is {lim * ts:.4g} s "
              f"(ω_max {w / ts:.4g} rad/s, {w / self.problem.omega_max:.3g} x its value at the start)")
        m = max(self.m + 1, math.ceil(self.h0 / (STIFF_TARGET * lim)))
        if not self.spec.symplectic or m > STIFF_MAX_REDUCTION:
            why = ("it is not symplectic: its step is not changed within a run" if not self.spec.symplectic
                   else f"the step would have to shrink {m} times")
            self.failure = (f"stopped: {at}, below the step dt = {st.h * ts:.4g} s of {self.spec.name}, and {why}; "
                            "use a symplectic method or a smaller solver.dt_s")
            return True
        self.m = m
        st.h = self.h0 / m
        self.reductions += 1
        self.say(f"step reduced: {at}; dt {self.h0 * ts:.4g} s -> {st.h * ts:.4g} s (h0/{m}) from here on")
        return False

    def snapshot(self) -> tuple[dict, dict]:
        """(arrays, scalars) of the follower for a checkpoint: its reduction, counters, and the
        stiffness tracker's warm-start vector."""
        scalars = {"m": self.m, "w_top": self.w_top, "checks": self.checks, "reductions": self.reductions,
                   "tracker_s": self.tracker.seconds if self.tracker else 0.0}
        return ({"tracker_x": self.tracker.x} if self.tracker else {}), scalars

    def restore(self, arrays: dict, scalars: dict) -> None:
        self.m, self.w_top = int(scalars["m"]), float(scalars["w_top"])
        self.checks, self.reductions = int(scalars["checks"]), int(scalars["reductions"])
        if self.tracker is not None:
            self.tracker.x = np.array(arrays["tracker_x"])
            self.tracker.seconds = float(scalars["tracker_s"])

    def summary(self) -> None:
        if self.on and self.checks:
            ts = self.problem.system.scales.time_s
            self.say(f"stiffness tracked at {self.checks} frames: largest ω_max {self.w_top / ts:.4g} rad/s "
                     f"({self.w_top / self.problem.omega_max:.3g} x the start), {self.tracker.seconds:.3f} s")

    def attrs(self, wall: float) -> dict:
        if not self.on:
            return {}
        ts = self.problem.system.scales.time_s
        return {"dt_min_s": self.h0 / self.m * ts, "step_reductions": self.reductions,
                "stiffness_checks": self.checks, "stiffness_check_s": self.tracker.seconds,
                "omega_max_run_rad_s": self.w_top / ts}


class _Observer:
    """Turns the nondimensional state into SI frames for the writer."""

    def __init__(self, problem: Problem, writer_path: Path, n_frames: int | None = None, writer=None):
        sys_, out = problem.system, problem.scene.output
        self.sys = sys_
        self.stride = out.site_stride
        self.sites = np.arange(0, sys_.n_sites, self.stride)
        names = out.fields or [f.name for f in sys_.fields]
        self.fields = [f for f in sys_.fields if f.name in names]
        self.velocities = out.velocities
        self.energy = out.energy
        sc = sys_.scales
        site_vars, time_vars = {}, {}
        for f in self.fields:
            u, du = UNITS[f.kind]
            site_vars[f.name] = (u, f.long_name)
            if self.velocities:
                site_vars[f.name + "_dot"] = (du, f"rate of {f.long_name}")
        if self.energy:
            for name, long in (
                ("kinetic_energy", "kinetic energy"),
                ("potential_energy", "potential energy"),
                ("total_energy", "kinetic + potential energy"),
                ("dissipated_energy", "energy dissipated by damping since t = 0"),
                ("applied_work", "work done by applied forces since t = 0"),
            ):
                time_vars[name] = ("J", long)
        for name, (idx, kind) in sys_.extra_dofs.items():
            u, du = UNITS[kind]
            time_vars[name + "_position"] = (u, f"{name} displacement")
            time_vars[name + "_velocity"] = (du, f"{name} velocity")
        attrs = sys_.site_coord_attrs  # (units, long_name) of non-length coordinates
        coords = {k: (v[self.sites], *attrs.get(k, ("m", f"{k} position in the reference configuration")))
                  for k, v in sys_.site_coords.items()}
        add_state(sys_, self.sites, site_vars, coords)  # rest and initial state: analysis never rebuilds the model
        self.site_vars, self.time_vars = site_vars, time_vars
        self.writer = (writer or DatasetWriter)(writer_path, self.sites.size, site_vars, time_vars, coords, n_frames,
                                                shape_variables(sys_.unit_shapes(), self.sites, sc.length_m))
        self.sc = sc

    def frame(self, st: Stepper) -> None:
        """Write the stepper's current state as one SI frame."""
        pause_point("frame")
        s, sc = self.sys, self.sc
        q, v = st.q, st.v
        site_vals, time_vals = {}, {}
        stride = self.stride
        for f in self.fields:
            k = s.field_index(f.name) * s.n_sites
            rows = slice(k, k + s.n_sites, stride)  # the sites self.sites: a view, not a gather
            site_vals[f.name] = q[rows] * sc.coordinate(f.kind)
            if self.velocities:
                site_vals[f.name + "_dot"] = v[rows] * sc.rate(f.kind)
        if self.energy:
            kin, pot = st.last_energies or st.energies()
            e = sc.energy
            time_vals.update(
                kinetic_energy=kin * e, potential_energy=pot * e, total_energy=(kin + pot) * e,
                dissipated_energy=st.ledger.dissipated * e, applied_work=st.ledger.work * e,
            )
        for name, (idx, kind) in s.extra_dofs.items():
            time_vals[name + "_position"] = q[idx] * sc.coordinate(kind)
            time_vals[name + "_velocity"] = v[idx] * sc.rate(kind)
        self.writer.append(st.t * sc.time_s, site_vals, time_vals)


def _runs(chunks: list[int]) -> list[list[int]]:
    """``chunks`` as [value, count] runs (a checkpoint's record of the schedule)."""
    out: list[list[int]] = []
    for n in chunks:
        if out and out[-1][0] == n:
            out[-1][1] += 1
        else:
            out.append([int(n), 1])
    return out


def _resume(ck: Checkpoint, stepper: Stepper, track: _StepFollower, obs: _Observer, plan: Schedule,
            lines: list[str], say: Callable[[str], None]) -> tuple[int, list[str]]:
    """Put the run where checkpoint ``ck`` left it: state, follower, frames, log. Returns the
    chunks done and the resumptions (its own noted). A longer schedule than the checkpoint's
    (``--extend``) must begin with the same step and chunks."""
    m = ck.meta
    done = m["frames_done"] - 1
    ts = stepper.system.scales.time_s
    before = [n for n, k in m["chunks"] for _ in range(k)][:done]
    if m["h0"] != plan.h or plan.chunks[:done] != before or m["frames_written"] != m["frames_done"]:
        raise CheckpointError(f"{ck.path}: its schedule (step {m['h0'] * ts:.6g} s, {m['frames_total']} frames) is not "
                              f"the start of this run's (step {plan.h * ts:.6g} s, {len(plan.chunks) + 1} frames)")
    stepper.restore(ck.arrays, m["stepper"])
    track.restore(ck.arrays, m["follower"])
    try:
        obs.writer.copy_frames(ck.dataset(), m["frames_written"], m["t_written_s"])
    except OSError as exc:
        raise CheckpointError(f"the frames of {ck.path} cannot be continued: {ck.dataset()}: "
                              f"{exc.strerror or exc}") from None
    lines[:] = m["log"]
    note = (f"resumed at t = {m['t_s']:.6g} s (frame {done}, step {m['steps']}) from {ck.path} "
            f"(written {m['written']} by flexmm {m['flexmm_version']}, {m['git_commit']})")
    say(note)
    return done, [*m.get("resumptions", []), note]


def _close(writer, attrs: dict, spill: bool, say: Callable[[str], None]) -> tuple[Path | None, bool]:
    """Close the run's writer: (its path, False if ``spill`` failed). ``spill``: an in-memory run's
    frames are first written beside its final checkpoint (``MemoryWriter.sync``)."""
    if spill:
        try:
            writer.sync()
        except OSError as exc:
            say(f"warning: the frames of the final checkpoint could not be written ({exc.strerror or exc})")
            return writer.close(attrs), False
    elif hasattr(writer, "discard_spill"):  # frames written for earlier checkpoints: none will need them
        writer.discard_spill()
    return writer.close(attrs), True


def _progress(total: int, enabled: bool):
    if not enabled:
        return None
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    prog = Progress(TextColumn("[bold]run"), BarColumn(), TextColumn("{task.percentage:>5.1f}%"),
                    TimeRemainingColumn(), transient=True)
    prog.start()
    prog.add_task("run", total=total)
    return prog


def run_problem(
    problem: Problem, run_dir: Path, *, progress: bool = False,
    log: Callable[[str], None] | None = None, extra_attrs: dict | None = None,
    on_finish: Callable | None = None, in_memory: bool = False,
    checkpoints: Checkpointing | None = None, resume: Checkpoint | None = None,
) -> RunResult:
    """Integrate ``problem`` and write ``run_dir/dataset.nc``; never raises on a blow-up.

    ``on_finish(q, v, h, say, t) -> dict`` (if given) sees the final state of a finished run
    and returns extra attrs (used by flexmm.plan for its accuracy check). ``in_memory``: no
    dataset file; ``result.dataset`` holds what it would have held (``io.run_dataset.MemoryWriter``).
    ``checkpoints``: write checkpoints (``flexmm.checkpoint``) into ``run_dir`` at frames, every
    ``checkpoints.every_s`` of wall time, when the run ends (finished: for ``--extend``) and
    when a signal stops it. ``resume``: continue from that checkpoint instead of t = 0 (its frames
    copied from its dataset; ``CheckpointError`` when it does not fit this problem's schedule).
    """
    scene, s = problem.scene, problem.system
    spec = INTEGRATORS[scene.solver.integrator]
    sc = s.scales
    lines: list[str] = []

    def say(msg: str) -> None:
        lines.append(msg)
        if log:
            log(msg)

    for note in problem.notes:
        say(note)
    every = scene.output.every_s / sc.time_s if scene.output.every_s else None
    plan = schedule(problem.duration, None if spec.adaptive else problem.dt, scene.output.n_frames, every,
                    exact=scene.output.exact_frame_times, given=scene.solver.dt_s is not None, time_s=sc.time_s)
    h, chunks = plan.h, plan.chunks
    changes = [f"frames: {note}" for note in plan.notes]  # a problem flexmm.prepare did not fit to its frames
    for change in changes:
        say(f"plan: change: {change}")
    n_frames = len(chunks) + 1
    spill = None if checkpoints is None else checkpoints.directory  # an in-memory run's frames, for a checkpoint
    obs = _Observer(problem, run_dir / "dataset.nc", n_frames,
                    functools.partial(MemoryWriter, spill=spill) if in_memory else None)
    size = estimate_bytes(n_frames, obs.sites.size, len(obs.site_vars), len(obs.time_vars))
    steps = (f"adaptive steps (rtol {scene.solver.rtol or DEFAULT_RTOL:g})" if spec.adaptive
             else f"{sum(chunks)} steps of {h * sc.time_s:.4g} s")
    stepper = make_stepper(problem, spec, h=h, threads=scene.solver.threads,
                           rtol=(scene.solver.rtol or DEFAULT_RTOL) if spec.adaptive else None,
                           atol=scene.solver.atol,
                           max_step=scene.solver.dt_s / sc.time_s if scene.solver.dt_s else None, warm=False)
    threads = stepper.threads
    asked = scene.solver.threads
    if asked is not None and asked > available_threads():
        say(f"solver.threads {asked} > the {available_threads()} threads this process may use: "
            f"running on {threads}")
    say(f"{s.model}: {s.n_sites} units, {s.ndof} DOFs, {spec.name}, {steps} "
        f"(stable limit {problem.stable_dt * sc.time_s:.4g} s), {n_frames} frames, ~{size / 2**20:.1f} MiB"
        + (f", {threads} threads" if threads > 1 else ""))

    track = _StepFollower(problem, spec, stepper, say)
    start, resumptions = 0, []  # chunks done before (a resumed run), and the resumptions noted
    if resume is not None:
        try:
            start, resumptions = _resume(resume, stepper, track, obs, plan, lines, say)
        except BaseException:
            obs.writer.abort()
            raise
    done, at_frame = [start + 1], [stepper.steps]  # frames appended (frame 0 included); steps at the last
    early: Outcome | None = None  # a signal while compiling or writing frame 0: the run stops there
    try:
        compile_s = stepper.warm_up()
        if resume is None:
            obs.frame(stepper)
    except KeyboardInterrupt as exc:  # Ctrl-C, or SIGTERM under _signals.stop_on_signals
        compile_s = stepper.compile_s
        early = Outcome("interrupted", signal.Signals(signal_of(exc)).name, stepper.t)
    prog = _progress(len(chunks), progress)
    if prog and start:
        prog.advance(prog.task_ids[0], start)
    write_error: list[tuple[float, OSError]] = []
    ckpt_error: list[tuple[float, OSError]] = []  # a checkpoint that could not be written: the run stops
    last_line = [_time.monotonic()]

    clock = [_time.monotonic()]  # when the last checkpoint was written
    saved_t: list[float] = [resume.meta["t_s"]] if resume is not None else []  # time of the last checkpoint (s)

    def checkpoint(status: str, dataset: str, durable: bool = True) -> None:
        """Write a checkpoint of the state now (``OSError`` if it cannot be: the previous one stays)."""
        arrays, scalars = stepper.snapshot()
        f_arrays, f_scalars = track.snapshot()
        w = obs.writer
        meta = {"status": status, "frames_done": done[0], "frames_total": n_frames, "frames_written": w.n_written,
                "t_written_s": w.t_written, "dataset": dataset, "steps": stepper.steps, "t_s": stepper.t * sc.time_s,
                "h0": plan.h, "chunks": _runs(chunks), "interval": plan.interval, "problem_dt": problem.dt,
                "duration": problem.duration, "stepper": scalars, "follower": f_scalars, "log": list(lines),
                "resumptions": resumptions}
        checkpoints.save(meta, {**arrays, **f_arrays}, durable)
        saved_t.append(stepper.t * sc.time_s)
        clock[0] = _time.monotonic()

    def on_frame(st: Stepper) -> bool:
        try:
            obs.frame(st)
        except OSError as exc:  # disk full, quota, I/O error: stop, keep the frames written
            write_error.append((st.t, exc))
            return True
        done[0], at_frame[0] = done[0] + 1, st.steps
        if track.check(st):
            return True
        if checkpoints is not None and _time.monotonic() - clock[0] >= checkpoints.every_s:
            t0 = _time.perf_counter()
            try:
                obs.writer.sync()  # the frames a checkpoint counts are on disk before it is written
            except OSError as exc:
                write_error.append((st.t, exc))
                return True
            checkpoints.seconds += _time.perf_counter() - t0
            try:
                checkpoint("running", obs.writer.tmp.name)
            except OSError as exc:  # a full disk: stop now rather than run on with nothing to resume from
                ckpt_error.append((st.t, exc))
                return True
        if prog:
            prog.advance(prog.task_ids[0])
        elif log is not None and _time.monotonic() - last_line[0] >= PROGRESS_EVERY_S:
            last_line[0] = _time.monotonic()
            frac = min(st.t / problem.duration, 1.0)
            eta = st.wall_s * (1 - frac) / frac if frac > 0 else float("nan")
            log(f"progress: t = {st.t * sc.time_s:.4g} s of {problem.duration * sc.time_s:.4g} s "
                f"({100 * frac:.1f} %), {st.steps} steps, {st.wall_s:.0f} s elapsed, ~{eta:.0f} s left")
        return False

    try:
        outcome = early or stepper.run(track.chunks(chunks[start:]), on_frame)
    finally:
        if prog:
            prog.stop()
    if not write_error:
        try:  # the frames still buffered: a write that fails here is a write failure like any other
            obs.writer.flush()
        except OSError as exc:
            write_error.append(((obs.writer.t_written or 0.0) / sc.time_s, exc))
    status, t = outcome.status, stepper.t
    n_steps = stepper.steps
    reason = ""
    if status == "failed":
        reason = (f"blow-up between t = {outcome.t_good * sc.time_s:.6g} s and {t * sc.time_s:.6g} s "
                  f"({outcome.reason}) with dt = {h * sc.time_s:.4g} s; "
                  f"stable limit {problem.stable_dt * sc.time_s:.4g} s; "
                  f"last good time {outcome.t_good * sc.time_s:.6g} s kept")
    if track.failure and status == "finished":
        status, reason = "failed", track.failure
    if write_error or ckpt_error:
        t_bad, exc = (write_error or ckpt_error)[0]
        status = "failed"
        w = obs.writer
        kept = "no frames are kept" if w.t_written is None else (
            f"the {w.n_written} frames written before it (to t = {w.t_written:.6g} s) are kept")
        what = "writing frames" if write_error else "writing a checkpoint"
        reason = f"{what} failed at t = {t_bad * sc.time_s:.6g} s ({exc.strerror or exc}); {kept}"
        if checkpoints is not None:
            reason += (f", and the checkpoint of t = {saved_t[-1]:.6g} s, which --resume continues from once "
                       "there is room" if saved_t else "; no checkpoint was written before it")
    elif status == "interrupted":
        reason = (f"interrupted by {outcome.reason} at t = {t * sc.time_s:.6g} s; frames up to "
                  f"{outcome.t_good * sc.time_s:.6g} s kept")
    wall = stepper.wall_s
    mups = n_steps * s.n_sites / wall / 1e6 if wall > 0 else float("nan")
    say(f"{status}: {n_steps} steps in {wall:.3f} s ({mups:.1f} M unit-steps/s), compile {compile_s:.2f} s")
    if reason and not (write_error or ckpt_error):  # what a write failure kept is known once the file is closed
        say(reason)
    track.summary()
    if checkpoints is not None and checkpoints.count:
        say(f"checkpoints: {checkpoints.count} written ({checkpoints.bytes / 2**20:.3g} MiB each), "
            f"{checkpoints.seconds:.3g} s")
    if on_finish is not None and status == "finished":
        extra_attrs = {**(extra_attrs or {}), **on_finish(stepper.q, stepper.v, h, say, t)}
    if status == "finished":
        why = inaccuracy(extra_attrs or {}, stepper, problem)
        if why is not None:
            status, reason = "inaccurate", why
            say(f"inaccurate: {why}")
    counters = stepper.ledger.counters()
    solver_attrs = {"threads": threads, "force_evaluations": counters["force_evaluations"]}
    if spec.adaptive:
        h = t / n_steps if n_steps else h  # mean accepted step (frames are dense output)
        solver_attrs.update(rtol=float(stepper.acc[S_RTOL]), atol=float(stepper.acc[S_ATOL]),
                            rejected_steps=counters["rejected_or_newton"])
    if spec.implicit:
        solver_attrs.update(newton_iterations=counters["rejected_or_newton"], krylov_iterations=counters["krylov"])
    attrs = {
        **provenance_attrs(scene),
        "title": scene.name,
        "description": scene.description,
        "model": s.model,
        "integrator": spec.name,
        "dt_s": h * sc.time_s,
        "frame_interval_s": plan.interval * sc.time_s,
        "exact_frame_times": int(bool(scene.output.exact_frame_times)),
        "stable_dt_s": problem.stable_dt * sc.time_s,
        "omega_max_rad_s": problem.omega_max / sc.time_s,
        "n_steps": n_steps,
        **solver_attrs,
        **track.attrs(wall),
        "compile_time_s": compile_s,
        "wall_time_s": wall,
        "cpu_time_s": stepper.cpu_s,
        "status": status,
        "status_reason": reason,
        "length_scale_m": sc.length_m,
        "time_scale_s": sc.time_s,
        "mass_scale_kg": sc.mass_kg,
        "spacing_m": s.spacing_m,
        "log": "\n".join(lines),
        **({"resumed": "\n".join(resumptions), "n_resumptions": len(resumptions)} if resumptions else {}),
        **(extra_attrs or {}),
    }
    attrs["plan_changes"] = "\n".join(c for c in (attrs.get("plan_changes", ""), *changes) if c)
    # the state the run ended in, which --resume (interrupted) or --extend go on from (a run kept in
    # memory: only when interrupted, its frames then written beside the checkpoint)
    final = (checkpoints is not None and early is None and status != "failed" and stepper.steps == at_frame[0]
             and obs.writer.n_written == done[0] and (not in_memory or status == "interrupted"))
    with absorbed() if status == "interrupted" else contextlib.nullcontext():
        path, spilled = _close(obs.writer, attrs, final and in_memory, say)
        if final and spilled and path is not None:
            try:  # not fsynced, like the dataset beside it (a power cut may lose both; the death of the process neither)
                checkpoint(status, path.name, durable=False)
            except OSError as exc:
                say(f"warning: the checkpoint of the run's end could not be written ({exc.strerror or exc}): "
                    + ("--resume continues from the one before" if status == "interrupted"
                       else "it cannot be --extended"))
            else:
                if status != "interrupted":
                    checkpoints.drop_previous()
    if path is None:  # the file could not be completed: say so, never claim frames that are gone
        status = "failed"
        head = (f"writing frames failed at t = {write_error[0][0] * sc.time_s:.6g} s" if write_error
                else f"{reason + '; ' if reason else ''}writing the dataset failed")
        reason = f"{head} ({obs.writer.closed_why}); nothing was kept"
        say(reason)
    elif write_error or ckpt_error:
        say(reason)
    return RunResult(status, reason, path, n_steps, obs.writer.n_written, t * sc.time_s, h * sc.time_s,
                     problem.stable_dt * sc.time_s, compile_s, wall, lines, n_units=s.n_sites,
                     accuracy={k: v for k, v in attrs.items() if k.startswith("accuracy_")
                               and "accuracy_estimate" in attrs},
                     dataset=getattr(obs.writer, "dataset", None))
