"""The blow-up test every integration loop applies at its frames (controller and runner alike).

A run is a runaway when its energy exceeds ``RUNAWAY_FACTOR`` × a reference: the largest of

- the largest |E| seen at frames at least ``RUNAWAY_LAG_STEPS`` steps old (an unstable mode grows
  by ≥ 1.5 per step, so it cannot raise its own threshold when frames are frequent);
- the drive scale: initial kinetic energy plus (sum of drive amplitudes)² × units — a run that
  starts at rest and is driven has no other energy scale at its first frames — plus the work
  recorded so far.

Its energy ledger does not balance when |E − E0 − W + D| exceeds ``drift_allowance`` of the
budget |E0| + |W| + D (W the work of drives, prescribed displacements included, accumulated by
the integrators; D the dissipated energy) at ``PERSIST_CHECKS`` consecutive checks spanning at
least ``RUNAWAY_LAG_STEPS`` steps (``RunawayGuard.unbalanced``): a drive's first steps give O(1)
relative imbalances on a tiny budget, which a resolved run outgrows within that many steps.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

RUNAWAY_FACTOR = 1e4
RUNAWAY_LAG_STEPS = 100
PERSIST_CHECKS = 3  # an imbalance fails a run once it lasts this many checks and RUNAWAY_LAG_STEPS steps
DRIFT_TOL = 0.05
#: the ledger's error is at most this × (h ω_max / limit)^ledger_order of the budget (the
#: dissipation's trapezoid rule; the drives' work is of each method's own order)
LEDGER_CONSTANT = 2.0  # largest ledger imbalance, as a fraction of the energy budget


def drift_allowance(spec, h: float, omega_max: float) -> float:
    """Largest ledger imbalance a run of ``spec`` at step h allows (module docstring)."""
    lim = getattr(spec, "stability_limit", math.inf)
    if not (math.isfinite(lim) and omega_max > 0) or getattr(spec, "adaptive", False):
        return DRIFT_TOL
    return DRIFT_TOL + LEDGER_CONSTANT * min(1.0, h * omega_max / lim) ** getattr(spec, "ledger_order", 2)


class RunawayGuard:
    """Feed it each frame's energy (``check``, then ``record``); see the module docstring."""

    def __init__(self, system, terms: tuple, e0: float, drift_tol: float = DRIFT_TOL):
        self.e0, self.drift_tol = e0, drift_tol
        self.e_max = abs(e0)
        self.over_since: int | None = None  # step of the first check of the current run of imbalances
        self.over_checks = 0  # checks in that run
        self.recent: deque[tuple[int, float]] = deque()
        amp = float(np.sum(np.abs(terms.drv_prm[:, 0])))
        self.drive_scale = float(np.sum(system.mass * system.v0**2)) + amp**2 * system.n_sites + 1e-12

    def runaway(self, energy: float, work: float) -> bool:
        """True when ``energy`` (this frame) is a runaway given the recorded ``work`` so far."""
        return energy > RUNAWAY_FACTOR * max(self.e_max, self.drive_scale + max(work, 0.0))

    def imbalance(self, energy: float, work: float, dissipated: float) -> float:
        """|E − E0 − W + D| / (|E0| + |W| + D): the ledger's imbalance relative to the energy budget."""
        budget = abs(self.e0) + abs(work) + abs(dissipated)
        return abs(energy - self.e0 - work + dissipated) / max(budget, 1e-300)

    def unbalanced(self, energy: float, work: float, dissipated: float, step: int | None = None) -> str | None:
        """Why the ledger does not balance (module docstring), or None.

        With ``step`` (the cumulative step count), an imbalance must persist over
        ``PERSIST_CHECKS`` consecutive checks spanning ``RUNAWAY_LAG_STEPS`` steps: in the first steps of a drive the
        budget is tiny and the work quadrature's relative error is O(1) (a drive that starts like
        t², sampled by a few steps), which a runaway outgrows and a resolved run does not."""
        r = self.imbalance(energy, work, dissipated)
        if r <= self.drift_tol:
            self.over_since = None
            return None
        if step is not None:
            if self.over_since is None:
                self.over_since, self.over_checks = step, 0
            self.over_checks += 1
            if step - self.over_since < RUNAWAY_LAG_STEPS or self.over_checks < PERSIST_CHECKS:
                return None
        terms = "" if work == 0 and dissipated == 0 else f", work in {work:.4g}, dissipated {dissipated:.4g}"
        return (f"energy not conserved: E = {energy:.4g} from E0 = {self.e0:.4g}{terms} (nondimensional), an "
                f"imbalance of {r:.3g} of the energy budget, beyond the {self.drift_tol:.3g} the integrator's error "
                "allows: the step does not resolve the motion")

    def state(self) -> dict:
        """What ``restore`` needs to continue exactly (plain numbers, for a checkpoint)."""
        return {"e0": self.e0, "e_max": self.e_max, "over_since": self.over_since,
                "over_checks": self.over_checks, "recent": [list(r) for r in self.recent]}

    def restore(self, state: dict) -> None:
        self.e0, self.e_max = float(state["e0"]), float(state["e_max"])
        self.over_since, self.over_checks = state["over_since"], int(state["over_checks"])
        self.recent = deque((int(s), float(e)) for s, e in state["recent"])

    def record(self, step: int, energy: float) -> None:
        """Remember a good frame's |E| at cumulative step count ``step``."""
        self.recent.append((step, abs(energy)))
        while self.recent and self.recent[0][0] <= step - RUNAWAY_LAG_STEPS:
            self.e_max = max(self.e_max, self.recent.popleft()[1])
