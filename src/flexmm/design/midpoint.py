"""Compiled forward (with checkpoints, or every state: the replay), reverse and tangent sweeps of
the implicit midpoint rule (``integrators.implicit``, docs/physics.md §3).

One step from (q, v) at t, with held DOFs H (m⁻¹ = 0: fixed, or prescribed by g) and free DOFs:

    V_H = (q̂_H − q_H)/h,   q̂_H = g(t + h) on prescribed DOFs, q_H on fixed ones,
    R(V) = M (V − v) − (h/2) (F(Q, V, t + h/2; p) − c V) = 0 on the free DOFs,  Q = q + (h/2) V,
    q' = q + h V,   v' = 2V − v,   [q'_D, v'_D] ← [g(t + h), ġ(t + h)],

F the total force (model, contacts, applied forces at Q; dashpots, ground friction at V). The
forward step is the engine's (``implicit.step``, the one the engine's ``midpoint_advance``
takes) with its Newton–Krylov iteration run to the fixed relative residual ``NEWTON_RTOL``
(round-off) instead of the engine's adaptive one, so the computed V is the root of R to
rounding and the step is the exact implicit map differentiated here. Its Jacobian is
J = ∂R/∂V_free = M + (h²/4) K + (h/2) C_v, with K = −∂F/∂Q and C_v = c − ∂F/∂V; both are
symmetric (F = −∇E for the model and contacts; dashpots are symmetric, friction diagonal), so
Jᵀ = J.

The reverse of a step, given the adjoints (λq', λv') of its end (after the prescription's
reverse, which sends λ of the overwritten q'_D, v'_D to the drive parameters):

    λV = h λq' + 2 λv',   λq = λq',   λv = −λv',
    J μ = λV_free                         (one linear solve: ``_solve``, CG with exact Hessian-
                                           vector products: ``sweeps._force_adjoint``'s)
    w = (h/2) μ:  λq += (∂F/∂Q)ᵀ w,  ∂J/∂p += (∂F/∂p)ᵀ w   (model, contacts, drives at t + h/2;
                  dashpots, friction: (∂F/∂V)ᵀ w, their parameters),
    free DOFs:    λv += M μ,  ∂J/∂m⁻¹ += μ ⊙ (V − v) M²,  ∂J/∂c −= (h/2) μ ⊙ V,
    held DOFs:    λV_H += (h/2) (∂F/∂Q)ᵀ w + (∂F/∂V)ᵀ w, then λq_H −= λV_H/h and λq̂_H = λV_H/h
                  goes to the drive parameters (prescribed) or back to λq_H (fixed).

(−∂R/∂x)ᵀ μ for every input x: the implicit-function theorem, dV/dx = −J⁻¹ ∂R/∂x.) ``tangent``
is the forward counterpart: J dV_free = −(∂R/∂x) dx, one solve per step and direction.

A state is (q, v); the force recorded with it is the total force F(q, v, t) there, one more
evaluation per recorded step (the engine carries the midpoint force between steps only as its
Newton predictor: kept in the checkpoints so that a replay repeats the run bit for bit).
"""

from __future__ import annotations

import math

import numpy as np

from flexmm._jit import jit
from flexmm.design.sweeps import (
    _checkpoint,
    _force_adjoint,
    _force_tangent,
    _inject,
    _record,
)
from flexmm.design.terms import (
    prescribed_adjoint,
    prescribed_tangent,
    velocity_adjoint,
    velocity_tangent,
)
from flexmm.integrators.common import apply_prescribed, free_damping, total_force
from flexmm.integrators.implicit import step

#: the Newton iteration's relative residual tolerance in differentiated runs (the engine's
#: adaptive one loosens to 1e-6 at large steps; this is a few hundred roundings of its terms)
NEWTON_RTOL = 1e-13
#: the adjoint's and tangent's linear solves: relative residual (2-norm, the CG recursion's)
SOLVE_RTOL = 1e-15
#: ... accepted after the iteration limit if below this (rounding stalls the recursion)
SOLVE_ACCEPT = 1e-11


