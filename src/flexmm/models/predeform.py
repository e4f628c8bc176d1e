"""Static equilibrium of a rigid-unit lattice under applied strain or load (PHYSICS.md §1.2).

Constant loads are a linear potential E_load = −Σ_k f_k q_k (so they stay on during the dynamics
and the energy stays conserved); applied strain holds the end units at ∓ε L/2 along the axis.
``relax`` minimises the energy with the compiled force (FIRE, a damped-dynamics minimiser that
moves continuously, so it cannot jump across a unit) and stores the equilibrium as the initial
state ``q0`` and as ``meta['rest_state']``.
"""

from __future__ import annotations

import numpy as np

from flexmm._jit import jit
from flexmm.models.base import System
from flexmm.models.hinge import chain_energy, chain_force, chain_reference

#: sign of the inward normal of an end, along its axis
INWARD = {"left": 1.0, "bottom": 1.0, "right": -1.0, "top": -1.0}


def empty_loads() -> tuple:
    """Load arguments with no loads: (dof (0,), value (0,))."""
    return (np.zeros(0, np.int64), np.zeros(0))


@jit
def load_terms(q, loads, out, want_force):
    """Add the constant forces to ``out`` (if ``want_force``); return E_load = −Σ f q."""
    dof, val = loads
    e = 0.0
    for k in range(dof.shape[0]):
        e -= val[k] * q[dof[k]]
        if want_force:
            out[dof[k]] += val[k]
    return e


def load_reference(q: np.ndarray, loads: tuple) -> tuple[float, np.ndarray]:
    dof, val = loads
    f = np.zeros_like(q)
    np.add.at(f, dof, val)
    return -float(np.dot(val, q[dof])), f


@jit
def chain_loaded_force(q, args, out):
    """Chain forces (hinge.chain_force on ``args[0]``) plus constant loads ``args[1]``."""
    chain_force(q, args[0], out)
    load_terms(q, args[1], out, True)


@jit
def chain_loaded_energy(q, args):
    return chain_energy(q, args[0]) + load_terms(q, args[1], np.empty(0), False)


def chain_loaded_reference(q: np.ndarray, args: tuple) -> tuple[float, np.ndarray]:
    e, f = chain_reference(q, args[0])
    el, fl = load_reference(q, args[1])
    return e + el, f + fl


def attach_loads(system: System, dof: np.ndarray, val: np.ndarray) -> None:
    """Put constant loads into a system's energy: its load slot, or the loaded chain kernels."""
    loads = (np.asarray(dof, np.int64), np.asarray(val, float))
    slot = system.meta.get("load_slot")
    if slot is not None:
        args = list(system.args)
        args[slot] = loads
        system.args = tuple(args)
    elif system.force is chain_force:
        system.force, system.energy = chain_loaded_force, chain_loaded_energy
        system.reference = chain_loaded_reference
        system.args = (system.args, loads)
    else:
        raise NotImplementedError(f"model {system.model!r} takes no constant loads")


def _strained(system: System, cfg, guess: np.ndarray) -> dict[int, float]:
    """Held DOFs (index -> value) of the applied strains; also seeds ``guess`` affinely."""
    n, meta = system.n_sites, system.meta
    fields = meta.get("axis_fields", {"x": meta["longitudinal_field"]})
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
            for s in meta["ends"][end]:
                held[k + s] = target[s]
    return held


@jit(cache=False)  # takes the model's force kernel as an argument (see flexmm._jit)
def fire_relax(force, args, q, free, dt0, dt_max, tol, max_steps):
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
        force(q, args, f)
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


def _stiffest(system: System, q: np.ndarray, free: np.ndarray, iters: int = 30) -> float:
    """Largest Hessian eigenvalue over the free DOFs at q (power iteration, force differences)."""
    rng = np.random.default_rng(0)
    x = rng.normal(size=q.size) * free
    fp, fm = np.zeros(q.size), np.zeros(q.size)
    lam = 1.0
    for _ in range(iters):
        x /= np.linalg.norm(x)
        eps = 1e-6
        system.force(q + eps * x, system.args, fp)
        system.force(q - eps * x, system.args, fm)
        y = -(fp - fm) / (2 * eps) * free
        lam = float(np.dot(x, y))
        x = y
    return abs(lam)


def relax(system: System, cfg) -> dict:
    """Minimise the energy under ``cfg`` (a ``Predeform``); update q0, inv_mass, args, meta.

    Raises ValueError if the minimiser does not reach ``cfg.gradient_tolerance`` (e.g. a load
    with nothing to hold the lattice).
    """
    n, meta = system.n_sites, system.meta
    q = system.q0.copy()
    rot = system.field_index(meta["rotation_field"]) * n
    q[rot : rot + n] += np.where(system.inv_mass[rot : rot + n] > 0, cfg.theta_guess_rad, 0.0)
    held = _strained(system, cfg, q)
    dof, val = [], []
    for load in cfg.loads:
        sites = meta["ends"][load.end]
        field = meta.get("end_fields", {}).get(load.end, meta["longitudinal_field"])
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
    steps, resid = fire_relax(system.force, system.args, q, mask, 0.1 / np.sqrt(lam), 0.5 / np.sqrt(lam),
                              cfg.gradient_tolerance, cfg.max_steps)
    if not resid <= cfg.gradient_tolerance:
        raise ValueError(f"predeformation did not converge: max residual force {resid:.3g} "
                         f"(nondimensional) after {steps} steps; is every load balanced by a fixed or "
                         "strained end?")
    system.q0 = q
    system.inv_mass[list(held)] = 0.0
    info = {"residual": float(resid), "steps": int(steps), "energy": float(system.energy(q, system.args))}
    meta["rest_state"] = q.copy()
    meta["predeform"] = info
    return info
