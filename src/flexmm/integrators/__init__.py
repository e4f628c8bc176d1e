"""Integrator registry: each entry is data (order, symplectic, stability limit, ...) plus kernels.

Tests parametrise over ``INTEGRATORS`` (tests/integrators/) and measure each method's observed
order, energy behaviour and stability limit, so a new entry is checked automatically.

A new method must provide, as compiled functions:

1. ``advance(args, q, v, f, minv, damp, terms, t, h, nsteps, acc) -> t``: advance q, v (in
   place) from t to t + nsteps·h and return the new time. ``args`` is the model's NamedTuple:
   the model force is ``models.kernels.model_force(q, args, out)`` (dispatched on the type of
   ``args``, so the loop takes no function argument and numba caches it). ``terms`` is a
   ``common.Terms`` (contacts, dashpots, drives, friction — all must be honoured), ``minv`` the
   inverse masses (0: held DOF), ``damp`` the on-site viscous coefficients. ``acc`` (from
   ``new_acc``) accumulates the dissipated energy and the applied work in its named slots
   (``common.ACC_*``), counts force evaluations and steps and holds any method state.
2. ``init(args, q, v, t, f, terms)``: fill ``f`` with the total force at the start.
3. Metadata below; ``stability_limit`` is max h·ω_max on the harmonic oscillator
   (``stability.harmonic_limit`` recomputes it from the method), inf for A-stable methods.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from flexmm.integrators import composition, dopri5
from flexmm.integrators.common import (
    ACC_HEADER,
    Accumulators,
    total_force,
)
from flexmm.integrators.implicit import midpoint_advance
from flexmm.integrators.rk4 import rk4_advance
from flexmm.integrators.splitting import make_splitting_advance, pefrl_advance
from flexmm.integrators.verlet import verlet_advance, verlet_advance_parallel, verlet_force


@dataclass(frozen=True)
class IntegratorSpec:
    """Metadata and compiled kernels of one time-stepping method (see the module docstring)."""

    name: str
    order: int
    symplectic: bool  # without damping
    stability_limit: float  # max h·ω_max on the harmonic oscillator (inf: A-stable)
    velocity_dependent_forces: bool  # accepts damping, dashpots, friction without losing order
    advance: Callable
    init: Callable
    force_evals: float = 1.0  # model-force evaluations per (accepted) step, nominal
    adaptive: bool = False  # error-controlled step; h·nsteps is the output interval
    implicit: bool = False
    advance_parallel: Callable | None = None  # same scheme with threaded DOF passes
    state_size: Callable[[int], int] | None = None  # extra accumulator slots for ndof DOFs
    description: str = ""
    #: order in h of the work and dissipation it accumulates (the energy ledger): the trapezoid
    #: rule's 2 for the dissipation (a splitting's drive work is of its own order, ``splitting``)
    ledger_order: int = 2

    @property
    def explicit_limit(self) -> bool:
        """Whether dt is bounded by ``stability_limit``/ω_max (fixed-step explicit methods)."""
        return not self.adaptive and math.isfinite(self.stability_limit)

    def new_acc(self, ndof: int, *, rtol: float | None = None, atol: float | None = None,
                max_step: float | None = None) -> np.ndarray:
        """Accumulator with counters (and, for adaptive methods given ``rtol``, their state)."""
        if not self.adaptive or rtol is None:
            return np.zeros(ACC_HEADER)
        acc = np.zeros(ACC_HEADER + self.state_size(ndof))
        acc[dopri5.S_RTOL] = rtol
        acc[dopri5.S_ATOL] = rtol * 1e-2 if atol is None else atol
        acc[dopri5.S_MAX_STEP] = 0.0 if max_step is None else max_step
        return acc

    @staticmethod
    def counters(acc: np.ndarray) -> dict[str, int]:
        """Work done so far, from an accumulator made by ``new_acc``."""
        return Accumulators(acc).counters()


INTEGRATORS: dict[str, IntegratorSpec] = {
    "velocity_verlet": IntegratorSpec(
        name="velocity_verlet", order=2, symplectic=True, stability_limit=2.0,
        velocity_dependent_forces=True, advance=verlet_advance, init=verlet_force,
        force_evals=1.0, advance_parallel=verlet_advance_parallel,
        description="velocity Verlet, semi-implicit on-site damping (with solver.accuracy: null)",
    ),
    "pefrl": IntegratorSpec(
        name="pefrl", order=4, symplectic=True, stability_limit=2.9894,
        velocity_dependent_forces=True, advance=pefrl_advance, init=total_force,
        force_evals=4.0,
        description="4th-order symplectic splitting (Omelyan PEFRL), exact damped kicks (default)",
    ),
    "blanes_moan6": IntegratorSpec(
        name="blanes_moan6", order=6, symplectic=True, stability_limit=3.141436,
        velocity_dependent_forces=False, advance=make_splitting_advance(*composition.blanes_moan_6()),
        init=total_force, force_evals=11.0,
        description="6th-order symplectic RKN splitting (Blanes & Moan 2002, SRKN11b), forces of q only",
    ),
    "rk4": IntegratorSpec(
        name="rk4", order=4, symplectic=False, stability_limit=2.0 * math.sqrt(2.0),
        velocity_dependent_forces=True, advance=rk4_advance, init=total_force, force_evals=4.0,
        description="classical Runge-Kutta 4",
    ),
    "dopri5": IntegratorSpec(
        name="dopri5", order=5, symplectic=False, stability_limit=0.9972,
        velocity_dependent_forces=True, advance=dopri5.dopri5_advance, init=total_force,
        force_evals=6.0, adaptive=True, state_size=dopri5.state_size,
        description="Dormand-Prince 5(4), adaptive, dense output (accuracy reference)",
    ),
    "implicit_midpoint": IntegratorSpec(
        name="implicit_midpoint", order=2, symplectic=True, stability_limit=math.inf,
        velocity_dependent_forces=True, advance=midpoint_advance, init=total_force,
        force_evals=math.nan, implicit=True,
        description="implicit midpoint, Newton-Krylov (matrix-free), A-stable for stiff scenes",
    ),
}

__all__ = ["INTEGRATORS", "IntegratorSpec"]