@jit
def _jv(args, terms, minv, damp, Q, V, tm, h, x, out, y, mv, dg, ddg):
    """out = J x on the free DOFs (x zero on held ones; out zero there); y: scratch. The
    Hessian-vector product is the force adjoint's (K is symmetric) in the run's ``form`` (a
    chain's or grid sheet's columns: 2–3× cheaper than the model's tangent kernel); ``mv`` =
    (that form, parameter-adjoint sinks g1, g2, gcon, gdrv, zero dashpot and drive directions)."""
    n = x.shape[0]
    form, s1, s2, sc, sd, zp, zd = mv
    for k in range(n):
        y[k] = 0.5 * h * x[k]
        out[k] = 0.0
    _force_adjoint(args, terms, Q, tm, y, out, s1, s2, sc, sd, dg, ddg, form, False)
    velocity_tangent(V, x, out, terms.dash_ij, terms.dash_c, zp, terms.drv_dof, terms.drv_mode, terms.drv_prm, zd)
    for k in range(n):
        if minv[k] > 0.0:
            out[k] = x[k] / minv[k] - 0.5 * h * (out[k] - damp[k] * x[k])
        else:
            out[k] = 0.0


@jit
def _solve(args, terms, minv, damp, Q, V, tm, h, b, x, W, mv):
    """x = J⁻¹ b (b zero on held DOFs) by conjugate gradients preconditioned with the diagonal
    M + (h/2) c, to ``SOLVE_RTOL``; J is symmetric (module docstring). Returns the iterations
    taken, or −1 if it did not converge (an indefinite J, compression past buckling, may not).
    W: scratch (5, n); ``mv``: as ``_jv``'s (t_m = t + h/2)."""
    n = b.shape[0]
    r, z, p, Ap, y = W[0], W[1], W[2], W[3], W[4]
    dg = np.empty(4)
    ddg = np.empty(4)
    b2 = 0.0
    for k in range(n):
        x[k] = 0.0
        r[k] = b[k]
        b2 += b[k] * b[k]
    if b2 == 0.0:
        return 0
    rz = 0.0
    for k in range(n):
        z[k] = r[k] / (1.0 / minv[k] + 0.5 * h * damp[k]) if minv[k] > 0.0 else 0.0
        p[k] = z[k]
        rz += r[k] * z[k]
    tol2 = SOLVE_RTOL * SOLVE_RTOL * b2
    r2 = b2
    for it in range(1, 10 * n + 201):
        _jv(args, terms, minv, damp, Q, V, tm, h, p, Ap, y, mv, dg, ddg)
        pap = 0.0
        for k in range(n):
            pap += p[k] * Ap[k]
        if pap == 0.0 or not math.isfinite(pap):
            break
        alpha = rz / pap
        r2 = 0.0
        for k in range(n):
            x[k] += alpha * p[k]
            r[k] -= alpha * Ap[k]
            r2 += r[k] * r[k]
        if r2 <= tol2:
            return it
        rz_new = 0.0
        for k in range(n):
            z[k] = r[k] / (1.0 / minv[k] + 0.5 * h * damp[k]) if minv[k] > 0.0 else 0.0
            rz_new += r[k] * z[k]
        beta = rz_new / rz
        rz = rz_new
        for k in range(n):
            p[k] = z[k] + beta * p[k]
    return 10 * n + 200 if r2 <= SOLVE_ACCEPT * SOLVE_ACCEPT * b2 else -1


@jit
def _record_state(args, terms, q, v, t, fr, obs, Rq, Rv, Rf, j):
    """Record (q, v, F(q, v, t))[obs] (the total force at the state, into fr)."""
    total_force(args, q, v, t, fr, terms)
    _record(q, v, fr, obs, Rq, Rv, Rf, j)


