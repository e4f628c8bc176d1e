"""Threaded variants and the rule for when to use them.

Numba parallel loops pay only when a step has enough work to hide the fork/join of each
parallel region (a few µs): ``PARALLEL_MIN_SITES`` (≈ 1e5 units, benchmarks/) is where two
threads start to win on the chain. Below it, or for models without a threaded force kernel,
everything runs on one thread.
"""

from __future__ import annotations

import os
from typing import Callable

import numba

from flexmm.integrators.verlet import verlet_advance
from flexmm.integrators.verlet_chain import chain_verlet_advance, chain_verlet_advance_parallel
from flexmm.models.hinge import chain_force, chain_force_parallel

#: serial force kernel -> the same kernel with threaded site loops
PARALLEL_FORCES: dict[Callable, Callable] = {chain_force: chain_force_parallel}
#: (advance, serial force kernel) -> (serial, threaded) advance fused with that force
FUSED: dict[tuple[Callable, Callable], tuple[Callable, Callable]] = {
    (verlet_advance, chain_force): (chain_verlet_advance, chain_verlet_advance_parallel),
}
PARALLEL_MIN_SITES = 100_000


def available_threads() -> int:
    """Threads numba may use (NUMBA_NUM_THREADS, capped by the CPUs this process may run on)."""
    try:
        cpus = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        cpus = os.cpu_count() or 1
    return max(1, min(numba.config.NUMBA_NUM_THREADS, cpus))


def choose_threads(n_sites: int, requested: int | None = None) -> int:
    """``requested`` if given, else all available threads for ≥ PARALLEL_MIN_SITES units, else 1."""
    if requested is not None:
        return max(1, min(requested, available_threads()))
    return available_threads() if n_sites >= PARALLEL_MIN_SITES else 1


def kernels(spec, force: Callable, threads: int) -> tuple[Callable, Callable, int]:
    """(advance, force, threads actually used) for ``threads`` requested threads.

    Falls back to the serial kernels (and 1 thread) when the method or the model has no
    threaded variant; uses the method's stepper fused with the model's force where ``FUSED``
    has one (same results, less memory traffic). Sets numba's thread count when threads > 1.
    """
    par_force = PARALLEL_FORCES.get(force)
    fused = FUSED.get((spec.advance, force))
    if threads > 1 and spec.advance_parallel is not None and par_force is not None:
        numba.set_num_threads(threads)
        return (fused[1] if fused else spec.advance_parallel), par_force, threads
    return (fused[0] if fused else spec.advance), force, 1
