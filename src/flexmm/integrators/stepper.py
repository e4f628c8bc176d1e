"""The one object that advances a built problem in time: ``Stepper``, made by ``make_stepper``.

A Stepper owns the state (q, v, the total force f, t, the accumulator), picks the compiled
``advance`` for the method, the model's argument type and the thread count
(``parallel.advance_kernel``), compiles it on copies before the clock starts (``warm_up``),
counts work (``ledger``), and checks every frame for a blow-up (non-finite state, or runaway
energy: ``runaway.RunawayGuard``). ``run(chunks, on_frame)`` is flexmm's only time loop: the
controller (frames to a dataset), the in-memory runner, the accuracy and formation pilots, the
benchmarks and the tests all call it, and observers see the stepper at each frame.

    stepper = make_stepper(problem, h=problem.dt)
    outcome = stepper.run([100] * 10, on_frame=lambda s: print(s.t, s.energies()))
"""

from __future__ import annotations

import math
import signal
import time
from dataclasses import dataclass
from typing import Callable, Iterable

import numpy as np

from flexmm._signals import deferred, signal_of
from flexmm.integrators import INTEGRATORS, IntegratorSpec
from flexmm.integrators.common import Accumulators, Terms, apply_prescribed, contact_energy
from flexmm.integrators.parallel import advance_kernel, choose_threads, keep_tables
from flexmm.integrators.runaway import DRIFT_TOL, RunawayGuard, drift_allowance
from flexmm.models.kernels import model_energy

#: relative tolerance of adaptive integrators when none is given
DEFAULT_RTOL = 1e-6
#: unit-steps per compiled call of a stepper with ``bounded_calls`` (0.02–0.5 s on one core)
CALL_WORK = 4e6
#: ... but at least this many steps (a lattice of more than CALL_WORK / MIN_CALL_STEPS sites):
#: the fused chain kernel is blocked in time (32 steps per sweep of memory), and calls of a step
#: or two ran it at 40 % of its speed on 10⁷ units; a call then takes ~1 s there
MIN_CALL_STEPS = 64


@dataclass(frozen=True)
class Outcome:
    """How a ``Stepper.run`` ended: ``status`` ('finished', 'failed', 'interrupted'), ``reason``
    ('non-finite state', 'runaway energy', ...), and ``t_good``, the last time whose state
    passed the checks (nondimensional; the stepper's own ``t`` is where it stopped)."""

    status: str
    reason: str
    t_good: float

    @property
    def ok(self) -> bool:
        return self.status == "finished"


#: bytes the state arrays are aligned to (a cache line: vector loads do not straddle two)
ALIGN = 64


