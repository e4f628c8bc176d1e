"""Independent harmonic oscillators x_k'' = −k_k x_k (unit masses): the integrators' test model.

Each method's one-step map on it gives the method's linear stability limit (``stability``);
its exact solution gives order tests.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from flexmm._jit import jit


class HarmonicArgs(NamedTuple):
    """``stiffness`` (n,): k_k of each oscillator (ω_k² with unit masses)."""

    stiffness: np.ndarray


@jit
def harmonic_force(q, args, out):
    """F_k = −k_k q_k."""
    k = args.stiffness
    for i in range(q.shape[0]):
        out[i] = -k[i] * q[i]


@jit
def harmonic_energy(q, args):
    """E = Σ k_k q_k² / 2."""
    k = args.stiffness
    e = 0.0
    for i in range(q.shape[0]):
        e += 0.5 * k[i] * q[i] * q[i]
    return e


def harmonic_reference(q: np.ndarray, args: HarmonicArgs) -> tuple[float, np.ndarray]:
    """Numpy oracle: (E, F)."""
    return float(0.5 * np.sum(args.stiffness * q * q)), -args.stiffness * q
