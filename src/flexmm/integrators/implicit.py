"""Implicit midpoint rule with a matrix-free Newton–Krylov solve (PHYSICS.md §3).

For q' = v, M v' = F(q, v, t) − C v, one step of size h is

    V = (v + v')/2,   Q = q + (h/2) V,   q' = q + h V,   v' = 2V − v,
    R(V) = M (V − v) − (h/2) (F(Q, V, t + h/2) − C V) = 0,

solved for the midpoint velocity V of the free DOFs by Newton's method. The Jacobian
M + (h²/4) K + (h/2) C_v (K the stiffness, C_v the velocity-force Jacobian) is applied
matrix-free by a forward difference of R (one force evaluation per product) and inverted by
preconditioned conjugate gradients (preconditioner M + (h/2) c). Second order, symplectic
without damping, A-stable: no step-size limit from stiff hinges or contacts, only accuracy.
Held DOFs keep V = 0 (fixed) or V = (g(t + h) − g(t))/h (prescribed, so Q is the mean).
Energy ledger: midpoint rule, h (c·V² + dashpot power) and h P_applied(V, t + h/2) — exact for
quadratic energies.

Newton stops when the update is below ``NEWTON_RTOL`` × max|V|, or when it stops shrinking
while below ``STALL_RTOL`` × max|V| (the round-off floor of F: hinge strains are differences
of O(1) terms, so at tiny amplitudes F carries a relative error ~1e-16/strain).
``f`` carries the total force at the last midpoint between calls (``init`` fills it at the
start); it only seeds the predictor V₀ = v + (h/2) M⁻¹(f − C v). A Newton iteration that
does not converge in ``MAX_NEWTON`` iterations sets the state to NaN (the controller reports a
failed run) and counts in ``acc[ACC_FAILED]``.
"""

from __future__ import annotations

import math

import numpy as np

from flexmm._jit import jit
from flexmm.integrators.common import (
    ACC_FAILED,
    ACC_FEVALS,
    ACC_LINEAR,
    ACC_REJECTED,
    ACC_STEPS,
    applied_power,
    apply_prescribed,
    damping_power,
    free_damping,
    total_force,
)

MAX_NEWTON = 30
NEWTON_RTOL = 1e-12  # on the update of V, relative to max |V| (plus an absolute floor)
STALL_RTOL = 1e-6  # an update that stops shrinking below this (relative) is round-off: accept
CG_RTOL = 1e-6  # forcing term of the inexact Newton iteration
MAX_CG = 500


@jit(cache=False)  # takes the model's force kernel (see flexmm._jit)
def _residual(force, args, terms, minv, damp, q, v, V, t_mid, h, Q, F, R):
    """R(V) on the free DOFs (0 on held ones); leaves Q and F at the midpoint. Returns P_applied."""
    for k in range(q.shape[0]):
        Q[k] = q[k] + 0.5 * h * V[k]
    power = total_force(force, args, Q, V, t_mid, F, terms)
    for k in range(q.shape[0]):
        if minv[k] > 0.0:
            R[k] = (V[k] - v[k]) / minv[k] - 0.5 * h * (F[k] - damp[k] * V[k])
        else:
            R[k] = 0.0
    return power


@jit
def _norm_inf(x):
    s = 0.0
    for k in range(x.shape[0]):
        s = max(s, abs(x[k]))
    return s


@jit
def _dot(x, y):
    s = 0.0
    for k in range(x.shape[0]):
        s += x[k] * y[k]
    return s


@jit(cache=False)  # takes the model's force kernel (see flexmm._jit)
def _jacobian_product(force, args, terms, minv, damp, q, v, V, t_mid, h, R0, x, out, W):
    """out ≈ J x = (R(V + εx) − R(V))/ε, by one force evaluation."""
    Vp, Qp, Fp = W[0], W[1], W[2]
    xn = _norm_inf(x)
    if xn == 0.0:
        out[:] = 0.0
        return
    eps = 1e-7 * (1.0 + _norm_inf(V)) / xn
    for k in range(V.shape[0]):
        Vp[k] = V[k] + eps * x[k]
    _residual(force, args, terms, minv, damp, q, v, Vp, t_mid, h, Qp, Fp, out)
    for k in range(V.shape[0]):
        out[k] = (out[k] - R0[k]) / eps


