"""Integrator registry: each entry is data (order, symplectic, stability limit) plus kernels.

Tests parametrise over ``INTEGRATORS`` and measure each method's observed order.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from flexmm.integrators.verlet import verlet_advance, verlet_force


@dataclass(frozen=True)
class IntegratorSpec:
    """Metadata and compiled kernels of one time-stepping method.

    ``advance(force, args, q, v, f, minv, damp, terms, t, h, nsteps, acc) -> t`` runs many
    steps; ``init(force, args, q, v, t, f, terms)`` fills the starting force.
    """

    name: str
    order: int
    symplectic: bool
    stability_limit: float  # max h·ω_max on the harmonic oscillator
    velocity_dependent_forces: bool
    advance: Callable
    init: Callable
    description: str = ""


INTEGRATORS: dict[str, IntegratorSpec] = {
    "velocity_verlet": IntegratorSpec(
        name="velocity_verlet",
        order=2,
        symplectic=True,
        stability_limit=2.0,
        velocity_dependent_forces=True,
        advance=verlet_advance,
        init=verlet_force,
        description="velocity Verlet, semi-implicit on-site damping (default)",
    ),
}

__all__ = ["INTEGRATORS", "IntegratorSpec"]
