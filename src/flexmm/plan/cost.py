"""What a run will cost, estimated before any work: steps, memory, output size, time.

``estimate(scene)`` reads sizes from the config and gets the step from a small copy of the
lattice (at most ``PROBE_SITES`` units, the same unit cell, so the same stiffest mode and stable
step) — in well under a second for any size, where building a 10⁷-unit chain to find its step
would take minutes. ``check(cost, out_dir)`` compares it with the limits below and with the free
space where the output goes; ``enforce`` raises ``ResourceError`` (a user error) unless forced.

Limits, overridable in the environment: ``FLEXMM_MAX_MEMORY_GIB`` (default: 80 % of this
machine's memory), ``FLEXMM_MAX_OUTPUT_GIB`` (default 100), ``FLEXMM_MAX_STEPS`` (default 1e10); a value that is not a positive number is refused with a
message naming the variable (``flexmm.environment``).
The memory figure is a model, not a measurement: ``BYTES_PER_DOF`` for state, scratch, parameter
tables and the frame buffer (a streamed 10⁶-unit chain peaked at 0.67 GiB, ≈ 35 doubles per DOF
above the interpreter's ≈ 0.15 GiB), plus ``BASE_BYTES``.

The time is steps × units over a measured throughput (``throughput``) plus a measured cost per call
(one per frame): unit-steps per CPU second of the compiled stepper for the model kind, the method
and the lattice size, and its CPU seconds per call, from the calibration table
``flexmm/data/throughput.csv`` (written by ``python benchmarks/calibrate.py``, which times the
stepper on every shipped scene and on larger copies of the chains; ``calibrate.py check`` runs the
shipped scenes and compares). Sizes between calibrated ones are interpolated in log–log, sizes
outside take the nearest; a method not calibrated for a kind is scaled from one that is by their
force evaluations per step; a kind not in the table takes the table's median (said in the line).
"""

from __future__ import annotations

import csv
import math
import os
import shutil
from dataclasses import dataclass, field
from functools import lru_cache
from importlib import resources
from pathlib import Path

from flexmm import environment
from flexmm.errors import FlexmmError

PROBE_SITES = 256  # largest lattice built to find the step
EXACT_SITES = 4096  # up to this size the scene itself is built (exact step, strikers included)
#: up to this size ``flexmm validate`` shows the run's own plan (``prepare.resolve``: the lattice built,
#: the accuracy pilots run, seconds); above it the estimate from a small copy (under a second)
PLANNED_SITES = 200_000
BYTES_PER_DOF = 40 * 8
BASE_BYTES = 200 * 2**20
CALIBRATION = "throughput.csv"  # in flexmm/data: kind, method, n_units, threads, unit_steps_per_s, call_s, scene
GIB = 2**30


class ResourceError(FlexmmError):
    """A run beyond the configured limits or the free disk space (``--force`` runs it anyway)."""


def limits() -> dict[str, float]:
    """The limits in force: memory and output in GiB, steps."""
    try:
        ram = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE") / GIB
    except (ValueError, OSError, AttributeError):
        ram = 16.0
    return {"memory_gib": environment.number("FLEXMM_MAX_MEMORY_GIB", 0.8 * ram),
            "output_gib": environment.number("FLEXMM_MAX_OUTPUT_GIB", 100.0),
            "steps": environment.number("FLEXMM_MAX_STEPS", 1e10)}


@dataclass
class Cost:
    """Estimated size and cost of a run (``steps``/``dt_s`` None when no step could be found)."""

    n_sites: int
    ndof: int
    frames: int
    saved_sites: int
    output_bytes: int
    memory_bytes: int
    dt_s: float | None = None
    steps: float | None = None
    notes: list[str] = field(default_factory=list)
    stable_dt_s: float | None = None
    rate: float = math.nan  # unit-steps per second (``throughput``)
    call_s: float = 0.0  # seconds per call into the stepper beyond its steps (one call per frame)
    rate_note: str = ""

    @property
    def seconds(self) -> float | None:
        """Integration time at the calibrated throughput ``rate`` and cost of a call, one per frame
        (compile, pilots and writing apart): the time on an idle machine (a loaded one stretches it)."""
        if self.steps is None:
            return None
        return self.steps * self.n_sites / self.rate + max(self.frames - 1, 0) * self.call_s

    def time_line(self) -> str:
        """'≈ 0.05 s at 2.3 M unit-steps/s and 20 µs a frame (calibrated ...)' (empty without steps)."""
        if self.steps is None:
            return ""
        return (f"≈ {_duration(self.seconds)} at {self.rate / 1e6:.3g} M unit-steps/s and {self.call_s * 1e6:.2g} µs "
                f"a frame ({self.rate_note})")

    def lines(self) -> list[str]:
        steps = ("steps unknown" if self.steps is None
                 else f"{self.steps:.4g} steps of {self.dt_s:.4g} s ({self.time_line()})")
        return [f"cost: {self.n_sites:,} units, {self.ndof:,} DOFs, {steps}; memory ≈ "
                f"{self.memory_bytes / GIB:.2g} GiB; output {self.frames:,} frames × {self.saved_sites:,} sites "
                f"≈ {self.output_bytes / GIB:.3g} GiB", *[f"cost: {n}" for n in self.notes]]