def _aligned(x) -> np.ndarray:
    """A float64 copy of x whose data start on an ``ALIGN``-byte boundary. numpy aligns to 16 bytes
    only; the fused chain kernel measured 3–6 % slower at 10⁵ units on state arrays 8 or 16 bytes
    off a cache line (more at 10⁶), and by how much depended on where each array happened to
    land, so steppers running the same kernel differed."""
    x = np.asarray(x, float)
    buf = np.empty(x.size + ALIGN // 8)
    k = (-buf.ctypes.data % ALIGN) // 8
    out = buf[k : k + x.size].reshape(x.shape)
    out[...] = x
    return out


class Stepper:
    """State and compiled kernel of one (problem, integrator, step) — see the module docstring.

    Attributes: ``q``, ``v`` (ndof,) the state, ``f`` (ndof,) the total force, ``t`` the time,
    ``h`` the step (the frame interval for an adaptive method, which picks its own steps),
    ``acc`` the accumulator and ``ledger`` its named view, ``kernel`` the compiled advance and
    ``threads`` it uses, ``compile_s``,
    ``wall_s`` and ``cpu_s`` spent advancing (compile excluded).
    """

    def __init__(self, spec: IntegratorSpec, system, terms: Terms, damp: np.ndarray, h: float, *,
                 threads: int = 1, q0: np.ndarray | None = None, v0: np.ndarray | None = None,
                 t0: float = 0.0, rtol: float | None = None, atol: float | None = None,
                 max_step: float | None = None, check_energy: bool = True, drift_tol: float = DRIFT_TOL):
        self.spec, self.system, self.terms, self.damp = spec, system, terms, damp
        self.args = system.args
        self.h = float(h)
        self.adaptive = spec.adaptive and rtol is not None
        self.acc = spec.new_acc(system.ndof, rtol=rtol, atol=atol, max_step=max_step)
        self.ledger = Accumulators(self.acc)
        kernel, self.threads = advance_kernel(spec, system.args, system.inv_mass, damp, terms, threads)
        self.kernel = keep_tables(kernel)  # a fused kernel's tables are built once, not per call
        self.q = _aligned(system.q0 if q0 is None else q0)
        self.v = _aligned(system.v0 if v0 is None else v0)
        self.f = _aligned(np.zeros_like(self.q))
        self.t = float(t0)
        self.check_energy = check_energy
        self.compile_s = self.wall_s = self.cpu_s = 0.0
        self._warm = False
        self.max_call_steps: int | None = None  # None: one compiled call per chunk (``bounded_calls``)
        apply_prescribed(self.q, self.v, self.t, *terms.drives)
        spec.init(self.args, self.q, self.v, self.t, self.f, terms)
        self._held_mass = np.where(system.inv_mass > 0, 0.0, system.mass)
        self._held = bool(self._held_mass.any())
        self.last_energies: tuple[float, float] | None = self.energies()  # of the last checked state
        self.guard = RunawayGuard(system, terms, sum(self.last_energies), drift_tol)

    # -- one call into compiled code -------------------------------------------------------
    def warm_up(self) -> float:
        """Compile (or load from numba's cache) the advance kernel on copies; returns seconds."""
        if not self._warm:
            t0 = time.perf_counter()
            self._call(self.q.copy(), self.v.copy(), self.f.copy(), 1, self.acc.copy())
            self.compile_s = time.perf_counter() - t0
            self._warm = True
        return self.compile_s

    def _call(self, q, v, f, nsteps: int, acc) -> float:
        return self.kernel(self.args, q, v, f, self.system.inv_mass, self.damp, self.terms, self.t, self.h, nsteps,
                           acc)

    def advance(self, nsteps: int) -> None:
        """Advance ``nsteps`` steps of size h (adaptive: to t + nsteps·h) in place, in calls of at
        most ``max_call_steps`` steps when that is set (a fixed-step method only)."""
        self.warm_up()
        w0, c0 = time.perf_counter(), time.process_time()
        left = int(nsteps)
        cap = self.max_call_steps if self.max_call_steps and not self.adaptive else max(left, 1)
        while True:
            k = min(cap, left)
            with deferred():  # a signal waits for the call: q, v, f, acc and t change together
                self.t = self._call(self.q, self.v, self.f, k, self.acc)
            left -= k
            if left <= 0:
                break
        self.wall_s += time.perf_counter() - w0
        self.cpu_s += time.process_time() - c0

    def bounded_calls(self, work: float = CALL_WORK, min_steps: int = MIN_CALL_STEPS) -> Stepper:
        """Compiled calls of at most ``work`` unit-steps from here on (``max_call_steps``), so the
        stepper comes back to Python — where a signal is acted on — every fraction of a second
        whatever the chunks asked of ``run``. Sized by work, not by wall time: a run's result must
        not depend on the machine's load (a call boundary rounds differently from a step inside a
        call: the fused closing and opening half kicks), and at least ``min_steps`` steps (a kernel
        blocked in time runs at its speed only on long calls). Returns the stepper."""
        self.max_call_steps = max(min_steps, 1, int(work // max(self.system.n_sites, 1)))
        return self

    # -- checkpoints -----------------------------------------------------------------------------
    def snapshot(self) -> tuple[dict[str, np.ndarray], dict]:
        """(arrays, scalars) from which ``restore`` continues this stepper bit for bit: the state
        q, v, the total force f (a fused or FSAL method's opening kick uses it), the accumulator
        (ledger, counters, an adaptive or implicit method's state slots), t, h, the time spent
        and the runaway guard's references. Taken between compiled calls (``run`` lets a signal
        in only there), where nothing else carries over from one call to the next."""
        arrays = {"q": self.q, "v": self.v, "f": self.f, "acc": self.acc}
        scalars = {"t": self.t, "h": self.h, "wall_s": self.wall_s, "cpu_s": self.cpu_s,
                   "guard": self.guard.state()}
        return arrays, scalars

    def restore(self, arrays: dict[str, np.ndarray], scalars: dict) -> None:
        """Continue from a ``snapshot`` of a stepper of the same problem, method and step."""
        for name in ("q", "v", "f", "acc"):
            mine = getattr(self, name)
            if arrays[name].shape != mine.shape:
                raise ValueError(f"{name} has shape {arrays[name].shape}, not {mine.shape}")
            mine[...] = arrays[name]
        self.t, self.h = float(scalars["t"]), float(scalars["h"])
        self.wall_s, self.cpu_s = float(scalars["wall_s"]), float(scalars["cpu_s"])
        self.guard.restore(scalars["guard"])
        self.last_energies = None

    # -- observations ------------------------------------------------------------------------
    @property
    def steps(self) -> int:
        """Steps taken so far (accepted steps of an adaptive method)."""
        return self.ledger.steps

    def energies(self) -> tuple[float, float]:
        """(kinetic, potential + contact) energy of the current state (nondimensional).

        The kinetic energy is that of the DOFs that move freely: a prescribed DOF's imposed motion
        is not the system's energy (its work on the rest is in ``ledger.work``; docs/physics.md §3)."""
        s, terms = self.system, self.terms
        pot = model_energy(self.q, self.args) + contact_energy(self.q, terms.con_ij, terms.con_prm)
        kin = s.kinetic_energy(self.v)
        if self._held:
            kin -= 0.5 * float(np.dot(self._held_mass, self.v * self.v))
        return kin, float(pot)

    def failure(self) -> str | None:
        """Why the current state is not trustworthy (non-finite, runaway energy), or None."""
        if not (np.isfinite(self.q).all() and np.isfinite(self.v).all()):
            return "non-finite state"
        self.last_energies = None
        if self.check_energy:
            self.last_energies = self.energies()
            e = sum(self.last_energies)
            if self.guard.runaway(e, self.ledger.work):
                return "runaway energy"
            why = self.guard.unbalanced(e, self.ledger.work, self.ledger.dissipated, self.steps)
            if why is not None:
                return why
            self.guard.record(self.steps, e)
        return None

    # -- the time loop ---------------------------------------------------------------------
    def run(self, chunks: Iterable[int], on_frame: Callable[[Stepper], bool | None] | None = None, *,
            reraise: bool = False) -> Outcome:
        """Advance chunk after chunk of steps; after each, check the state and call ``on_frame``.

        Stops at the first failed check ('failed', the state is then past ``t_good``), on
        Ctrl-C or SIGTERM ('interrupted', reason 'SIGINT'/'SIGTERM'), or when ``on_frame``
        returns True (an observer that has seen enough, 'finished'). ``reraise``: a Ctrl-C or
        SIGTERM propagates instead (a pilot, whose partial result is worth nothing: a caller
        that went on with it would choose from a truncated measurement).
        """
        if reraise:
            return self._run(chunks, on_frame)
        try:
            return self._run(chunks, on_frame)
        except KeyboardInterrupt as exc:  # Ctrl-C, or SIGTERM under _signals.stop_on_signals
            return Outcome("interrupted", signal.Signals(signal_of(exc)).name, self._t_good)

    def _run(self, chunks, on_frame) -> Outcome:
        self._t_good = self.t
        for nsteps in chunks:
            if self.max_call_steps:  # bounded calls: a signal stops the chunk between two of them
                self.advance(nsteps)
            # else the chunk's one call, its checks and observers run whole: a signal stops the run
            # at a frame, which a checkpoint continues from (it waits for the compiled call anyway)
            with deferred():
                if not self.max_call_steps:
                    self.advance(nsteps)
                why = self.failure()
                if why is not None:
                    return Outcome("failed", why, self._t_good)
                self._t_good = self.t
                if on_frame is not None and on_frame(self):
                    break
        return Outcome("finished", "", self._t_good)


def frame_chunks(t_end: float, h: float, n_frames: int) -> tuple[float, list[int]]:
    """(h', steps per frame): whole steps h' ≤ h between n_frames − 1 uniform frame intervals."""
    interval = t_end / max(n_frames - 1, 1)
    per = max(1, math.ceil(interval / h - 1e-9))
    return interval / per, [per] * max(n_frames - 1, 1)


def make_stepper(problem, integrator: str | IntegratorSpec | None = None, *, h: float | None = None,
                 rtol: float | None = None, atol: float | None = None, max_step: float | None = None,
                 threads: int | None = None, q0: np.ndarray | None = None, v0: np.ndarray | None = None,
                 check_energy: bool = True, warm: bool = True, drift_tol: float | None = None) -> Stepper:
    """The Stepper of a built problem (``assemble.Problem``).

    ``integrator`` defaults to the scene's; ``h`` to the problem's dt (for an adaptive method
    with ``rtol``, h is the interval between calls); ``threads`` None chooses by size
    (``parallel.choose_threads``). ``warm`` compiles before returning, so timings exclude it.
    ``drift_tol`` the energy-ledger tolerance (default ``runaway.drift_allowance``; inf: off).
    """
    spec = (INTEGRATORS[problem.scene.solver.integrator] if integrator is None
            else INTEGRATORS[integrator] if isinstance(integrator, str) else integrator)
    s = problem.system
    stepper = Stepper(spec, s, problem.terms, problem.damp, problem.dt if h is None else h,
                      threads=choose_threads(s.n_sites, threads), q0=q0, v0=v0, rtol=rtol,
                      atol=atol, max_step=max_step, check_energy=check_energy,
                      drift_tol=drift_allowance(spec, problem.dt if h is None else h, problem.omega_max)
                      if drift_tol is None else drift_tol)
    if warm:
        stepper.warm_up()
    return stepper
