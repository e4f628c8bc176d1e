"""Implicit midpoint rule with a matrix-free Newton–Krylov solve (docs/physics.md §3).

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

Newton stops when max|R| ≤ ρ × size + ``FORCE_FLOOR`` × h, size = max(M|V − v|, h|F|/2) (the
step's change). The relative tolerance ρ scales with the accuracy of the step: at the explicit
predictor the residual is |R₀| ≈ (hω/2) × size (ω the frequency of the motion), while the
rule's local error is ≈ (hω)²/6 × size, so ρ = ``NEWTON_ACCURACY`` (|R₀|/size)² ≈ 2.5e-3 (hω)²,
clamped to [``NEWTON_RTOL``, ``NEWTON_RTOL_MAX``], keeps the Newton error near 1.5 % of the local
error or below at every step size. A fixed tolerance either floors the error at small steps
(a fixed 3e-3 accepts the predictor: order 0.5, tests/integrators/test_integrator_long_order)
or costs a second Newton–Krylov solve per step for nothing (the former fixed 1e-12: twice the
force evaluations on the LEGO soliton bench, final errors equal to 4 digits). The absolute
floor is the round-off of F (hinge strains are differences of O(1) terms, so at tiny
amplitudes F carries an absolute error ~1e-16).
``f`` carries the total force at the last midpoint between calls (``init`` fills it at the
start); it only seeds the predictor V₀ = v + (h/2) M⁻¹(f − C v). A step whose Newton iteration
does not converge in ``MAX_NEWTON`` iterations (strong nonlinearity, or a Jacobian made
indefinite by compression past buckling, where CG stops early) is retried as 2, 4, … substeps;
if even ``MAX_SPLIT`` substeps fail, the state is set to NaN (the controller reports a failed
run) and ``acc[ACC_FAILED]`` counts it.
"""

from __future__ import annotations

import math

import numpy as np

from flexmm._jit import jit
from flexmm.integrators.common import (
    ACC_DISSIPATED,
    ACC_WORK,
    ACC_FAILED,
    ACC_FEVALS,
    ACC_LINEAR,
    ACC_REJECTED,
    ACC_STEPS,
    apply_prescribed,
    damping_power,
    free_damping,
    total_force,
)

MAX_NEWTON = 30
MAX_SPLIT = 64  # a failed step is retried as up to this many substeps
NEWTON_RTOL = 1e-12  # tightest tolerance on the residual, relative to the size of its terms
NEWTON_RTOL_MAX = 1e-6  # loosest (steps far beyond the explicit limit, hω ≫ 1)
NEWTON_ACCURACY = 1e-2  # relative tolerance = NEWTON_ACCURACY (|R₀|/size)², clamped (docstring)
FORCE_FLOOR = 1e-14  # absolute round-off of F (nondimensional): hinge strains are differences of O(1) terms
CG_RTOL = 1e-6  # forcing term of the inexact Newton iteration
MAX_CG = 500


@jit
def _residual(args, terms, minv, damp, q, v, V, t_mid, h, Q, F, R):
    """R(V) on the free DOFs (0 on held ones); leaves Q and F at the midpoint. Returns P_applied."""
    for k in range(q.shape[0]):
        Q[k] = q[k] + 0.5 * h * V[k]
    power = total_force(args, Q, V, t_mid, F, terms)
    for k in range(q.shape[0]):
        if minv[k] > 0.0:
            R[k] = (V[k] - v[k]) / minv[k] - 0.5 * h * (F[k] - damp[k] * V[k])
        else:
            R[k] = 0.0
    return power


@jit
def _residual_size(R, V, v, F, minv, h):
    """(max |R|, size of its terms) over the free DOFs."""
    res = 0.0
    size = 0.0
    for k in range(R.shape[0]):
        if minv[k] > 0.0:
            res = max(res, abs(R[k]))
            size = max(size, abs(V[k] - v[k]) / minv[k], 0.5 * h * abs(F[k]))
    return res, size


@jit
def newton_rtol(res0, size0):
    """Relative residual tolerance from the residual at the predictor (module docstring)."""
    x = res0 / size0 if size0 > 0.0 else 0.0
    return min(NEWTON_RTOL_MAX, max(NEWTON_RTOL, NEWTON_ACCURACY * x * x))


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


@jit
def _jacobian_product(args, terms, minv, damp, q, v, V, t_mid, h, R0, x, out, W):
    """out ≈ J x = (R(V + εx) − R(V))/ε, by one force evaluation."""
    Vp, Qp, Fp = W[0], W[1], W[2]
    xn = _norm_inf(x)
    if xn == 0.0:
        out[:] = 0.0
        return
    eps = 1e-7 * (1.0 + _norm_inf(V)) / xn
    for k in range(V.shape[0]):
        Vp[k] = V[k] + eps * x[k]
    _residual(args, terms, minv, damp, q, v, Vp, t_mid, h, Qp, Fp, out)
    for k in range(V.shape[0]):
        out[k] = (out[k] - R0[k]) / eps


