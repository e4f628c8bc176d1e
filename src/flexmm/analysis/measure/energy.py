"""Energy budget of a run: E(t) = E(0) + W(t) − D(t) (work W done by the excitation, D dissipated).

Reads the per-time variables the controller writes (``kinetic_energy``, ``potential_energy``,
``total_energy``, ``dissipated_energy``, ``applied_work``; J). The balance residual
E(t) − E(0) − W(t) + D(t) measures the integrator's energy error, relative to the largest energy
that entered the system (E(0) + max W).

The work of a prescribed displacement (shaker with ``amplitude_m`` or ``amplitude_rad``,
``boundary_displacement``) is recorded in ``applied_work`` and ``kinetic_energy`` leaves out the
driven units (docs/physics.md §3). Datasets of old runs recorded no such work: when the config
has one and the recorded work is zero, the work is inferred from the balance,
W = E(t) − E(0) + D(t), ``work_recorded`` is False and the balance error is NaN (there is
nothing independent left to check).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np


@dataclass
class EnergyBudget:
    """Energies at the start and the end of the run and the worst balance error (J)."""

    initial_total_j: float
    work_j: float
    final_kinetic_j: float
    final_potential_j: float
    final_total_j: float
    dissipated_j: float
    max_kinetic_j: float
    balance_residual_j: float
    max_relative_balance_error: float
    work_recorded: bool = True

    def scalars(self) -> dict:
        return asdict(self)


def _displacement_drive(ds) -> bool:
    import yaml

    loader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)  # libyaml's where there is one: 10x faster
    exc = (yaml.load(ds.attrs.get("config", ""), Loader=loader) or {}).get("excitation") or {}
    return exc.get("kind") == "boundary_displacement" or (
        exc.get("kind") == "shaker" and exc.get("amplitude_n") is None)


def energy_budget(ds) -> EnergyBudget | None:
    """Budget from a run dataset, or None when it has no energy variables."""
    if not all(v in ds for v in ("kinetic_energy", "potential_energy")):
        return None
    kin = np.asarray(ds["kinetic_energy"].values, float)
    pot = np.asarray(ds["potential_energy"].values, float)
    tot = np.asarray(ds["total_energy"].values, float) if "total_energy" in ds else kin + pot
    zero = np.zeros_like(tot)
    work = np.asarray(ds["applied_work"].values, float) if "applied_work" in ds else zero
    diss = np.asarray(ds["dissipated_energy"].values, float) if "dissipated_energy" in ds else zero
    recorded = not (np.all(work == 0) and _displacement_drive(ds))
    if not recorded:
        work = tot - tot[0] + diss
    resid = tot - tot[0] - work + diss
    scale = max(abs(tot[0]) + float(np.max(np.abs(work))), float(np.max(np.abs(tot))), 1e-300)
    return EnergyBudget(
        initial_total_j=float(tot[0]), work_j=float(work[-1]), final_kinetic_j=float(kin[-1]),
        final_potential_j=float(pot[-1]), final_total_j=float(tot[-1]), dissipated_j=float(diss[-1]),
        max_kinetic_j=float(kin.max()), balance_residual_j=float(resid[-1]),
        max_relative_balance_error=float(np.max(np.abs(resid)) / scale) if recorded else float("nan"),
        work_recorded=recorded,
    )
