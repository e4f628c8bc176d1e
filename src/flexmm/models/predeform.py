"""Static equilibrium of a rigid-unit lattice under applied strain or load (PHYSICS.md §1.2).

Constant loads are a linear potential E_load = −Σ_k f_k q_k (so they stay on during the dynamics
and the energy stays conserved); applied strain holds the end units at ∓ε L/2 along the axis.
``relax`` minimises the compiled energy with its exact gradient (scipy L-BFGS-B over the free
DOFs) and stores the equilibrium as the initial state ``q0`` and as ``meta['rest_state']``.
"""

from __future__ import annotations

import numpy as np
from scipy import optimize

from flexmm._jit import jit
from flexmm.models.base import System
from flexmm.models.hinge import chain_energy, chain_force, chain_reference

MAX_TURN = np.pi / 4  # largest change of a rotation from its initial guess during relaxation (rad)
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


def _residual(system: System, q: np.ndarray, idx: np.ndarray, f: np.ndarray) -> float:
    """Largest generalised force on the free DOFs."""
    system.force(q, system.args, f)
    return float(np.max(np.abs(f[idx]))) if idx.size else 0.0


def relax(system: System, cfg) -> dict:
    """Minimise the energy under ``cfg`` (a ``Predeform``); update q0, inv_mass, args, meta.

    Raises ValueError if the minimiser does not reach ``cfg.gradient_tolerance`` (e.g. a load
    with nothing to hold the lattice).
    """
    n, meta = system.n_sites, system.meta
    q = system.q0.copy()
    rot = system.field_index(meta["rotation_field"]) * n
    q[rot : rot + n] += cfg.theta_guess_rad
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
    idx = np.flatnonzero(free)
    f = np.zeros(system.ndof)

    def fun(x):
        q[idx] = x
        system.force(q, system.args, f)
        return float(system.energy(q, system.args)), -f[idx]

    # rotations stay within ±π/4 of the guess: the line search cannot flip a unit over
    x0 = q[idx].copy()
    angle = np.array([system.dof_kind(k) == "angle" for k in idx])
    lim = np.where(angle, MAX_TURN, np.inf)
    res = optimize.minimize(fun, x0, jac=True, method="L-BFGS-B", bounds=list(zip(x0 - lim, x0 + lim)),
                            options={"gtol": cfg.gradient_tolerance, "ftol": 1e-16, "maxiter": 50_000,
                                     "maxcor": 30})
    q[idx] = res.x
    if np.any(np.abs(res.x - x0)[angle] > 0.999 * MAX_TURN):
        raise ValueError(f"predeformation turned a unit by more than {MAX_TURN:.3f} rad from the initial "
                         "guess; give a closer guess (theta_guess_rad)")
    resid = _residual(system, q, idx, f)
    if resid > cfg.gradient_tolerance and idx.size:  # L-BFGS stalls on energy round-off: Newton polish
        def grad(x):
            q[idx] = x
            system.force(q, system.args, f)
            return -f[idx]
        try:
            q[idx] = optimize.newton_krylov(grad, q[idx].copy(), f_tol=cfg.gradient_tolerance, maxiter=50)
        except optimize.NoConvergence as exc:
            q[idx] = exc.args[0]
        resid = _residual(system, q, idx, f)
    if not resid <= 10 * cfg.gradient_tolerance:
        raise ValueError(f"predeformation did not converge: max residual force {resid:.3g} "
                         f"(nondimensional) after {res.nit} iterations ({res.message}); "
                         "is every load balanced by a fixed or strained end?")
    system.q0 = q
    system.inv_mass[list(held)] = 0.0
    info = {"residual": resid, "iterations": int(res.nit), "energy": float(system.energy(q, system.args))}
    meta["rest_state"] = q.copy()
    meta["predeform"] = info
    return info