@lru_cache(maxsize=1)
def calibration() -> tuple[dict, ...]:
    """The rows of the calibration table (``CALIBRATION``), numbers parsed."""
    text = resources.files("flexmm.data").joinpath(CALIBRATION).read_text()
    rows = []
    for r in csv.DictReader(line for line in text.splitlines() if not line.startswith("#")):
        rows.append({**r, "n_units": int(r["n_units"]), "threads": int(r["threads"]),
                     "unit_steps_per_s": float(r["unit_steps_per_s"]), "call_s": float(r.get("call_s") or 0.0)})
    return tuple(rows)


def _interpolate(points: list[tuple[int, float]], n: int) -> float:
    """log–log interpolation of (size, rate) points at ``n`` (the nearest end outside); several rates
    at one size are averaged geometrically."""
    by_size: dict[int, list[float]] = {}
    for size, rate in points:
        by_size.setdefault(size, []).append(math.log(rate))
    xs = sorted(by_size)
    ys = [sum(by_size[x]) / len(by_size[x]) for x in xs]
    if n <= xs[0]:
        return math.exp(ys[0])
    if n >= xs[-1]:
        return math.exp(ys[-1])
    for (x0, y0), (x1, y1) in zip(zip(xs, ys), zip(xs[1:], ys[1:])):
        if x0 <= n <= x1:
            w = (math.log(n) - math.log(x0)) / (math.log(x1) - math.log(x0))
            return math.exp(y0 + w * (y1 - y0))
    return math.exp(ys[-1])  # not reached


