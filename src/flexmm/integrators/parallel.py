"""Threaded variants, fused kernels and the rule for when to use them.

Numba parallel loops pay only when a step has enough work to hide the fork/join of each
parallel region (a few µs): ``PARALLEL_MIN_SITES`` (≈ 1e5 units, benchmarks/) is where two
threads start to win on the chain. Below it, or for methods without a threaded variant,
everything runs on one thread.

On a shared machine three rules keep threads from hurting (``python benchmarks/run.py
contention`` measures one thread against two beside a busy-loop process; README):

- Idle threads sleep instead of spinning: ``OMP_WAIT_POLICY=PASSIVE`` unless the user set it
  (read once, when numba starts its OpenMP threads, so it is set on import here). A spinning
  thread that has finished its share holds a core that the thread still working needs when
  another process has the other core. Cost: a wake-up per parallel region, negligible for the
  fused chain kernel (one region per ``verlet_chain.TIME_BLOCK`` steps).
- The automatic choice counts the cores of this process's affinity set that are actually free
  (``free_cpus``: /proc/stat over 20 ms; the 1-minute load average where that cannot be read),
  so a run started beside a busy process uses one thread.
- The fused chain kernel gives the same bits on any number of threads, so its threaded advance
  (``AdaptiveThreads``) re-measures between calls how many CPUs other processes keep busy
  (``BusyMeter``, no sleeping) and runs on one thread as soon as they hold the cores the
  threads need, back on two only once they have been free for a while; otherwise on whichever
  thread count has been faster lately.
"""

from __future__ import annotations

import os
import time
from collections import deque
from collections.abc import Callable

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # before numba loads its OpenMP layer

import numba
import numpy as np

from flexmm.integrators.verlet import (sheet_fusable, sheet_prepare, sheet_verlet_advance,
                                      sheet_verlet_advance_prepared)
from flexmm.integrators.verlet_chain import (chain_verlet_advance, chain_verlet_advance_parallel,
                                             chain_verlet_advance_parallel_prepared, chain_verlet_advance_prepared,
                                             fusable, prepare)
from flexmm.models.hinge import ChainArgs
from flexmm.models.sheet_kernels import SheetArgs

#: (integrator name, model args type) -> (serial, threaded or None, applies) advance fused with
#: that model's force, and the test whether a scene allows it
FUSED: dict[tuple[str, type], tuple[Callable, Callable | None, Callable]] = {
    ("velocity_verlet", ChainArgs): (chain_verlet_advance, chain_verlet_advance_parallel, fusable),
    ("velocity_verlet", SheetArgs): (sheet_verlet_advance, None, sheet_fusable),
}
#: fused advance -> (its tables of (args, minv, damp, h), the same advance taking them first):
#: a ``Stepper`` builds the tables once, not on every call (``keep_tables``)
PREPARED: dict[Callable, tuple[Callable, Callable]] = {
    chain_verlet_advance: (prepare, chain_verlet_advance_prepared),
    chain_verlet_advance_parallel: (prepare, chain_verlet_advance_parallel_prepared),
    sheet_verlet_advance: (sheet_prepare, sheet_verlet_advance_prepared),
}
PARALLEL_MIN_SITES = 100_000
#: a CPU busier than this over the sampling window (other processes) is not counted as free
BUSY_FRACTION = 0.5
#: sampling window of ``free_cpus``
FREE_WINDOW_S = 0.02