@jit
def forward(args, terms, minv, damp, rtol, q, v, f, t, h, nsteps, seg, stride, obs, CQ, CV, CF, CT, SW,
            Rq, Rv, Rf):
    """Run ``nsteps`` midpoint steps from (q, v, f, t) (f: the total force at the start, the
    first predictor) in place; checkpoint (q, v, f, t) every ``seg`` steps, record every
    ``stride`` steps, keep each step's midpoint velocity V in the rows of SW if it has any.
    Returns (t, the first step whose Newton iteration failed or −1)."""
    n = q.shape[0]
    cd = free_damping(damp, minv)
    work = np.empty((14, n))
    acc = np.zeros(2)  # the ledger only (no counters)
    fr = np.empty(n)
    keep = SW.shape[0] > 0
    for k in range(nsteps + 1):
        if k % seg == 0:
            _checkpoint(q, v, f, t, CQ, CV, CF, CT, k // seg)
        if k % stride == 0:
            if k == 0:
                _record(q, v, f, obs, Rq, Rv, Rf, 0)
            else:
                _record_state(args, terms, q, v, t, fr, obs, Rq, Rv, Rf, k // stride)
        if k < nsteps:
            if not step(args, terms, minv, damp, cd, q, v, f, t, h, acc, work, rtol):
                return t, k
            if keep:
                SW[k, :] = work[7]
            t += h
    return t, -1


@jit
def reverse(args, terms, minv, damp, SQ, SV, SW, ST, h, k0, nsteps, stride, obs, dRq, dRv, dRf, lq, lv, lf,
            g1, g2, gcon, gdrv, gdash, gminv, gdamp, form, mv):
    """Reverse the steps k0 + nsteps → k0 of a replayed segment (SQ, SV, ST rows 0..nsteps, SW:
    the midpoint velocity of each step, rows 0..nsteps − 1).

    (lq, lv) enter as the adjoints of the state at step k0 + nsteps, lf as that of its recorded
    force; they leave as those at step k0 (its records included). Parameter adjoints accumulate
    (gminv, gdamp: m⁻¹ and c per DOF; the model's in ``form``, ``sweeps._force_adjoint``'s; ``mv``:
    ``_jv``'s). Returns the first step (counted from the run's start)
    whose linear solve did not converge, or −1."""
    n = lq.shape[0]
    dd, dm, ds, dp = terms.drv_dof, terms.drv_mode, terms.drv_shape, terms.drv_prm
    dij, dc = terms.dash_ij, terms.dash_c
    dg = np.empty(4)
    ddg = np.empty(4)
    S = np.empty((6, n))
    Q, lV, mu, w, a, lqe = S[0], S[1], S[2], S[3], S[4], S[5]
    zv = np.zeros(n)
    W = np.empty((5, n))
    for j in range(nsteps, 0, -1):
        t1 = ST[j]
        q1 = SQ[j]
        if (k0 + j) % stride == 0:  # the recorded force F(q_j, v_j, t_j) (λf is 0 between records)
            velocity_adjoint(SV[j], lf, lv, dij, dc, gdash, dd, dm, dp, gdrv)
            _force_adjoint(args, terms, q1, t1, lf, lq, g1, g2, gcon, gdrv, dg, ddg, form, False)
            lf[:] = 0.0
        prescribed_adjoint(t1, lq, lv, dd, dm, ds, dp, gdrv, dg, ddg)
        q, v, V, t = SQ[j - 1], SV[j - 1], SW[j - 1], ST[j - 1]
        for k in range(n):
            Q[k] = q[k] + 0.5 * h * V[k]
            lV[k] = h * lq[k] + 2.0 * lv[k]
            lv[k] = -lv[k]
            a[k] = lV[k] if minv[k] > 0.0 else 0.0
        tm = t + 0.5 * h
        if _solve(args, terms, minv, damp, Q, V, tm, h, a, mu, W, mv) < 0:
            return k0 + j - 1
        for k in range(n):
            w[k] = 0.5 * h * mu[k]
            a[k] = 0.0
            lqe[k] = 0.0
        _force_adjoint(args, terms, Q, tm, w, a, g1, g2, gcon, gdrv, dg, ddg, form, False)
        velocity_adjoint(V, w, lqe, dij, dc, gdash, dd, dm, dp, gdrv)  # lqe: (∂F/∂V)ᵀ w for now
        for k in range(n):
            lq[k] += a[k]
            if minv[k] > 0.0:
                mi = minv[k]
                lv[k] += mu[k] / mi
                gminv[k] += mu[k] * (V[k] - v[k]) / (mi * mi)
                gdamp[k] -= 0.5 * h * mu[k] * V[k]
                lqe[k] = 0.0
            else:
                x = (lV[k] + 0.5 * h * a[k] + lqe[k]) / h
                lq[k] -= x
                lqe[k] = x
        prescribed_adjoint(t + h, lqe, zv, dd, dm, ds, dp, gdrv, dg, ddg)
        for k in range(n):
            lq[k] += lqe[k]  # fixed DOFs: q̂ = q
            zv[k] = 0.0
        _inject(k0 + j - 1, stride, obs, dRq, dRv, dRf, lq, lv, lf)
    return -1


@jit
def _state_force_tangent(args, terms, q, v, t, dq, dv, d1, d2, dcon, ddrv, ddash, out, dg, ddg):
    """The tangent of the total force F(q, v, t) along (dq, dv, parameters) into ``out``."""
    _force_tangent(args, terms, q, t, dq, d1, d2, dcon, ddrv, out, dg, ddg)
    velocity_tangent(v, dv, out, terms.dash_ij, terms.dash_c, ddash, terms.drv_dof, terms.drv_mode, terms.drv_prm,
                     ddrv)


@jit
def tangent(args, terms, minv, damp, rtol, q, v, f, t, h, nsteps, stride, obs, D1, D2, DCON, DDRV, DDASH,
            DMINV, DDAMP, DQ0, DV0, Rq, Rv, Rf, TQ, TV, TF, mv):
    """Forward run with tangents along several directions (index m of every D*), as
    ``sweeps.tangent``; DMINV, DDAMP are the directions of m⁻¹ and c (``mv``: ``_jv``'s). From (q, v) at t
    (prescribed and force computed here). Returns (t, the first step whose Newton iteration or
    linear solve failed, or −1)."""
    n = q.shape[0]
    nd = D1.shape[0]
    dd, dm, ds, dp = terms.drv_dof, terms.drv_mode, terms.drv_shape, terms.drv_prm
    dg = np.empty(4)
    ddg = np.empty(4)
    dq = DQ0.copy()
    dv = DV0.copy()
    cd = free_damping(damp, minv)
    work = np.empty((14, n))
    acc = np.zeros(2)
    W = np.empty((5, n))
    S = np.empty((10, n))
    q0, v0, dqe, dve, dQ, dVH, b, x, fr, dfr = S[0], S[1], S[2], S[3], S[4], S[5], S[6], S[7], S[8], S[9]
    apply_prescribed(q, v, t, dd, dm, ds, dp)
    total_force(args, q, v, t, f, terms)
    for m in range(nd):
        prescribed_tangent(t, dq[m], dv[m], dd, dm, ds, dp, DDRV[m], dg, ddg)
    for k in range(nsteps + 1):
        if k % stride == 0:
            j = k // stride
            if k == 0:
                _record(q, v, f, obs, Rq, Rv, Rf, 0)
            else:
                _record_state(args, terms, q, v, t, fr, obs, Rq, Rv, Rf, j)
            for m in range(nd):
                _state_force_tangent(args, terms, q, v, t, dq[m], dv[m], D1[m], D2[m], DCON[m], DDRV[m], DDASH[m],
                                     dfr, dg, ddg)
                _record(dq[m], dv[m], dfr, obs, TQ[m], TV[m], TF[m], j)
        if k == nsteps:
            break
        q0[:] = q
        v0[:] = v
        if not step(args, terms, minv, damp, cd, q, v, f, t, h, acc, work, rtol):
            return t, k
        V, Q = work[7], work[8]
        tm = t + 0.5 * h
        t1 = t + h
        for m in range(nd):
            dqe[:] = dq[m]
            prescribed_tangent(t1, dqe, dve, dd, dm, ds, dp, DDRV[m], dg, ddg)
            for i in range(n):
                dVH[i] = 0.0 if minv[i] > 0.0 else (dqe[i] - dq[m, i]) / h
                dQ[i] = dq[m, i] + 0.5 * h * dVH[i]
            _force_tangent(args, terms, Q, tm, dQ, D1[m], D2[m], DCON[m], DDRV[m], b, dg, ddg)
            velocity_tangent(V, dVH, b, terms.dash_ij, terms.dash_c, DDASH[m], dd, dm, dp, DDRV[m])
            for i in range(n):  # −(∂R/∂x) dx with dV_free = 0
                mi = minv[i]
                if mi > 0.0:
                    b[i] = (dv[m, i] / mi + (V[i] - v0[i]) * DMINV[m, i] / (mi * mi)
                            + 0.5 * h * (b[i] - DDAMP[m, i] * V[i]))
                else:
                    b[i] = 0.0
            if _solve(args, terms, minv, damp, Q, V, tm, h, b, x, W, mv) < 0:
                return t, k
            for i in range(n):
                dV = x[i] + dVH[i]
                dq[m, i] += h * dV
                dv[m, i] = 2.0 * dV - dv[m, i]
            prescribed_tangent(t1, dq[m], dv[m], dd, dm, ds, dp, DDRV[m], dg, ddg)
        t = t1
    return t, -1
