"""Velocity Verlet with semi-implicit linear damping (docs/physics.md §3).

With on-site damping c_k (rate γ_k = c_k/m_k) one step of size h reads

    v½ = v + h/2 (F(q, v)/m − γ v)
    q' = q + h v½
    v' = (v½ + h/2 F(q', v*)/m) / (1 + h γ/2)

which is explicit, second order, symplectic when γ = 0 and keeps the linear stability limit
h ω_max < 2. Contact forces enter F explicitly. Velocity-dependent external forces (dashpots,
ground friction) are evaluated at the predicted end-of-step velocity
v* = (v½ + h/2 F(q', v½)/m)/(1 + hγ/2), which keeps the step second order (with v½ alone it
would be first order). The energy ledger is consistent with the step to O(h²): dissipation by
the midpoint rule (with v½), work of applied forces by the trapezoid rule in time with the
half-step velocity v½ = Δq/h.

Speed (benchmarks/): per-DOF kick and damping factors are computed once per call, the end
kick of one step and the start kick + drift of the next run as one pass, and the ledger and
external terms are skipped when a scene has none. ``verlet_advance_parallel`` runs the same
passes over blocks of DOFs on numba's threads (with a parallel force kernel, for N ≳ 1e5).
"""

from __future__ import annotations

import numpy as np

from flexmm._jit import jit, prange
from flexmm.models.kernels import model_force, model_force_parallel
from flexmm.integrators.common import (
    ACC_DISSIPATED,
    ACC_WORK,
    ACC_FEVALS,
    ACC_STEPS,
    applied_power,
    apply_prescribed,
    damping_power,
    dashpot_power,
    external_forces,
    has_velocity_terms,
    total_force,
)

#: DOFs per block of the parallel passes (blocks are shared out among the threads)
BLOCK = 8192


@jit
def verlet_force(args, q, v, t, f, terms):
    """Total force at (q, v, t): model forces plus contacts, dashpots and applied forces."""
    return total_force(args, q, v, t, f, terms)


@jit
def _factors(minv, damp, h):
    """Per-DOF kick h/2·m⁻¹, damping factors 1 − hγ/2 and 1/(1 + hγ/2), masked c; any damping."""
    n = minv.shape[0]
    kick = np.empty(n)
    pre = np.empty(n)
    post = np.empty(n)
    cd = np.empty(n)
    damped = False
    for k in range(n):
        g = damp[k] * minv[k]
        kick[k] = 0.5 * h * minv[k]
        pre[k] = 1.0 - 0.5 * h * g
        post[k] = 1.0 / (1.0 + 0.5 * h * g)
        cd[k] = damp[k] if minv[k] > 0.0 else 0.0
        damped = damped or g != 0.0
    return kick, pre, post, cd, damped


# Block passes: all arguments are slices over the same DOFs, loops start at 0 (vectorise).
@jit
def _start(q, v, f, kick, pre, h, damped):
    """Half kick (with damping) then drift."""
    if damped:
        for k in range(q.shape[0]):
            v[k] = v[k] * pre[k] + kick[k] * f[k]
            q[k] += h * v[k]
    else:
        for k in range(q.shape[0]):
            v[k] += kick[k] * f[k]
            q[k] += h * v[k]


@jit
def _end(v, f, kick, post, damped):
    """Closing half kick (semi-implicit damping)."""
    if damped:
        for k in range(v.shape[0]):
            v[k] = (v[k] + kick[k] * f[k]) * post[k]
    else:
        for k in range(v.shape[0]):
            v[k] += kick[k] * f[k]


@jit
def _end_start(q, v, f, kick, pre, post, h, damped):
    """Closing half kick of one step fused with the opening half kick and drift of the next."""
    if damped:
        for k in range(q.shape[0]):
            v[k] = (v[k] + kick[k] * f[k]) * post[k] * pre[k] + kick[k] * f[k]
            q[k] += h * v[k]
    else:
        for k in range(q.shape[0]):
            v[k] += 2.0 * kick[k] * f[k]
            q[k] += h * v[k]


@jit
def _onsite_power(v, cd):
    s = 0.0
    for k in range(v.shape[0]):
        s += cd[k] * v[k] * v[k]
    return s


@jit
def _external(q, v, t, f, terms, kick, post, f_model, v_pred, vdep):
    """Add external terms to the model force in ``f``; velocity terms at the predicted v'."""
    con_ij, con_prm, dash_ij, dash_c = terms.con_ij, terms.con_prm, terms.dash_ij, terms.dash_c
    drv_dof, drv_mode, drv_shape, drv_prm = terms.drv_dof, terms.drv_mode, terms.drv_shape, terms.drv_prm
    if vdep:
        f_model[:] = f
    power = external_forces(q, v, t, f, con_ij, con_prm, dash_ij, dash_c, drv_dof, drv_mode, drv_shape, drv_prm)
    if vdep:  # re-evaluate velocity-dependent forces at the predicted v'
        for k in range(q.shape[0]):
            v_pred[k] = (v[k] + kick[k] * f[k]) * post[k]
            f[k] = f_model[k]
        external_forces(q, v_pred, t, f, con_ij, con_prm, dash_ij, dash_c, drv_dof, drv_mode, drv_shape, drv_prm)
    return power


