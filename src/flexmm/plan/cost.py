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
"""

from __future__ import annotations

import math
import os
import shutil
from dataclasses import dataclass, field
from pathlib import Path

from flexmm import environment
from flexmm.errors import FlexmmError

PROBE_SITES = 256  # largest lattice built to find the step
EXACT_SITES = 4096  # up to this size the scene itself is built (exact step, strikers included)
BYTES_PER_DOF = 40 * 8
BASE_BYTES = 200 * 2**20
UNIT_STEPS_PER_S = 5e7  # a conservative single-thread rate for the time estimate (benchmarks/)
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

    @property
    def seconds(self) -> float | None:
        """Integration time at ``UNIT_STEPS_PER_S`` (an order of magnitude)."""
        return None if self.steps is None else self.steps * self.n_sites / UNIT_STEPS_PER_S

    def lines(self) -> list[str]:
        steps = ("steps unknown" if self.steps is None
                 else f"{self.steps:.3g} steps of {self.dt_s:.3g} s (≈ {_duration(self.seconds)} at "
                      f"{UNIT_STEPS_PER_S / 1e6:.0f} M unit-steps/s)")
        return [f"cost: {self.n_sites:,} units, {self.ndof:,} DOFs, {steps}; memory ≈ "
                f"{self.memory_bytes / GIB:.2g} GiB; output {self.frames:,} frames × {self.saved_sites:,} sites "
                f"≈ {self.output_bytes / GIB:.3g} GiB", *[f"cost: {n}" for n in self.notes]]


def _duration(seconds: float) -> str:
    for unit, size in (("days", 86400.0), ("h", 3600.0), ("min", 60.0)):
        if seconds >= 2 * size:
            return f"{seconds / size:.3g} {unit}"
    return f"{seconds:.2g} s"


def _frames(scene) -> int:
    out = scene.output
    if out.every_s:
        return int(math.floor(scene.solver.duration_s / out.every_s + 1e-9)) + 2
    return out.n_frames


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
    cost = Cost(n, ndof, frames, saved, output, memory, dt,
                None if dt is None else math.ceil(scene.solver.duration_s / dt - 1e-9), stable_dt_s=stable)
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
        problems.append(f"takes {cost.steps:.3g} steps (≈ {_duration(cost.seconds)}), above the limit of "
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