def _cpus() -> list[int]:
    try:
        return sorted(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return list(range(os.cpu_count() or 1))


def available_threads() -> int:
    """Threads numba may use (NUMBA_NUM_THREADS, capped by the CPUs this process may run on)."""
    return max(1, min(numba.config.NUMBA_NUM_THREADS, len(_cpus())))


def _cpu_times() -> dict[int, tuple[int, int]] | None:
    """Per CPU (busy, total) jiffies from /proc/stat, or None where it cannot be read."""
    try:
        with open("/proc/stat") as fh:
            out = {}
            for line in fh:
                if line.startswith("cpu") and line[3:4].isdigit():
                    name, *vals = line.split()
                    v = [int(x) for x in vals[:8]]
                    idle = v[3] + v[4]  # idle + iowait
                    out[int(name[3:])] = (sum(v) - idle, sum(v))
            return out
    except (OSError, ValueError):
        return None


def free_cpus(window_s: float = FREE_WINDOW_S) -> int:
    """CPUs of this process's affinity set that other work left free over the last ``window_s``.

    This process sleeps while it samples, so its own CPU counts as free. Falls back to the
    CPUs less the 1-minute load average where /proc/stat is not available.
    """
    cpus = _cpus()
    a = _cpu_times()
    if a is None:
        return max(1, len(cpus) - round(os.getloadavg()[0]))
    time.sleep(window_s)
    b = _cpu_times() or a
    free = 0
    for c in cpus:
        if c in a and c in b:
            total = b[c][1] - a[c][1]
            free += total <= 0 or (b[c][0] - a[c][0]) / total < BUSY_FRACTION
    return max(1, free)


def choose_threads(n_sites: int, requested: int | None = None) -> int:
    """``requested`` if given (capped by ``available_threads``); else, for ≥ PARALLEL_MIN_SITES
    units, the available threads on CPUs that are actually free (``free_cpus``), else 1."""
    if requested is not None:
        return max(1, min(requested, available_threads()))
    if n_sites < PARALLEL_MIN_SITES or available_threads() == 1:
        return 1
    return max(1, min(available_threads(), free_cpus()))


class BusyMeter:
    """CPUs that other processes kept busy, measured between calls without sleeping: over a
    window of at least ``WINDOW_S``, all the CPUs' busy time (/proc/stat) less this process's
    own CPU time, over the wall time. ``sample()`` returns the latest window's figure (None
    until a window has passed or where /proc/stat cannot be read). /proc/stat counts in ticks
    (10 ms at 100 Hz), so a window of 0.2 s reads to about ±0.1 CPU."""

    WINDOW_S = 0.2

    def __init__(self):
        self.hz = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100
        self.cpus = set(_cpus())
        self._start = self._now()
        self.busy: float | None = None
        self.windows = 0  # windows measured so far

    def _now(self):
        times = _cpu_times()
        if times is None:
            return None
        jiffies = sum(b for c, (b, _) in times.items() if c in self.cpus)
        return time.perf_counter(), time.process_time(), jiffies

    def sample(self) -> float | None:
        """Others' busy CPUs over the last complete window (updated when one has passed)."""
        if self._start is None:
            return None
        wall = time.perf_counter() - self._start[0]
        if wall >= self.WINDOW_S:
            now = self._now()
            if now is None:
                return self.busy
            w0, c0, j0 = self._start
            own = now[1] - c0
            self.busy = max(0.0, ((now[2] - j0) / self.hz - own) / max(now[0] - w0, 1e-9))
            self._start = now
            self.windows += 1
        return self.busy


class AdaptiveThreads:
    """A threaded advance whose results do not depend on the thread count (the fused chain
    kernel): each call runs the threaded kernel on ``threads`` threads or the serial one.

    The choice, before each call:

    - Cores taken by other processes (``BusyMeter``: re-measured over every window of
      ``BusyMeter.WINDOW_S`` or more, between calls): when they leave fewer than ``threads``
      cores free (others busier than ``cpus − threads + BUSY_MARGIN`` CPUs), the call runs on
      one thread at once — two threads on cores another process holds only wait for each
      other at their barriers. Back to ``threads`` only after ``QUIET_CHECKS`` windows in a row
      without that (switch down fast, up slowly).
    - Otherwise, calls of at least ``MIN_TIMED_STEPS`` steps and ``MIN_TIMED_S`` seconds are
      timed (steps per second, by thread count, the last ``WINDOW``; not the one-step compile
      warm-up): the first two go to the threads, the next to one thread, then each call uses the
      faster median, and every ``EXPLORE``-th timed call the other count.

    Same signature and results as the kernel (plus ``tables``: the fused kernels' prepared
    tables, ``PREPARED``); ``counts`` tallies the calls by thread count.
    """

    MIN_TIMED_S = 2e-3
    MIN_TIMED_STEPS = 8
    WINDOW = 5
    EXPLORE = 8
    BUSY_MARGIN = 0.3
    QUIET_CHECKS = 4

    def __init__(self, serial: Callable, kernel: Callable, threads: int):
        self.serial, self.kernel, self.threads = serial, kernel, threads
        self.cpus = len(_cpus())
        self.__name__ = getattr(kernel, "__name__", "advance")
        self.rates: dict[int, deque] = {1: deque(maxlen=self.WINDOW), threads: deque(maxlen=self.WINDOW)}
        self.counts = {1: 0, threads: 0}
        self.meter = BusyMeter()
        self.crowded = False  # other processes hold the cores the threads would need
        self._quiet = 0
        self._seen = 0  # the meter's windows already acted on
        self._timed = 0
        self._compiled: set = set()

    def _crowded(self) -> bool:
        """Whether other processes hold the cores (down at once, up after QUIET_CHECKS windows)."""
        busy = self.meter.sample()
        if busy is None or self.meter.windows == self._seen:  # no new window since the last call
            return self.crowded
        self._seen = self.meter.windows
        if busy > self.cpus - self.threads + self.BUSY_MARGIN:
            self.crowded, self._quiet = True, 0
        elif self.crowded:
            self._quiet += 1
            self.crowded = self._quiet < self.QUIET_CHECKS
        return self.crowded

    def choice(self) -> int:
        """The thread count for the next call."""
        if self._crowded():
            return 1
        many, one = self.rates[self.threads], self.rates[1]
        if len(many) < 2:
            return self.threads
        if not one:
            return 1
        best = self.threads if float(np.median(many)) >= float(np.median(one)) else 1
        if self._timed % self.EXPLORE == self.EXPLORE - 1:
            return 1 if best == self.threads else self.threads
        return best

    def _kernels(self, tables) -> tuple[Callable, Callable]:
        if tables is None:
            return self.serial, self.kernel
        return PREPARED[self.serial][1], PREPARED[self.kernel][1]

    def __call__(self, args, q, v, f, minv, damp, terms, t, h, nsteps, acc, tables=None):
        serial, kernel = self._kernels(tables)
        call = (args, q, v, f, minv, damp, terms, t, h, nsteps, acc)
        if tables is not None:
            call = (tables, *call)
        if (tables is None) not in self._compiled:  # both kernels on the first call (the stepper's warm-up)
            for kern in (serial, kernel):
                if hasattr(kern, "compile"):
                    kern.compile(tuple(numba.typeof(a) for a in call))
            self._compiled.add(tables is None)
        k = self.choice()
        t0 = time.perf_counter()
        if k == 1:
            t = serial(*call)
        else:
            numba.set_num_threads(k)
            t = kernel(*call)
        wall = time.perf_counter() - t0
        self.counts[k] += 1
        if wall >= self.MIN_TIMED_S and nsteps >= self.MIN_TIMED_STEPS:
            self.rates[k].append(nsteps / wall)
            self._timed += 1
        return t

    def __getattr__(self, name):  # the kernel's own attributes (numba's ``stats``, ...)
        return getattr(self.kernel, name)


class KeptTables:
    """An advance (same signature) whose fused kernel's tables (``PREPARED``: they depend on the
    parameters, masses, damping and h only) are built on the first call and again only when h
    or one of those arrays is replaced (arrays changed in place are not seen: build a new
    stepper). ``tables`` the current ones; other attributes (``__name__``, numba's ``stats``,
    ``AdaptiveThreads.counts``) are those of the kernel that runs, but the name, the fused
    kernel's."""

    def __init__(self, prepare: Callable, advance: Callable, target, name: str):
        self._prepare, self._advance, self.target = prepare, advance, target
        self.__name__ = name
        self.tables: tuple | None = None
        self._of: tuple = ()

    def __call__(self, args, q, v, f, minv, damp, terms, t, h, nsteps, acc):
        if (self.tables is None or h != self._of[0]
                or any(a is not b for a, b in zip((args, minv, damp), self._of[1:]))):
            self.tables = self._prepare(args, minv, damp, h)
            self._of = (h, args, minv, damp)
        return self._advance(self.tables, args, q, v, f, minv, damp, terms, t, h, nsteps, acc)

    def __getattr__(self, name):
        return getattr(self.target, name)


def keep_tables(kernel: Callable) -> Callable:
    """``kernel`` as a ``KeptTables`` where it is a fused advance with prepared tables
    (``PREPARED``, or ``AdaptiveThreads`` over two such kernels), else ``kernel`` itself."""
    if isinstance(kernel, AdaptiveThreads):
        if kernel.serial in PREPARED and kernel.kernel in PREPARED:
            return KeptTables(PREPARED[kernel.serial][0], lambda tables, *call: kernel(*call, tables=tables), kernel,
                              kernel.__name__)
        return kernel
    try:
        entry = PREPARED.get(kernel)
    except TypeError:  # not hashable
        return kernel
    return kernel if entry is None else KeptTables(entry[0], entry[1], entry[1], kernel.__name__)


def advance_kernel(spec, args, minv: np.ndarray, damp: np.ndarray, terms, threads: int) -> tuple[Callable, int]:
    """(advance, threads actually used) of ``spec`` for a model with arguments ``args``.

    Uses the method's stepper fused with the model's force where ``FUSED`` has one and the
    scene allows it (``verlet_chain.fusable``, ``verlet.sheet_fusable``: same results, less
    memory traffic), threaded through ``AdaptiveThreads`` where the fused kernel has a threaded
    variant (else on one thread); falls back to the serial kernel (and 1 thread) when the
    method has no threaded variant. Sets numba's thread count when threads > 1.
    """
    fused = FUSED.get((spec.name, type(args)))
    if fused is not None and not fused[2](args, np.empty(minv.shape[0]), minv, damp, terms):
        fused = None
    if fused is not None:
        if threads > 1 and fused[1] is not None:
            numba.set_num_threads(threads)
            return AdaptiveThreads(fused[0], fused[1], threads), threads
        return fused[0], 1
    if threads > 1 and spec.advance_parallel is not None:
        numba.set_num_threads(threads)
        return spec.advance_parallel, threads
    return spec.advance, 1