@jit
def _count(acc, nsteps):
    if acc.shape[0] > ACC_STEPS:
        acc[ACC_FEVALS] += nsteps
        acc[ACC_STEPS] += nsteps


@jit
def verlet_advance(args, q, v, f, minv, damp, terms, t, h, nsteps, acc):
    """Advance ``nsteps`` steps of size ``h`` from time ``t``; returns the new time.

    ``f`` must hold the total force at entry and is kept current. ``acc`` accumulates the
    energy dissipated by damping and the work of applied forces (``common.ACC_*``).
    """
    if nsteps <= 0:
        return t
    dash_ij, dash_c, drv_dof, drv_mode, drv_shape, drv_prm = (terms.dash_ij, terms.dash_c, terms.drv_dof,
                                                          terms.drv_mode, terms.drv_shape, terms.drv_prm)
    n = q.shape[0]
    kick, pre, post, cd, damped = _factors(minv, damp, h)
    vdep = has_velocity_terms(terms)
    external = terms.con_ij.shape[0] + dash_ij.shape[0] + drv_dof.shape[0] > 0
    dissipative = damped or dash_ij.shape[0] > 0
    f_model = np.empty(n if vdep else 0)
    v_pred = np.empty(n if vdep else 0)
    _start(q, v, f, kick, pre, h, damped)
    for s in range(nsteps):
        power0 = applied_power(v, f, t, drv_dof, drv_mode, drv_shape, drv_prm)  # with v½ at t
        t += h
        apply_prescribed(q, v, t, drv_dof, drv_mode, drv_shape, drv_prm)
        model_force(q, args, f)
        power = 0.0
        if external:
            power = _external(q, v, t, f, terms, kick, post, f_model, v_pred, vdep)
        if dissipative:
            acc[ACC_DISSIPATED] += h * damping_power(v, cd, dash_ij, dash_c)
        acc[ACC_WORK] += 0.5 * h * (power0 + power)
        if s < nsteps - 1:
            _end_start(q, v, f, kick, pre, post, h, damped)
        else:
            _end(v, f, kick, post, damped)
    _count(acc, nsteps)
    return t


@jit(parallel=True)
def verlet_advance_parallel(args, q, v, f, minv, damp, terms, t, h, nsteps, acc):
    """``verlet_advance`` with the DOF passes split over numba's threads (same arguments).

    The model's threaded force kernel (``models.kernels.model_force_parallel``) uses the threads
    for the force too; the scheme and results are those of ``verlet_advance``.
    """
    if nsteps <= 0:
        return t
    dash_ij, dash_c, drv_dof, drv_mode, drv_shape, drv_prm = (terms.dash_ij, terms.dash_c, terms.drv_dof,
                                                          terms.drv_mode, terms.drv_shape, terms.drv_prm)
    n = q.shape[0]
    kick, pre, post, cd, damped = _factors(minv, damp, h)
    vdep = has_velocity_terms(terms)
    external = terms.con_ij.shape[0] + dash_ij.shape[0] + drv_dof.shape[0] > 0
    nb = max(1, min(n // BLOCK, 16))
    f_model = np.empty(n if vdep else 0)
    v_pred = np.empty(n if vdep else 0)
    for b in prange(nb):
        lo, hi = b * n // nb, (b + 1) * n // nb
        _start(q[lo:hi], v[lo:hi], f[lo:hi], kick[lo:hi], pre[lo:hi], h, damped)
    for s in range(nsteps):
        power0 = applied_power(v, f, t, drv_dof, drv_mode, drv_shape, drv_prm)
        t += h
        apply_prescribed(q, v, t, drv_dof, drv_mode, drv_shape, drv_prm)
        model_force_parallel(q, args, f)
        power = 0.0
        if external:
            power = _external(q, v, t, f, terms, kick, post, f_model, v_pred, vdep)
        if damped:
            diss = 0.0
            for b in prange(nb):
                lo, hi = b * n // nb, (b + 1) * n // nb
                diss += _onsite_power(v[lo:hi], cd[lo:hi])
            acc[ACC_DISSIPATED] += h * diss
        if dash_ij.shape[0] > 0:
            acc[ACC_DISSIPATED] += h * dashpot_power(v, dash_ij, dash_c)
        acc[ACC_WORK] += 0.5 * h * (power0 + power)
        last = s == nsteps - 1
        for b in prange(nb):
            lo, hi = b * n // nb, (b + 1) * n // nb
            if last:
                _end(v[lo:hi], f[lo:hi], kick[lo:hi], post[lo:hi], damped)
            else:
                _end_start(q[lo:hi], v[lo:hi], f[lo:hi], kick[lo:hi], pre[lo:hi], post[lo:hi], h, damped)
    _count(acc, nsteps)
    return t