@jit(cache=False)  # takes the model's force kernel (see flexmm._jit)
def _cg(force, args, terms, minv, damp, q, v, V, t_mid, h, R0, delta, precond, W):
    """Solve J δ = −R0 approximately by preconditioned CG; returns the iterations used."""
    r, z, p, Ap = W[3], W[4], W[5], W[6]
    delta[:] = 0.0
    for k in range(V.shape[0]):
        r[k] = -R0[k]
        z[k] = r[k] * precond[k]
    p[:] = z
    rz = _dot(r, z)
    r0 = math.sqrt(_dot(r, r))
    if r0 == 0.0:
        return 0
    it = 0
    while it < MAX_CG:
        it += 1
        _jacobian_product(force, args, terms, minv, damp, q, v, V, t_mid, h, R0, p, Ap, W)
        pAp = _dot(p, Ap)
        if not pAp > 0.0:  # not positive definite (or NaN): keep what we have
            break
        alpha = rz / pAp
        for k in range(V.shape[0]):
            delta[k] += alpha * p[k]
            r[k] -= alpha * Ap[k]
        if math.sqrt(_dot(r, r)) <= CG_RTOL * r0:
            break
        for k in range(V.shape[0]):
            z[k] = r[k] * precond[k]
        rz_new = _dot(r, z)
        beta = rz_new / rz
        rz = rz_new
        for k in range(V.shape[0]):
            p[k] = z[k] + beta * p[k]
    return it


@jit(cache=False)  # takes the model's force kernel (see flexmm._jit)
def midpoint_advance(force, args, q, v, f, minv, damp, terms, t, h, nsteps, acc):
    """Advance ``nsteps`` implicit-midpoint steps of size ``h`` from ``t``; returns the new time."""
    drv_dof, drv_mode, drv_shape, drv_prm = terms[4], terms[5], terms[6], terms[7]
    n = q.shape[0]
    cd = free_damping(damp, minv)
    counting = acc.shape[0] > ACC_FAILED
    precond = np.empty(n)
    for k in range(n):
        precond[k] = 1.0 / (1.0 / minv[k] + 0.5 * h * damp[k]) if minv[k] > 0.0 else 0.0
    V = np.empty(n)
    Q = np.empty(n)
    R = np.empty(n)
    delta = np.empty(n)
    q_end = np.empty(n)
    v_end = np.empty(n)
    W = np.empty((7, n))
    for _ in range(nsteps):
        t_mid = t + 0.5 * h
        q_end[:] = q
        v_end[:] = v
        apply_prescribed(q_end, v_end, t + h, drv_dof, drv_mode, drv_shape, drv_prm)
        for k in range(n):
            if minv[k] > 0.0:
                V[k] = v[k] + 0.5 * h * minv[k] * (f[k] - damp[k] * v[k])
            else:
                V[k] = (q_end[k] - q[k]) / h  # 0 on fixed DOFs, mean rate on prescribed ones
        converged = False
        power = 0.0
        step_prev = math.inf
        for it in range(MAX_NEWTON):
            power = _residual(force, args, terms, minv, damp, q, v, V, t_mid, h, Q, f, R)
            lin = _cg(force, args, terms, minv, damp, q, v, V, t_mid, h, R, delta, precond, W)
            if counting:
                acc[ACC_FEVALS] += 1 + lin
                acc[ACC_REJECTED] += 1
                acc[ACC_LINEAR] += lin
            for k in range(n):
                V[k] += delta[k]
            step, size = _norm_inf(delta), _norm_inf(V)
            # converged, or stalled at the round-off floor of F (cancellation in the springs)
            if step <= NEWTON_RTOL * size + 1e-300 or (step >= 0.5 * step_prev and step <= STALL_RTOL * size):
                converged = True
                break
            step_prev = step
        if not converged:
            q[:] = np.nan
            if counting:
                acc[ACC_FAILED] += 1
            return t + h
        # f and power are from the last residual, at V before its final update (≤ NEWTON_RTOL)
        acc[0] += h * damping_power(V, cd, terms[2], terms[3])
        acc[1] += h * power
        for k in range(n):
            q[k] += h * V[k]
            v[k] = 2.0 * V[k] - v[k]
        t += h
        apply_prescribed(q, v, t, drv_dof, drv_mode, drv_shape, drv_prm)
        if counting:
            acc[ACC_STEPS] += 1
    return t