def throughput(kind: str, method: str, n_units: int) -> tuple[float, float, str]:
    """(unit-steps per second, seconds per call, where they come from) of ``method`` on a ``kind``
    lattice of ``n_units`` (module docstring)."""
    from flexmm.integrators import INTEGRATORS

    rows = calibration()
    same = [r for r in rows if r["kind"] == kind]
    exact = [r for r in same if r["method"] == method]
    if exact:
        return (_interpolate([(r["n_units"], r["unit_steps_per_s"]) for r in exact], n_units),
                _interpolate([(r["n_units"], max(r["call_s"], 1e-9)) for r in exact], n_units),
                f"calibrated for {kind}, {method}")
    evals = INTEGRATORS[method].force_evals
    pool = [r for r in (same or rows) if r["method"] in INTEGRATORS]
    scaled = [(r["n_units"], r["unit_steps_per_s"] * INTEGRATORS[r["method"]].force_evals / evals) for r in pool]
    calls = [(r["n_units"], max(r["call_s"], 1e-9)) for r in pool]
    if same:
        return (_interpolate(scaled, n_units), _interpolate(calls, n_units),
                f"calibrated for {kind}, scaled to {method} by force evaluations")
    rates, per_call = sorted(rate for _, rate in scaled), sorted(c for _, c in calls)
    return (rates[len(rates) // 2], per_call[len(per_call) // 2],
            f"{kind} not calibrated: the table's median, scaled to {method}")


def _duration(seconds: float) -> str:
    for unit, size in (("days", 86400.0), ("h", 3600.0), ("min", 60.0)):
        if seconds >= 2 * size:
            return f"{seconds / size:.3g} {unit}"
    return f"{seconds:.2g} s"


def _frames(scene) -> int:
    """Frames saved (``frames.interval``; a request it refuses is counted as rounded up)."""
    from flexmm.frames import interval

    out = scene.output
    try:
        return interval(scene.solver.duration_s, out.n_frames, out.every_s)[1]
    except FlexmmError:
        return int(math.floor(scene.solver.duration_s / out.every_s + 1e-9)) + 2


def _step(scene) -> tuple[float | None, float | None, str | None]:
    """(dt in s, stable dt in s, note): the step the run will take, from the scene built (up to EXACT_SITES units)
    or from a small copy of its lattice; a dt above the stable limit raises UnstableStepError."""
    from flexmm.assemble import build_problem
    from flexmm.config.excitation import NoExcitation
    from flexmm.integrators import INTEGRATORS
    from flexmm.stability import UnstableStepError

    lat = scene.lattice
    spec = INTEGRATORS[scene.solver.integrator]
    adaptive = "adaptive method: steps counted at its stable limit" if spec.adaptive else None
    if lat.n_sites <= EXACT_SITES:
        problem = build_problem(scene)  # user errors (an unstable dt, ...) propagate
        ts = problem.system.scales.time_s
        return problem.dt * ts, problem.stable_dt * ts, adaptive
    small = lat.small_copy(PROBE_SITES)
    probe = scene.model_copy(update={"lattice": small})
    attempts = [(probe, f"step from a {small.n_sites}-unit copy of the lattice"),
                (probe.model_copy(update={"excitation": NoExcitation(kind="none"), "imperfection": None}),
                 f"step from a {small.n_sites}-unit copy of the lattice at rest")]
    last = "no step estimate"
    for sc, note in attempts:
        try:
            problem = build_problem(sc)
        except UnstableStepError:
            raise
        except (FlexmmError, ValueError, IndexError, KeyError) as exc:
            last = f"no step estimate ({exc})"
            continue
        ts = problem.system.scales.time_s
        return problem.dt * ts, problem.stable_dt * ts, "; ".join(n for n in (note, adaptive) if n)
    return scene.solver.dt_s, None, last


def estimate(scene, step: bool = True) -> Cost:
    """The estimated cost of running ``scene`` as configured (module docstring).

    ``step=False`` skips finding the step (steps unknown; ``check_steps`` checks them once the
    problem is built, so a run does not build its model twice).
    """
    lat, out = scene.lattice, scene.output
    n = lat.n_sites
    n_fields = len(type(lat).FIELD_NAMES)
    ndof = n * n_fields + (1 if getattr(scene.excitation, "striker", None) is not None else 0)
    frames = _frames(scene)
    saved = -(-n // out.site_stride)
    names = out.fields or type(lat).FIELD_NAMES
    site_vars = len(names) * (2 if out.velocities else 1)
    output = 8 * frames * (saved * site_vars + 8)
    memory = BASE_BYTES + BYTES_PER_DOF * ndof
    dt, stable, note = _step(scene) if step else (scene.solver.dt_s, None, None)
    rate, call_s, how = throughput(lat.kind, scene.solver.integrator, n)
    cost = Cost(n, ndof, frames, saved, output, memory, dt,
                None if dt is None else math.ceil(scene.solver.duration_s / dt - 1e-9), stable_dt_s=stable,
                rate=rate, call_s=call_s, rate_note=how)
    if note:
        cost.notes.append(note)
    return cost


def check(cost: Cost, out_dir: str | Path | None = None) -> list[str]:
    """What exceeds a limit (empty if nothing): memory, output size, free disk space, steps."""
    lim = limits()
    problems = []
    if cost.memory_bytes > lim["memory_gib"] * GIB:
        problems.append(f"needs ≈ {cost.memory_bytes / GIB:.3g} GiB of memory, above the limit of "
                        f"{lim['memory_gib']:.3g} GiB (FLEXMM_MAX_MEMORY_GIB)")
    if cost.output_bytes > lim["output_gib"] * GIB:
        problems.append(f"writes ≈ {cost.output_bytes / GIB:.3g} GiB, above the limit of {lim['output_gib']:.3g} GiB "
                        "(FLEXMM_MAX_OUTPUT_GIB; or save fewer frames/sites: output.n_frames, output.site_stride)")
    if out_dir is not None:
        probe = Path(out_dir).expanduser().absolute()
        while not probe.exists() and probe != probe.parent:
            probe = probe.parent
        try:
            free = shutil.disk_usage(probe).free
        except OSError:
            free = None
        if free is not None and cost.output_bytes > 0.95 * free:
            problems.append(f"writes ≈ {cost.output_bytes / GIB:.3g} GiB but {probe} has {free / GIB:.3g} GiB free")
    if cost.steps is not None and cost.steps > lim["steps"]:
        when = f" (≈ {_duration(cost.seconds)})" if math.isfinite(cost.seconds) else ""
        problems.append(f"takes {cost.steps:.3g} steps{when}, above the limit of "
                        f"{lim['steps']:.3g} (FLEXMM_MAX_STEPS; check solver.duration_s and solver.dt_s)")
    return problems


def check_steps(steps: float, dt_s: float, n_sites: int, force: bool = False) -> None:
    """ResourceError if ``steps`` exceeds FLEXMM_MAX_STEPS (unless ``force``)."""
    cost = Cost(n_sites, 0, 0, 0, 0, 0, dt_s, steps)
    problems = [] if force else check(cost)
    if problems:
        raise ResourceError("the run is too large: " + "; ".join(problems) + " (--force runs it anyway)")


def enforce(scene, out_dir: str | Path | None, force: bool = False, step: bool = True) -> Cost:
    """``estimate`` and ``check``; ResourceError listing what exceeds a limit unless ``force``."""
    cost = estimate(scene, step)
    problems = check(cost, out_dir)
    if problems and not force:
        raise ResourceError("the run is too large: " + "; ".join(problems) + " (--force runs it anyway)")
    return cost
