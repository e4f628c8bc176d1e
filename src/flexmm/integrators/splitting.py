"""Symplectic splittings of drifts and kicks, with damping by exact flows (docs/physics.md §3).

``split_step`` is one step of any splitting given its coefficients as data (PEFRL below;
Blanes–Moan's 6th-order method, ``composition``): ``splitting_advance`` is the engine's loop
around it, compiled once per argument types for every splitting (``make_splitting_advance``
binds a method's coefficients), and the gradient's sweeps (``design.splitting``) step with it too.

PEFRL: 4th-order symplectic splitting (Omelyan, Mryglod & Folk, Comput. Phys. Commun. 146,
188 (2002), "position-extended Forest–Ruth-like").

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
without damping. The energy ledger: the work of prescribed displacements and applied forces is
accumulated at the kicks, from each kick's own stage force (``common.stage_power``: time as a
coordinate of an extended phase space, whose momentum the splitting integrates like any other,
to the method's order); the dissipated energy and the friction's work use the trapezoid rule over
each step (2nd order).
"""

from __future__ import annotations

import math

import numpy as np

from flexmm._jit import jit
from flexmm.models.hinge import param
from flexmm.models.kernels import model_force
from flexmm.integrators.common import (
    ACC_DISSIPATED,
    ACC_WORK,
    ACC_FEVALS,
    ACC_STEPS,
    applied_force_energy,
    apply_prescribed,
    damping_power,
    free_damping,
    friction_power,
    held_dashpot_power,
    has_velocity_terms,
    position_forces,
    stage_power,
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
def _velocity_rhs(vv, fp, minv, damp, terms, out, gbuf):
    """out = M⁻¹(F_q + G(vv)) − γ vv with G the dashpot and friction forces."""
    gbuf[:] = 0.0
    velocity_forces(vv, gbuf, terms.dash_ij, terms.dash_c, terms.drv_dof, terms.drv_mode, terms.drv_prm)
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
def kick_factors(kicks, minv, damp, h):
    """(E, G), (M + 1, ndof): e_s, g_s of every kick s (``_kick_factors``; rows of zero kicks
    e = 1, g = 0, unused)."""
    n = minv.shape[0]
    E = np.ones((kicks.shape[0], n))
    G = np.zeros((kicks.shape[0], n))
    for s in range(kicks.shape[0]):
        if kicks[s] != 0.0:
            E[s], G[s] = _kick_factors(minv, damp, kicks[s] * h)
    return E, G


@jit
def _kick_field(e, g, v, f, c, q, vout, qout):
    """One field of a kick and its drift: v' = e v + g f, q' = q + c v' into vout, qout, or in
    place if they are empty (then no drift if q is empty too: a separate loop each, as a loop
    that reads and writes the same array through two names does not vectorise); e, g scalars or
    columns (``hinge.param``). Undamped (e = 1, g = τ m⁻¹) the kick is v + τ m⁻¹ f bit for bit."""
    if vout.shape[0]:
        for k in range(v.shape[0]):
            x = param(e, k) * v[k] + param(g, k) * f[k]
            vout[k] = x
            qout[k] = q[k] + c * x
    elif q.shape[0]:
        for k in range(v.shape[0]):
            x = param(e, k) * v[k] + param(g, k) * f[k]
            v[k] = x
            q[k] += c * x
    else:
        for k in range(v.shape[0]):
            v[k] = param(e, k) * v[k] + param(g, k) * f[k]


@jit(inline=True)
def kick(E, G, s, v, f, c, q, vout, qout):
    """Kick s and its drift (``_kick_field``) on each field; E, G per field ((M + 1, nf), nf
    fewer than the DOFs: ``design.splitting.field_factors``) or per DOF."""
    n = v.shape[0]
    if E.shape[1] == 0:  # undamped (``advance``): v' = v + g f, the same bits as e = 1, one load fewer
        g = G[s]
        for k in range(n):
            v[k] += g[k] * f[k]
        if q.shape[0]:
            for k in range(n):
                q[k] += c * v[k]
    elif E.shape[1] < n:
        m = n // E.shape[1]
        for i in range(E.shape[1]):
            a, b = i * m, (i + 1) * m
            _kick_field(E[s, i], G[s, i], v[a:b], f[a:b], c, q[a:b], vout[a:b], qout[a:b])
    else:
        _kick_field(E[s], G[s], v, f, c, q, vout, qout)


@jit(inline=True)
def stage_force(args, terms, q, v, t, f):
    """Prescribe the driven DOFs at t, then the position-dependent total force (model, contacts,
    applied forces) at (q, t) into f."""
    apply_prescribed(q, v, t, terms.drv_dof, terms.drv_mode, terms.drv_shape, terms.drv_prm)
    model_force(q, args, f)
    position_forces(q, t, f, terms.con_ij, terms.con_prm, terms.drv_dof, terms.drv_mode, terms.drv_shape,
                    terms.drv_prm)


@jit(inline=True)
def split_step(args, terms, kicks, drifts, E, G, slot, fsal, q, v, f, t, tf, h, FS, acc, minv, damp, work):
    """One step of the splitting K(k₀h) D(d₀h) … D(d_{M−1}h) K(k_M h) in place from t; returns
    (t + h, the stage time of the force left in f).

    Each kick (``kick``: kick s with the factors E, G of row ``slot[s]``, ``kick_factors``; with
    velocity-dependent terms, ``work`` (6, ndof) scratch, else (6, 0), by its RK4 flow with
    ``minv``, ``damp``), then its drift. The stage forces (``stage_force``) go to the rows of FS
    (stage forces, ndof: kept for the gradient's reverse sweep, the carried force copied to f)
    if it has rows, else to f. ``acc`` (``common.ACC_*``; empty: no ledger) gains each kick's
    work from its stage force, at the stage time ``tf`` of the force in f. The one step of the
    engine's ``advance`` and of the gradient's sweeps (``design.splitting``).
    """
    n = q.shape[0]
    M = drifts.shape[0]
    keep = FS.shape[0] > 0
    ledger = acc.shape[0] > ACC_WORK
    vdep = work.shape[1] > 0
    ts = t
    fk = f
    for s in range(M + 1):
        c = drifts[s] * h if s < M else 0.0
        if kicks[s] != 0.0:
            if ledger:
                _kick_work(q, fk, tf, terms, kicks[s] * h, acc)
            if vdep:
                _kick_rk4(v, fk, minv, damp, terms, kicks[s] * h, work)
            else:
                kick(E, G, slot[s], v, fk, 0.0, q[:0], q[:0], q[:0])
        if s == M:
            break
        for k in range(n):
            q[k] += c * v[k]
        ts += c
        if s == M - 1 and not fsal:
            break  # a drift-first method ends with this drift
        fk = FS[s] if keep else f
        stage_force(args, terms, q, v, ts, fk)
        tf = ts
    if fsal and keep:
        f[:] = fk
    t1 = t + h
    apply_prescribed(q, v, t1, terms.drv_dof, terms.drv_mode, terms.drv_shape, terms.drv_prm)
    return t1, tf


@jit
def _ledger_rates(v, cd, terms, dissipative):
    """Rates the trapezoid rule integrates over a step: dissipation, the friction's work and that of
    the prescribed displacements through dashpots."""
    if not dissipative:
        return 0.0, friction_power(v, terms.drv_dof, terms.drv_mode, terms.drv_prm)
    work = held_dashpot_power(v, terms.dash_ij, terms.dash_c, terms.drv_dof, terms.drv_mode)
    return (damping_power(v, cd, terms.dash_ij, terms.dash_c),
            work + friction_power(v, terms.drv_dof, terms.drv_mode, terms.drv_prm))


@jit
def _kick_work(q, f, ts, terms, tau, acc):
    """Work of the prescribed displacements and applied forces over a kick of size τ whose force
    ``f`` is that of stage time ``ts`` (``common.stage_power``)."""
    if terms.drv_dof.shape[0] > 0:
        acc[ACC_WORK] += tau * stage_power(q, f, ts, terms.drv_dof, terms.drv_mode, terms.drv_shape, terms.drv_prm)


@jit
def splitting_advance(kicks, drifts, values, slot, fsal, args, q, v, f, minv, damp, terms, t, h, nsteps, acc):
    """Advance ``nsteps`` steps of size ``h`` from ``t`` of the splitting with coefficients
    ``kicks``, ``drifts`` (``split_step``; ``values`` the distinct kick coefficients and ``slot``
    each kick's index among them, ``fsal`` whether it is kick-first); returns the new time.

    The coefficients are data, so every splitting runs the one compiled loop per argument types
    (``make_splitting_advance`` binds them). ``f`` is scratch (the last kick's force); ``acc`` as
    in ``common.ACC_*``.
    """
    drv_dof, drv_mode, drv_shape, drv_prm = terms.drv_dof, terms.drv_mode, terms.drv_shape, terms.drv_prm
    n = q.shape[0]
    cd = free_damping(damp, minv)
    damped = False
    for k in range(n):
        damped = damped or damp[k] * minv[k] != 0.0
    vdep = has_velocity_terms(terms)
    dissipative = damped or terms.dash_ij.shape[0] > 0
    E, G = kick_factors(values, minv, damp, h)  # a row per distinct kick (less to stream)
    if not damped:
        E = E[:, :0]  # e = 1: ``kick``'s undamped loop
    work = np.empty((6, n if vdep else 0))
    d0, p0 = _ledger_rates(v, cd, terms, dissipative)
    acc[ACC_WORK] -= applied_force_energy(q, t, drv_dof, drv_mode, drv_shape, drv_prm)
    if fsal:
        stage_force(args, terms, q, v, t, f)
    tf = t  # stage time of the force in f
    no_stages = np.empty((0, n))
    for _ in range(nsteps):
        t, tf = split_step(args, terms, kicks, drifts, E, G, slot, fsal, q, v, f, t, tf, h, no_stages, acc, minv,
                           damp, work)
        d1, p1 = _ledger_rates(v, cd, terms, dissipative)
        acc[ACC_DISSIPATED] += 0.5 * h * (d0 + d1)
        acc[ACC_WORK] += 0.5 * h * (p0 + p1)
        d0, p0 = d1, p1
    acc[ACC_WORK] += applied_force_energy(q, t, drv_dof, drv_mode, drv_shape, drv_prm)
    if acc.shape[0] > ACC_STEPS:
        evals = drifts.shape[0] if fsal else drifts.shape[0] - 1
        acc[ACC_FEVALS] += evals * nsteps + (1 if fsal else 0)
        acc[ACC_STEPS] += nsteps
    return t


class SplittingAdvance:
    """The ``advance(args, q, v, f, minv, damp, terms, t, h, nsteps, acc) -> t`` of one splitting:
    ``splitting_advance`` with its coefficients bound (``make_splitting_advance``); other
    attributes (numba's ``signatures``, ``stats``) are those of the compiled loop."""

    def __init__(self, kicks: tuple, drifts: tuple):
        self.kicks, self.drifts = np.array(kicks), np.array(drifts)
        values = tuple(dict.fromkeys(kicks))  # the distinct kick coefficients, and each kick's
        self.values = np.array(values)
        self.slot = np.array([values.index(c) for c in kicks], dtype=np.int64)
        self.fsal = kicks[0] != 0.0
        self.__name__ = "splitting_advance"

    def __call__(self, args, q, v, f, minv, damp, terms, t, h, nsteps, acc):
        return splitting_advance(self.kicks, self.drifts, self.values, self.slot, self.fsal, args, q, v, f, minv,
                                 damp, terms, t, h, nsteps, acc)

    def __getattr__(self, name):
        return getattr(splitting_advance, name)


def make_splitting_advance(kicks: tuple, drifts: tuple) -> SplittingAdvance:
    """The ``advance`` of the splitting K(k₀h) D(d₀h) K(k₁h) … D(d_{m−1}h) K(k_m h).

    ``kicks`` has one more entry than ``drifts``. A drift-first method (PEFRL) has k₀ = k_m = 0
    and m − 1 force evaluations per step; a kick-first one (a composition of velocity Verlet
    steps, an SRKN method) reuses the force after its last drift for the next step's first kick
    (first same as last): m evaluations per step, plus one at the start of each call. Kicks are
    the exact damped flows of the module docstring (an RK4 kick with dashpots or friction).
    """
    kicks = tuple(float(c) for c in kicks)
    drifts = tuple(float(c) for c in drifts)
    if len(kicks) != len(drifts) + 1:
        raise ValueError("a splitting needs one kick more than drifts (pad with zero kicks)")
    if kicks[0] == 0.0 and kicks[-1] != 0.0:
        raise ValueError("a drift-first splitting must also end with a drift (last kick 0)")
    return SplittingAdvance(kicks, drifts)


pefrl_advance = make_splitting_advance((0.0, *KICKS, 0.0), DRIFTS)