@jit
def _cg(args, terms, minv, damp, q, v, V, t_mid, h, R0, delta, precond, W):
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
        _jacobian_product(args, terms, minv, damp, q, v, V, t_mid, h, R0, p, Ap, W)
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


@jit
def step(args, terms, minv, damp, cd, q, v, f, t, h, acc, work, rtol_fixed):
    """One midpoint step of size h in place; False (q, v untouched) if Newton did not converge.

    ``rtol_fixed`` > 0 replaces the adaptive relative tolerance (``newton_rtol``): the design
    sweeps (``design.midpoint``) solve every step to round-off, so the run is the exact implicit
    map their adjoint differentiates. On success V and Q of the step are left in work[7], work[8]."""
    drv_dof, drv_mode, drv_shape, drv_prm = terms.drv_dof, terms.drv_mode, terms.drv_shape, terms.drv_prm
    n = q.shape[0]
    counting = acc.shape[0] > ACC_FAILED
    V, Q, R, delta, q_end, v_end, precond = work[7], work[8], work[9], work[10], work[11], work[12], work[13]
    for k in range(n):
        precond[k] = 1.0 / (1.0 / minv[k] + 0.5 * h * damp[k]) if minv[k] > 0.0 else 0.0
    t_mid = t + 0.5 * h
    q_end[:] = q
    v_end[:] = v
    apply_prescribed(q_end, v_end, t + h, drv_dof, drv_mode, drv_shape, drv_prm)
    for k in range(n):
        if minv[k] > 0.0:
            V[k] = v[k] + 0.5 * h * minv[k] * (f[k] - damp[k] * v[k])
        else:
            V[k] = (q_end[k] - q[k]) / h  # 0 on fixed DOFs, mean rate on prescribed ones
    power = 0.0
    rtol = NEWTON_RTOL
    for it in range(MAX_NEWTON):
        power = _residual(args, terms, minv, damp, q, v, V, t_mid, h, Q, f, R)
        if counting:
            acc[ACC_FEVALS] += 1
            acc[ACC_REJECTED] += 1
        res, size = _residual_size(R, V, v, f, minv, h)
        if it == 0:
            rtol = newton_rtol(res, size) if rtol_fixed <= 0.0 else rtol_fixed
        if res <= rtol * size + FORCE_FLOOR * h:
            acc[ACC_DISSIPATED] += h * damping_power(V, cd, terms.dash_ij, terms.dash_c)
            acc[ACC_WORK] += h * power
            for k in range(n):
                q[k] += h * V[k]
                v[k] = 2.0 * V[k] - v[k]
            apply_prescribed(q, v, t + h, drv_dof, drv_mode, drv_shape, drv_prm)
            if counting:
                acc[ACC_STEPS] += 1
            return True
        lin = _cg(args, terms, minv, damp, q, v, V, t_mid, h, R, delta, precond, work)
        if counting:
            acc[ACC_FEVALS] += lin
            acc[ACC_LINEAR] += lin
        for k in range(n):
            V[k] += delta[k]
        if not math.isfinite(_norm_inf(delta)):
            return False
    return False


@jit
def midpoint_advance(args, q, v, f, minv, damp, terms, t, h, nsteps, acc):
    """Advance ``nsteps`` implicit-midpoint steps of size ``h`` from ``t``; returns the new time.

    A step whose Newton iteration fails is retried as 2, 4, …, ``MAX_SPLIT`` substeps.
    """
    n = q.shape[0]
    cd = free_damping(damp, minv)
    work = np.empty((14, n))
    saved = np.empty((3, n))
    for _ in range(nsteps):
        if not step(args, terms, minv, damp, cd, q, v, f, t, h, acc, work, 0.0):
            saved[0], saved[1], saved[2] = q, v, f
            ledger = (acc[ACC_DISSIPATED], acc[ACC_WORK])
            sub, ok = 2, False
            while sub <= MAX_SPLIT and not ok:
                q[:], v[:], f[:] = saved[0], saved[1], saved[2]
                acc[ACC_DISSIPATED], acc[ACC_WORK] = ledger
                ok = True
                for j in range(sub):
                    if not step(args, terms, minv, damp, cd, q, v, f, t + j * h / sub, h / sub, acc, work, 0.0):
                        ok = False
                        break
                sub *= 2
            if not ok:
                q[:] = np.nan
                if acc.shape[0] > ACC_FAILED:
                    acc[ACC_FAILED] += 1
                return t + h
        t += h
    return t
