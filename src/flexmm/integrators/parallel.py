"""Threaded variants, fused kernels and the rule for when to use them.

Numba parallel loops pay only when a step has enough work to hide the fork/join of each
parallel region (a few µs): ``PARALLEL_MIN_SITES`` (≈ 1e5 units, benchmarks/) is where two
threads start to win on the chain. Below it, or for methods without a threaded variant,
everything runs on one thread.
"""

from __future__ import annotations

import os
from typing import Callable

import numba
import numpy as np

from flexmm.integrators.verlet_chain import chain_verlet_advance, chain_verlet_advance_parallel, fusable
from flexmm.models.hinge import ChainArgs

#: (integrator name, model args type) -> (serial, threaded) advance fused with that model's force
FUSED: dict[tuple[str, type], tuple[Callable, Callable]] = {
    ("velocity_verlet", ChainArgs): (chain_verlet_advance, chain_verlet_advance_parallel),
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


def advance_kernel(spec, args, minv: np.ndarray, damp: np.ndarray, terms, threads: int) -> tuple[Callable, int]:
    """(advance, threads actually used) of ``spec`` for a model with arguments ``args``.

    Uses the method's stepper fused with the model's force where ``FUSED`` has one and the
    scene allows it (``verlet_chain.fusable``: same results, less memory traffic); falls back
    to the serial kernel (and 1 thread) when the method has no threaded variant. Sets numba's
    thread count when threads > 1.
    """
    fused = FUSED.get((spec.name, type(args)))
    if fused is not None and not fusable(args, np.empty(minv.shape[0]), minv, damp, terms):
        fused = None
    if threads > 1 and spec.advance_parallel is not None:
        numba.set_num_threads(threads)
        return (fused[1] if fused else spec.advance_parallel), threads
    return (fused[0] if fused else spec.advance), 1
