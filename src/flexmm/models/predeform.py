"""Static equilibrium of a rigid-unit lattice under applied strain or load (docs/physics.md §1.2).

Constant loads are a linear potential E_load = −Σ_k f_k q_k (so they stay on during the dynamics
and the energy stays conserved); applied strain holds the end units at ∓ε L/2 along the axis.
``relax`` minimises the energy with the compiled force (FIRE, a damped-dynamics minimiser that
moves continuously, so it cannot jump across a unit) and stores the equilibrium as the initial
state ``q0`` and as ``System.predeformation``.
"""

from __future__ import annotations

import numpy as np

from flexmm._jit import jit
from flexmm.linalg import force_hessian, top_eigenvalue
from flexmm.models.base import Predeformation, System
from flexmm.models.hinge import ChainArgs
from flexmm.models.kernels import model_force
from flexmm.models.loads import LoadedChainArgs

#: sign of the inward normal of an end, along its axis
INWARD = {"left": 1.0, "bottom": 1.0, "right": -1.0, "top": -1.0}


def attach_loads(system: System, dof: np.ndarray, val: np.ndarray) -> None:
    """Put constant loads into a system's energy: its ``loads`` slot, or a loaded chain."""
    loads = (np.asarray(dof, np.int64), np.asarray(val, float))
    if "loads" in system.args._fields:
        system.args = system.args._replace(loads=loads)
    elif isinstance(system.args, ChainArgs):
        system.args = LoadedChainArgs(system.args, loads)
    else:
        raise NotImplementedError(f"model {system.model!r} takes no constant loads")


def _strained(system: System, cfg, guess: np.ndarray) -> dict[int, float]:
    """Held DOFs (index -> value) of the applied strains; also seeds ``guess`` affinely."""
    n, fields = system.n_sites, system.axis_fields
    held = {}
    for axis, eps, ends in (("x", cfg.strain_x, ("left", "right")), ("y", cfg.strain_y, ("bottom", "top"))):
        if eps is None:
            continue
        if axis not in fields:
            raise ValueError(f"model {system.model!r} has no {axis} axis to strain")
        x = system.site_coords[axis] / system.scales.length_m
        target = eps * (x - 0.5 * (x.min() + x.max()))
        k = system.field_index(fields[axis]) * n
        guess[k : k + n] += target
        for end in ends:
            for s in system.ends[end]:
                held[k + s] = target[s]
    return held


@jit
def fire_relax(args, q, free, dt0, dt_max, tol, max_steps):
    """FIRE minimisation (Bitzek et al., PRL 97, 170201, 2006) of the energy behind ``force``.

    Moves only DOFs with ``free[k] > 0`` (unit masses); stops when max |F| over them < ``tol``.
    Returns (steps taken, final max |F|). ``q`` is updated in place.
    """
    n = q.shape[0]
    v = np.zeros(n)
    f = np.zeros(n)
    dt, alpha, n_pos = dt0, 0.1, 0
    resid = np.inf
    for step in range(max_steps):
        model_force(q, args, f)
        power, vv, ff, resid = 0.0, 0.0, 0.0, 0.0
        for k in range(n):
            if free[k] > 0.0:
                power += f[k] * v[k]
                vv += v[k] * v[k]
                ff += f[k] * f[k]
                resid = max(resid, abs(f[k]))
        if resid < tol:
            return step, resid
        if power > 0.0:
            mix = alpha * np.sqrt(vv / ff) if ff > 0.0 else 0.0
            for k in range(n):
                v[k] = ((1.0 - alpha) * v[k] + mix * f[k]) * free[k]
            n_pos += 1
            if n_pos > 5:
                dt = min(1.1 * dt, dt_max)
                alpha *= 0.99
        else:
            for k in range(n):
                v[k] = 0.0
            dt *= 0.5
            alpha, n_pos = 0.1, 0
        for k in range(n):
            if free[k] > 0.0:
                v[k] += dt * f[k]
                q[k] += dt * v[k]
    return max_steps, resid


def _stiffest(system: System, q: np.ndarray, free: np.ndarray) -> float:
    """Largest Hessian eigenvalue over the free DOFs (``free`` a 0/1 mask) at q."""
    kx = force_hessian(system.force, system.args, q)
    return top_eigenvalue(lambda x: free * kx(free * x), q.size, np.flatnonzero(free))


def relax(system: System, cfg) -> Predeformation:
    """Minimise the energy under ``cfg`` (a ``Predeform``); update q0, inv_mass, args, predeformation.

    Raises ValueError if the minimiser does not reach ``cfg.gradient_tolerance`` (e.g. a load
    with nothing to hold the lattice).
    """
    n = system.n_sites
    q = system.q0.copy()
    rot = system.field_index(system.rotation_field) * n
    q[rot : rot + n] += np.where(system.inv_mass[rot : rot + n] > 0, cfg.theta_guess_rad, 0.0)
    held = _strained(system, cfg, q)
    dof, val = [], []
    for load in cfg.loads:
        sites = system.ends[load.end]
        field = system.end_field(load.end)
        k = system.field_index(field) * n
        f = INWARD[load.end] * load.force_n / system.scales.force / len(sites)
        dof += [k + s for s in sites]
        val += [f] * len(sites)
    if dof:
        attach_loads(system, np.array(dof), np.array(val))
    for k, x in held.items():
        q[k] = x
    free = system.inv_mass > 0
    free[list(held)] = False
    mask = free.astype(float)
    lam = max(_stiffest(system, q, mask), 1e-12)
    steps, resid = fire_relax(system.args, q, mask, 0.1 / np.sqrt(lam), 0.5 / np.sqrt(lam),
                              cfg.gradient_tolerance, cfg.max_steps)
    if not resid <= cfg.gradient_tolerance:
        raise ValueError(f"predeformation did not converge: max residual force {resid:.3g} "
                         f"(nondimensional) after {steps} steps; is every load balanced by a fixed or "
                         "strained end?")
    system.q0 = q
    system.inv_mass[list(held)] = 0.0
    system.predeformation = Predeformation(rest_state=q.copy(), residual=float(resid), steps=int(steps),
                                           energy=float(system.energy(q, system.args)))
    return system.predeformation
