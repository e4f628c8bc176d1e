"""PEFRL: 4th-order symplectic splitting (Omelyan, Mryglod & Folk, Comput. Phys. Commun. 146,
188 (2002), "position-extended Forest–Ruth-like"), with damping by exact flows (PHYSICS.md §3).

One step of size h alternates drifts D(τ): q ← q + τ v and kicks K(τ): v ← v + τ F(q)/m,

    D(ξh) K((1−2λ)h/2) D(χh) K(λh) D((1−2(χ+ξ))h) K(λh) D(χh) K((1−2λ)h/2) D(ξh),
    ξ = 0.1786178958448091, λ = −0.2123418310626054, χ = −0.06626458266981849,

four force evaluations per step, linear stability limit h ω_max < 2.9895 (the harmonic
oscillator's |trace| ≤ 2). Time advances in the drifts, so applied forces and prescribed DOFs
are evaluated at the stage times.

Damping: the kick flow with on-site viscous damping, v' = F(q)/m − γ v at frozen q, is solved
exactly, v ← e^{−γτ} v + τ φ(γτ) F/m with φ(x) = (1 − e^{−x})/x. It replaces the kick, so the
composition of two exact flows keeps 4th order (splitting the damping off symmetrically around
the whole step would give 2nd order). Velocity-dependent forces between DOFs (dashpots) and
ground friction make the frozen-q kick flow coupled; it is then integrated by one RK4 step of
its own (no extra model-force evaluations, still 4th order). The step is symplectic only
without damping. The energy ledger uses the trapezoid rule over each step (2nd order).
"""

from __future__ import annotations

import math

import numpy as np

from flexmm._jit import jit
from flexmm.integrators.common import (
    ACC_FEVALS,
    ACC_STEPS,
    applied_power,
    apply_prescribed,
    damping_power,
    free_damping,
    has_velocity_terms,
    position_forces,
    velocity_forces,
)

XI = 0.1786178958448091
LAM = -0.2123418310626054
CHI = -0.06626458266981849
DRIFTS = (XI, CHI, 1.0 - 2.0 * (CHI + XI), CHI, XI)
KICKS = (0.5 * (1.0 - 2.0 * LAM), LAM, LAM, 0.5 * (1.0 - 2.0 * LAM))


@jit
def _kick_factors(minv, damp, tau):
    """e = exp(−γτ), g = τ φ(γτ)/m per DOF for the exact damped kick v ← e v + g F."""
    n = minv.shape[0]
    e = np.empty(n)
    g = np.empty(n)
    for k in range(n):
        x = damp[k] * minv[k] * tau
        e[k] = math.exp(-x)
        g[k] = minv[k] * tau * (1.0 if x == 0.0 else -math.expm1(-x) / x)
    return e, g


@jit
def _kick_exact(v, f, e, g):
    for k in range(v.shape[0]):
        v[k] = e[k] * v[k] + g[k] * f[k]


@jit
def _kick_undamped(v, f, minv, tau):
    for k in range(v.shape[0]):
        v[k] += tau * minv[k] * f[k]


@jit
def _velocity_rhs(vv, fp, minv, damp, terms, out, gbuf):
    """out = M⁻¹(F_q + G(vv)) − γ vv with G the dashpot and friction forces."""
    gbuf[:] = 0.0
    velocity_forces(vv, gbuf, terms[2], terms[3], terms[4], terms[5], terms[7])
    for k in range(vv.shape[0]):
        out[k] = minv[k] * (fp[k] + gbuf[k] - damp[k] * vv[k])


@jit
def _kick_rk4(v, fp, minv, damp, terms, tau, work):
    """Kick flow at frozen q with velocity-dependent forces: one RK4 step of size τ."""
    vs, k1, k2, k3, k4, gbuf = work[0], work[1], work[2], work[3], work[4], work[5]
    _velocity_rhs(v, fp, minv, damp, terms, k1, gbuf)
    for k in range(v.shape[0]):
        vs[k] = v[k] + 0.5 * tau * k1[k]
    _velocity_rhs(vs, fp, minv, damp, terms, k2, gbuf)
    for k in range(v.shape[0]):
        vs[k] = v[k] + 0.5 * tau * k2[k]
    _velocity_rhs(vs, fp, minv, damp, terms, k3, gbuf)
    for k in range(v.shape[0]):
        vs[k] = v[k] + tau * k3[k]
    _velocity_rhs(vs, fp, minv, damp, terms, k4, gbuf)
    for k in range(v.shape[0]):
        v[k] += tau / 6.0 * (k1[k] + 2.0 * (k2[k] + k3[k]) + k4[k])


@jit
def _ledger_rates(v, t, cd, terms, dissipative):
    diss = damping_power(v, cd, terms[2], terms[3]) if dissipative else 0.0
    return diss, applied_power(v, t, terms[4], terms[5], terms[6], terms[7])


@jit(cache=False)  # takes the model's force kernel (see flexmm._jit)
def pefrl_advance(force, args, q, v, f, minv, damp, terms, t, h, nsteps, acc):
    """Advance ``nsteps`` PEFRL steps of size ``h`` from ``t``; returns the new time.

    ``f`` is scratch (the last kick's force); ``acc`` as in ``common.ACC_*``.
    """
    con_ij, con_prm, dash_ij, dash_c, drv_dof, drv_mode, drv_shape, drv_prm = terms
    n = q.shape[0]
    cd = free_damping(damp, minv)
    damped = False
    for k in range(n):
        damped = damped or damp[k] * minv[k] != 0.0
    vdep = has_velocity_terms(terms)
    dissipative = damped or dash_ij.shape[0] > 0
    e1, g1 = _kick_factors(minv, damp, KICKS[0] * h)
    e2, g2 = _kick_factors(minv, damp, KICKS[1] * h)
    work = np.empty((6, n if vdep else 0))
    d0, p0 = _ledger_rates(v, t, cd, terms, dissipative)
    for _ in range(nsteps):
        ts = t
        for s in range(5):
            c = DRIFTS[s] * h
            for k in range(n):
                q[k] += c * v[k]
            ts += c
            if s == 4:
                break
            apply_prescribed(q, v, ts, drv_dof, drv_mode, drv_shape, drv_prm)
            force(q, args, f)
            position_forces(q, ts, f, con_ij, con_prm, drv_dof, drv_mode, drv_shape, drv_prm)
            tau = KICKS[s] * h
            if vdep:
                _kick_rk4(v, f, minv, damp, terms, tau, work)
            elif damped:
                if s == 0 or s == 3:
                    _kick_exact(v, f, e1, g1)
                else:
                    _kick_exact(v, f, e2, g2)
            else:
                _kick_undamped(v, f, minv, tau)
        t += h
        apply_prescribed(q, v, t, drv_dof, drv_mode, drv_shape, drv_prm)
        d1, p1 = _ledger_rates(v, t, cd, terms, dissipative)
        acc[0] += 0.5 * h * (d0 + d1)
        acc[1] += 0.5 * h * (p0 + p1)
        d0, p0 = d1, p1
    if acc.shape[0] > ACC_STEPS:
        acc[ACC_FEVALS] += 4 * nsteps
        acc[ACC_STEPS] += nsteps
    return t
