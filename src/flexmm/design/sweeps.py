"""Compiled forward, reverse (adjoint) and tangent sweeps of velocity Verlet (docs/physics.md §3).

One step of ``integrators.verlet`` (``verlet.step``: the forward run and the replay take it)
with on-site damping, written with the per-DOF factors K = h/2 m⁻¹, P = 1 − hγ/2,
S = 1/(1 + hγ/2) (γ = c m⁻¹):

    w = P v + K f,   q' = q + h w,   [q'_D, w_D] = [g(t'), ġ(t')]   (prescribed DOFs D),
    f' = F(q', t'),  v' = S (w + K f').

The reverse of a step, given the adjoints (λq, λv, λf) of (q', v', f'):

    λw = S λv,  λf += K S λv,                       ∂J/∂S += λv ⊙ (w + K f'), ∂J/∂K += S λv ⊙ f',
    λq += (∂F/∂q)ᵀ λf,  ∂J/∂p += (∂F/∂p)ᵀ λf,         (model, contacts, applied forces)
    λq_D, λw_D → drive parameters, then zeroed,
    λw += h λq,  λv ← P λw,  λf ← K λw,              ∂J/∂P += λw ⊙ v, ∂J/∂K += λw ⊙ f.

The products with the integrator factors are folded per state: with z = λw (of the step out
of state j) + S λv (of v_j), ∂J/∂K += z ⊙ f_j and ∂J/∂P + S² ∂J/∂S += z ⊙ v_j (as
v_j = S (w + K f_j), prescribed DOFs included), two per-DOF sums from which ∂J/∂m⁻¹ and ∂J/∂c
follow (``gradient.Trajectory.gradient``).

Velocity-dependent external terms V (dashpots between DOFs, ground friction) enter as the
engine takes them (``verlet.step_force``): at the predicted end-of-step velocity u. With G the
rest of the force (model, contacts, applied forces) at (q', t'):

    f_a = G + V(w),   u = S (w + K f_a),   f' = G + V(u),

and the reverse of this part (``_prediction_adjoint``; ∂V/∂u is symmetric) runs between the
closing kick's and the force's:

    λu = (∂V/∂u) λf,  ∂J/∂θ += (∂V/∂θ)ᵀ λf          (θ: dashpot c, friction F₊, v_ε, F₋),
    λw += S λu,  λf_a = K S λu,                      (∂J/∂S, ∂J/∂K folded as above, with u, f_a)
    λw += (∂V/∂w) λf_a,  ∂J/∂θ += (∂V/∂θ)ᵀ λf_a,   then λG = λf + λf_a.

The run keeps each step's f_a with its state (only in runs with velocity terms: four arrays a
state instead of three), and the reverse step takes w and u again from it and the state before
by the forward run's operations (the same bits, no force evaluation); the initial force
G(q0) + V(v0) adds (∂V/∂v)ᵀλf to λv0 (``reverse_initial``).

This is the exact transpose of the discrete step, so gradients agree with finite differences
of the same discrete run to rounding. The objective enters through records of (q, v, f) at
the observed DOFs every ``stride`` steps: their adjoints are added at those steps.
"""

from __future__ import annotations

import platform

import numpy as np
from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic, overload

from flexmm._jit import JIT_OPTIONS, NO_JIT, fma, jit, runtime
from flexmm.design.kernels import (
    N_R,
    U_TH0,
    V_COS,
    V_SIN,
    chain_force_columns,
    chain_reverse_gather,
    chain_reverse_hessian,
    chain_strains,
    chain_uniform_force,
    chain_uniform_gather,
    chain_uniform_hinges,
    chain_uniform_sites,
    model_adjoint,
    model_tangent,
    sheet_grid_adjoint,
    sheet_uniform_adjoint,
)
from flexmm.design.terms import (
    contact_adjoint,
    contact_tangent,
    drive_force_adjoint,
    drive_force_tangent,
    prescribed_adjoint,
    prescribed_tangent,
    velocity_adjoint,
    velocity_tangent,
    waveform_dprm,
)
from flexmm.integrators import verlet
from flexmm.integrators.common import Terms, apply_prescribed, has_velocity_terms, position_forces, total_force
from flexmm.models.hinge import param
from flexmm.models.loads import load_terms


@jit
def initial_force(args, terms, q, v, f, t):
    """Prescribe the driven DOFs at t and fill f with the total force (``Stepper`` does the same)."""
    apply_prescribed(q, v, t, terms.drv_dof, terms.drv_mode, terms.drv_shape, terms.drv_prm)
    total_force(args, q, v, t, f, terms)


@jit
def _record(q, v, f, obs, Rq, Rv, Rf, j):
    for i in range(obs.shape[0]):
        Rq[j, i] = q[obs[i]]
        Rv[j, i] = v[obs[i]]
        Rf[j, i] = f[obs[i]]


@jit
def _checkpoint(q, v, f, t, CQ, CV, CF, CT, c):
    """Keep the state (q, v, f, t) as checkpoint row ``c``."""
    CQ[c, :] = q
    CV[c, :] = v
    CF[c, :] = f
    CT[c] = t


@jit
def forward(args, terms, kick, pre, post, q, v, f, t, h, nsteps, seg, stride, obs, CQ, CV, CF, CT, CA, Rq, Rv, Rf):
    """Run ``nsteps`` from (q, v, f, t) in place; checkpoint every ``seg`` steps (rows of CQ, CV,
    CF, CT; with velocity terms and rows in CA, also the f_a of the step into the state,
    ``verlet.step_force``: what ``reverse`` reads when every state is kept, seg = 1), record
    (q, v, f)[obs] every ``stride`` steps (rows of Rq, Rv, Rf); returns t."""
    g, fa, u = verlet.scratch(terms, q.shape[0])
    keep_fa = fa.shape[0] > 0 and CA.shape[0] > 0
    for k in range(nsteps + 1):
        if k % seg == 0:
            _checkpoint(q, v, f, t, CQ, CV, CF, CT, k // seg)
            if keep_fa and k > 0:
                CA[k // seg, :] = fa
        if k % stride == 0:
            _record(q, v, f, obs, Rq, Rv, Rf, k // stride)
        if k < nsteps:
            t = verlet.step(args, terms, kick, pre, post, q, v, f, t, h, g, fa, u)
    return t


@jit
def replay(args, terms, kick, pre, post, q0, v0, f0, t0, h, nsteps, SQ, SV, SF, ST, SA):
    """States 0..nsteps of a segment from its checkpoint into rows of SQ, SV, SF, ST (with
    velocity terms, the f_a of the step into each later state into SA: ``verlet.step_force``)."""
    q = q0.copy()
    v = v0.copy()
    f = f0.copy()
    t = t0
    g, fa, u = verlet.scratch(terms, q.shape[0])
    for s in range(nsteps + 1):
        SQ[s, :] = q
        SV[s, :] = v
        SF[s, :] = f
        ST[s] = t
        if s > 0 and fa.shape[0] > 0:
            SA[s, :] = fa
        if s < nsteps:
            t = verlet.step(args, terms, kick, pre, post, q, v, f, t, h, g, fa, u)


#: the model part of a reverse step (``_force_adjoint``'s ``form``): ``model_adjoint`` into the
#: tables, a grid sheet's hinge families, a chain-ordered chain's columns
FORM_TABLES, FORM_GRID, FORM_CHAIN = 0, 1, 2


@jit
def _chain_model_force(q, cols, with_kg, r, f, ldof, lval):
    """The model force of a chain-ordered chain from its columns (``chain_force_columns``), zero
    on DOFs past its 2n (a striker's), plus constant loads (``models.loads``: the engine's
    ``chain_loaded_force``, the same bits)."""
    chain_force_columns(q, cols, with_kg, r, f)
    for k in range(2 * cols.shape[1], q.shape[0]):
        f[k] = 0.0
    load_terms(q, (ldof, lval), f, True)


@jit
def _chain_adjoint(q, cols, u, lf, r, acc, lq, ldof, gload, ready):
    """The column form's model part of ``_force_adjoint``: λq += (∂F/∂q)ᵀλf, the hinge and site
    parameters' adjoints into ``acc``, the constant loads' into ``gload``; a uniform chain's
    (``u``: ``kernels.chain_uniform``'s parameters, else empty) by the fused kernels of its
    reverse sweep (``chain_uniform_reverse``), another's by the column kernels (``ready``: r
    already holds the state's strains, from its force)."""
    n = cols.shape[1]
    if u.shape[0]:
        cs, sn = r[V_COS, :n], r[V_SIN, :n]
        chain_uniform_sites(q[n : 2 * n], u[U_TH0], cs, sn)
        chain_uniform_hinges(q, lf, cs, sn, r, acc, u)
        chain_uniform_gather(q, lf, lq, cs, sn, r, acc, u)
    else:
        if not ready:
            chain_strains(q, cols, r)
        chain_reverse_hessian(q, cols, lf, r, acc)
        chain_reverse_gather(q, cols, lf, r, acc, lq)
    for k in range(ldof.shape[0]):
        gload[k] += lf[ldof[k]]


@jit
def _force_adjoint(args, terms, q, t, lf, lq, g1, g2, gcon, gdrv, dg, ddg, form, ready):
    """λq += (∂F/∂q)ᵀλf at (q, t); parameter adjoints of the model, contacts, applied forces.

    ``form`` = (kind, n_cols, θ0, columns, columns, accumulator, accumulator, accumulator,
    scratch, force scratch, load DOFs, load values, load accumulator): FORM_GRID (·, n_cols, θ0,
    x and y columns, their accumulators, θ0's, scratch: ``kernels.sheet_grid_adjoint``),
    FORM_CHAIN (·, lateral stretch?, a uniform chain's parameters or empty,
    ``kernels.chain_columns``, ·, their accumulator, ·, ·, scratch, F at the state: the reverse
    sweep takes the force again, ``ready``: the scratch already holds the state's strains; a
    loaded chain's constant loads, their values' adjoints: ``_chain_adjoint``), FORM_TABLES
    (``model_adjoint`` into g1, g2).
    """
    kind = form[0]
    if kind == FORM_CHAIN:
        _chain_adjoint(q, form[3], form[2], lf, form[8], form[5], lq, form[10], form[12], ready)
    elif kind == FORM_GRID:
        sheet_grid_adjoint(q, form[2], form[1], form[3], form[4], lf, lq, form[5], form[6], form[7], form[8])
    else:
        model_adjoint(q, args, lf, lq, g1, g2)
    contact_adjoint(q, lf, lq, terms.con_ij, terms.con_prm, gcon)
    drive_force_adjoint(t, lf, terms.drv_dof, terms.drv_mode, terms.drv_shape, terms.drv_prm, gdrv, dg, ddg)


@jit
def _inject(k, stride, obs, dRq, dRv, dRf, lq, lv, lf, col=None):
    """At a recorded step k, the objective's adjoints of the records added to the observed DOFs'
    (λq, λv, λf); ``col``: the record column of each entry of ``obs`` (None: entry i is column i;
    a spatial tile's observed DOFs, ``chain_uniform_tiles``)."""
    if k % stride == 0:
        j = k // stride
        for i in range(obs.shape[0]):
            c = i if col is None else col[i]
            lq[obs[i]] += dRq[j, c]
            lv[obs[i]] += dRv[j, c]
            lf[obs[i]] += dRf[j, c]


@jit
def _prediction_adjoint(terms, kick, pre, post, v0, f0, fa, t1, lf, lw, GK, GV, gdrv, gdash, s):
    """Reverse of the velocity terms of the step (·, v0, f0) → (·, ·, f1) (``verlet.step_force``),
    given λf of f1 (``lf``, the S λv part included) and λw so far: λu = (∂V/∂u)ᵀ λf, then
    u = S (w + K f_a) and f_a = G + V(w); λw and the folded factor sums (GK, GV) gain their
    terms, ``lf`` becomes λG = λf + λf_a (what ``_force_adjoint`` takes), and dashpot and
    friction parameters theirs. w and u are taken again, by the forward run's operations (the
    same bits), from the state before the step and the step's f_a the run kept (``fa``);
    ``s``: scratch (4, n)."""
    n = fa.shape[0]
    w, u, lu, fs = s[0], s[1], s[2], s[3]
    dd, dm, dp = terms.drv_dof, terms.drv_mode, terms.drv_prm
    for k in range(n):
        w[k] = pre[k] * v0[k] + kick[k] * f0[k]
    apply_prescribed(fs, w, t1, dd, dm, terms.drv_shape, dp)  # (fs: scratch for the prescribed q)
    for k in range(n):
        u[k] = (w[k] + kick[k] * fa[k]) * post[k]
        lu[k] = 0.0
    velocity_adjoint(u, lf, lu, terms.dash_ij, terms.dash_c, gdash, dd, dm, dp, gdrv)
    for k in range(n):  # u = S (w + K f_a): λw += S λu, λf_a = K S λu (into fs)
        su = post[k] * lu[k]
        lw[k] += su
        GK[k] += su * fa[k]
        GV[k] += su * u[k]
        fs[k] = kick[k] * su
    velocity_adjoint(w, fs, lw, terms.dash_ij, terms.dash_c, gdash, dd, dm, dp, gdrv)
    for k in range(n):
        lf[k] += fs[k]


@jit
def reverse(args, terms, kick, pre, post, SQ, SV, SF, ST, SA, h, k0, nsteps, stride, obs, dRq, dRv, dRf,
            lq, lv, lf, lw, g1, g2, GK, GV, gcon, gdrv, gdash, form):
    """Reverse the steps k0 + nsteps → k0 of a replayed segment (SQ, SV, SF, ST rows 0..nsteps;
    with velocity terms SA: the f_a of the step into each state, ``verlet.step_force``).

    (lq, lv, lf) enter as the adjoints of the state at step k0 + nsteps (objective included)
    and leave as those at step k0 (objective at k0 included); ``lw`` enters as λw of the step
    out of state k0 + nsteps (zero at the end of the run) and leaves as that of the step out of
    k0. Parameter adjoints accumulate; the integrator factors' in the folded form of the module
    docstring (GK, GV; the caller adds the initial state's products). A chain's column form
    without velocity terms takes each state's force again (its replay, ``chain_replay``, keeps
    none); with them it reads the kept force as the other forms do. Subnormal numbers are
    flushed to zero during the sweep, as in ``chain_uniform_reverse``.
    """
    csr = flush_subnormals()
    n = lq.shape[0]
    dg = np.empty(4)
    ddg = np.empty(4)
    dd, dm, ds, dp = terms.drv_dof, terms.drv_mode, terms.drv_shape, terms.drv_prm
    vdep = has_velocity_terms(terms)
    again = form[0] == FORM_CHAIN and not vdep
    scratch = np.empty((4, n if vdep else 0))
    cols, with_kg, r, fc = form[3], form[1] != 0, form[8], form[9]  # (passing the whole tuple on each
    ldof, lval = form[10], form[11]  # step costs a reference count per array)
    for j in range(nsteps, 0, -1):
        q1 = SQ[j]
        v1 = SV[j]
        t1 = ST[j]
        if again:  # the force again (cheaper than keeping it), strains with it
            f1 = fc
            _chain_model_force(q1, cols, with_kg, r, f1, ldof, lval)
            position_forces(q1, t1, f1, terms.con_ij, terms.con_prm, dd, dm, ds, dp)
        else:
            f1 = SF[j]
        for k in range(n):  # the products at state j, then λw = S λv, λf += K S λv
            sl = post[k] * lv[k]
            z = lw[k] + sl
            GK[k] += z * f1[k]
            GV[k] += z * v1[k]
            lw[k] = sl
            lf[k] += kick[k] * sl
        if vdep:  # dashpots, friction at the predicted velocity
            _prediction_adjoint(terms, kick, pre, post, SV[j - 1], SF[j - 1], SA[j], t1, lf, lw, GK, GV, gdrv, gdash,
                                scratch)
        _force_adjoint(args, terms, q1, t1, lf, lq, g1, g2, gcon, gdrv, dg, ddg, form, again)
        prescribed_adjoint(t1, lq, lw, dd, dm, ds, dp, gdrv, dg, ddg)
        for k in range(n):
            x = lw[k] + h * lq[k]
            lw[k] = x
            lv[k] = pre[k] * x
            lf[k] = kick[k] * x
        _inject(k0 + j - 1, stride, obs, dRq, dRv, dRf, lq, lv, lf)
    if csr >= 0:
        swap_mxcsr(csr)


@jit
def reverse_initial(args, terms, q0, v0, t0, lq, lv, lf, g1, g2, gcon, gdrv, gdash, form):
    """Reverse of ``initial_force`` at (q0, v0) (driven DOFs prescribed): (lq, lv) become the
    gradients w.r.t. the given q0, v0."""
    dg = np.empty(4)
    ddg = np.empty(4)
    velocity_adjoint(v0, lf, lv, terms.dash_ij, terms.dash_c, gdash, terms.drv_dof, terms.drv_mode, terms.drv_prm,
                     gdrv)
    _force_adjoint(args, terms, q0, t0, lf, lq, g1, g2, gcon, gdrv, dg, ddg, form, runtime(False))
    prescribed_adjoint(t0, lq, lv, terms.drv_dof, terms.drv_mode, terms.drv_shape, terms.drv_prm, gdrv, dg, ddg)


@jit
def _force_tangent(args, terms, q, t, dq, d1, d2, dcon, ddrv, out, dg, ddg):
    model_tangent(q, args, dq, d1, d2, out)
    contact_tangent(q, dq, out, terms.con_ij, terms.con_prm, dcon)
    drive_force_tangent(t, out, terms.drv_dof, terms.drv_mode, terms.drv_shape, terms.drv_prm, ddrv, dg, ddg)


@jit
def tangent(args, terms, kick, pre, post, q, v, f, t, h, nsteps, stride, obs,
            D1, D2, DK, DP, DS, DCON, DDRV, DDASH, DQ0, DV0, Rq, Rv, Rf, TQ, TV, TF):
    """Forward run with tangents along several parameter directions (index m of every D*).

    From the given (q, v) at t (prescribed and force computed here, as ``initial_force``),
    records the state at the observed DOFs every ``stride`` steps (Rq, Rv, Rf: (samples, obs))
    and its derivatives along each direction (TQ, TV, TF: (dirs, samples, obs)). D1, D2 are the
    directions of the parameter tables, DK, DP, DS of the integrator factors, DCON, DDRV, DDASH
    of the contact, drive (and friction) and dashpot parameters, DQ0, DV0 of the initial state.
    Returns t.
    """
    n = q.shape[0]
    nd = D1.shape[0]
    dg = np.empty(4)
    ddg = np.empty(4)
    dq = DQ0.copy()
    dv = DV0.copy()
    df = np.zeros((nd, n))
    dw = np.empty(n)
    tmp = np.empty(n)
    dd, dm, ds, dp = terms.drv_dof, terms.drv_mode, terms.drv_shape, terms.drv_prm
    dij, dc = terms.dash_ij, terms.dash_c
    g, fa, u = verlet.scratch(terms, n)
    vdep = fa.shape[0] > 0
    dfa = np.empty(fa.shape[0])
    du = np.empty(fa.shape[0])
    apply_prescribed(q, v, t, dd, dm, ds, dp)
    total_force(args, q, v, t, f, terms)
    for m in range(nd):
        prescribed_tangent(t, dq[m], dv[m], dd, dm, ds, dp, DDRV[m], dg, ddg)
        _force_tangent(args, terms, q, t, dq[m], D1[m], D2[m], DCON[m], DDRV[m], df[m], dg, ddg)
        velocity_tangent(v, dv[m], df[m], dij, dc, DDASH[m], dd, dm, dp, DDRV[m])
    w = np.empty(n)
    for k in range(nsteps + 1):
        if k % stride == 0:
            j = k // stride
            _record(q, v, f, obs, Rq, Rv, Rf, j)
            for m in range(nd):
                _record(dq[m], dv[m], df[m], obs, TQ[m], TV[m], TF[m], j)
        if k == nsteps:
            break
        # primal half kick and drift (w kept), tangents of w and q'
        for m in range(nd):
            for i in range(n):
                dw[i] = pre[i] * dv[m, i] + DP[m, i] * v[i] + kick[i] * df[m, i] + DK[m, i] * f[i]
                dq[m, i] += h * dw[i]
            dv[m, :] = dw  # holds dw until the closing kick
        for i in range(n):
            w[i] = pre[i] * v[i] + kick[i] * f[i]
            q[i] += h * w[i]
        t1 = t + h
        verlet.step_force(args, terms, kick, post, q, w, t1, g, f, fa, u)
        for m in range(nd):
            prescribed_tangent(t1, dq[m], dv[m], dd, dm, ds, dp, DDRV[m], dg, ddg)
            _force_tangent(args, terms, q, t1, dq[m], D1[m], D2[m], DCON[m], DDRV[m], tmp, dg, ddg)
            if vdep:  # f_a = G + V(w), u = S (w + K f_a), f' = G + V(u)
                dfa[:] = tmp
                velocity_tangent(w, dv[m], dfa, dij, dc, DDASH[m], dd, dm, dp, DDRV[m])
                for i in range(n):
                    du[i] = DS[m, i] * (w[i] + kick[i] * fa[i]) + post[i] * (
                        dv[m, i] + DK[m, i] * fa[i] + kick[i] * dfa[i])
                velocity_tangent(u, du, tmp, dij, dc, DDASH[m], dd, dm, dp, DDRV[m])
            for i in range(n):
                df[m, i] = tmp[i]
                dv[m, i] = DS[m, i] * (w[i] + kick[i] * f[i]) + post[i] * (
                    dv[m, i] + DK[m, i] * f[i] + kick[i] * tmp[i])
        for i in range(n):
            v[i] = (w[i] + kick[i] * f[i]) * post[i]
        t = t1
    return t


@jit
def apply_prescribed_only(terms, q, v, t):
    """``common.apply_prescribed`` with the terms' drive tables (the start of a run)."""
    apply_prescribed(q, v, t, terms.drv_dof, terms.drv_mode, terms.drv_shape, terms.drv_prm)


# ---------------------------------------------------------------- chain-ordered chains
#
# The same scheme on a chain-ordered rotating-squares chain (``kernels.chain_ordered``; with
# constant loads, contacts and a striker's DOFs past the chain's too) from parameter columns:
# the forward run and the replay step with the column force (bit-identical to ``verlet.step``);
# the replay keeps (q, v) only, and the reverse step takes the force at each state again with
# its Hessian-vector product (cos/sin once per site). With velocity terms the run and replay
# are the general ones (``forward``, ``replay``), and only the reverse step's model part takes
# the column form (``_chain_adjoint``; a uniform chain's by its fused kernels). The
# integrator-factor adjoints are folded: with z = λw(step j) + S λv(into j), the products at
# state j are ∂J/∂K += z ⊙ f_j and ∂J/∂P + S² ∂J/∂S += z ⊙ v_j (v_j = S (w + K f_j)), so two
# per-DOF accumulators GK, GV (``gradient.Trajectory.gradient`` turns them into m⁻¹, c).


@jit
def _chain_open(q, v, f, kick, pre, h):
    """Opening half kick and drift (v becomes the half-kicked w); factors: columns or scalars."""
    for k in range(q.shape[0]):
        v[k] = param(pre, k) * v[k] + param(kick, k) * f[k]
        q[k] += h * v[k]


@jit
def _chain_close(v, f, kick, post):
    for k in range(v.shape[0]):
        v[k] = (v[k] + param(kick, k) * f[k]) * param(post, k)


@jit
def _chain_close_open(q, v, f, kick, pre, post, h, sq, sv, sf, store):
    """Closing kick of a step (if ``store``, the new state's q, v copied to sq, sv, and its f to
    sf unless that is empty) and the opening kick and drift of the next in one pass: the
    operations of ``_chain_close`` then ``_chain_open``."""
    if store and sf.shape[0]:
        for k in range(q.shape[0]):
            x = (v[k] + param(kick, k) * f[k]) * param(post, k)
            sq[k] = q[k]
            sv[k] = x
            sf[k] = f[k]
            x = param(pre, k) * x + param(kick, k) * f[k]
            v[k] = x
            q[k] += h * x
    elif store:
        for k in range(q.shape[0]):
            x = (v[k] + param(kick, k) * f[k]) * param(post, k)
            sq[k] = q[k]
            sv[k] = x
            x = param(pre, k) * x + param(kick, k) * f[k]
            v[k] = x
            q[k] += h * x
    else:
        for k in range(q.shape[0]):
            x = (v[k] + param(kick, k) * f[k]) * param(post, k)
            x = param(pre, k) * x + param(kick, k) * f[k]
            v[k] = x
            q[k] += h * x


@jit
def _chain_force_at(cols, with_kg, ldof, lval, terms, q, v, f, t, w):
    """Prescribe the driven DOFs at t, then the total force (the column force, constant loads,
    contacts, applied forces)."""
    apply_prescribed(q, v, t, terms.drv_dof, terms.drv_mode, terms.drv_shape, terms.drv_prm)
    _chain_model_force(q, cols, with_kg, w, f, ldof, lval)
    position_forces(q, t, f, terms.con_ij, terms.con_prm, terms.drv_dof, terms.drv_mode, terms.drv_shape,
                    terms.drv_prm)


@jit
def chain_forward(cols, with_kg, ldof, lval, terms, kick, pre, post, q, v, f, t, h, nsteps, seg, stride, obs,
                  CQ, CV, CF, CT, Rq, Rv, Rf):
    """``forward`` with the column force (the same arithmetic: the same run). Between the states
    it keeps, the closing kick of a step and the opening of the next take one pass."""
    w = np.empty((N_R, cols.shape[1] + 1))
    for k in range(nsteps + 1):
        if k > 0:
            t += h
            _chain_force_at(cols, with_kg, ldof, lval, terms, q, v, f, t, w)
        keep = k % seg == 0 or k % stride == 0 or k == nsteps
        if k > 0 and keep:
            _chain_close(v, f, kick, post)
        if k % seg == 0:
            _checkpoint(q, v, f, t, CQ, CV, CF, CT, k // seg)
        if k % stride == 0:
            _record(q, v, f, obs, Rq, Rv, Rf, k // stride)
        if k < nsteps:
            if keep:
                _chain_open(q, v, f, kick, pre, h)
            elif k > 0:
                _chain_close_open(q, v, f, kick, pre, post, h, q, v, f[:0], runtime(False))
    return t


@jit
def _segment_start(q0, v0, f0, t0, SQ, SV, ST):
    """Copies of a checkpoint's (q, v, f) to step from; its (q, v, t) as row 0 of the segment."""
    SQ[0, :] = q0
    SV[0, :] = v0
    ST[0] = t0
    return q0.copy(), v0.copy(), f0.copy()


@jit
def chain_replay(cols, with_kg, ldof, lval, terms, kick, pre, post, q0, v0, f0, t0, h, nsteps, SQ, SV, ST):
    """States 0..nsteps of a segment from its checkpoint: (q, v, t) into rows of SQ, SV, ST (the
    reverse step takes the force again)."""
    w = np.empty((N_R, cols.shape[1] + 1))
    q, v, f = _segment_start(q0, v0, f0, t0, SQ, SV, ST)
    t = t0
    if nsteps > 0:
        _chain_open(q, v, f, kick, pre, h)
    for s in range(1, nsteps + 1):
        t += h
        _chain_force_at(cols, with_kg, ldof, lval, terms, q, v, f, t, w)
        ST[s] = t
        if s < nsteps:
            _chain_close_open(q, v, f, kick, pre, post, h, SQ[s], SV[s], f[:0], runtime(True))
        else:
            _chain_close(v, f, kick, post)
            SQ[s, :] = q
            SV[s, :] = v


# ---------------------------------------------------------------- uniform chains
#
# The reverse sweep of a uniform chain (``kernels.chain_uniform``): the steps of ``reverse``'s
# FORM_CHAIN branch with the model part from scalar parameters in fused passes
# (``kernels.chain_uniform_*``), and the integrator factors K, P, S as scalars per field, or
# per-DOF columns where they vary (a fixed end), through ``param``. The same gradient to
# rounding (tests/design/test_gradient.py), at about 0.6 of the column sweeps' reverse cost.


@jit
def chain_uniform_replay(u, with_kg, ldof, lval, fac, terms, q0, v0, f0, t0, h, nsteps, SQ, SV, SF, ST, SC, r):
    """``chain_replay`` of a uniform chain (``chain_uniform_reverse``'s ``u``, ``fac``, scratch r):
    the force from scalar parameters (``kernels.chain_uniform_force``; constant loads, contacts
    and applied forces as ``chain_replay``) and the kicks with the
    factors per field, the same operations, so the same states bit for bit. Keeps each state's
    force and cos/sin of θ0+θ too (SF[s], SC[s] = (cos, sin), rows 1..nsteps), which the
    reverse step reads."""
    n = q0.shape[0] // 2
    q, v, f = _segment_start(q0, v0, f0, t0, SQ, SV, ST)
    t = t0
    if nsteps > 0:
        _chain_open(q[:n], v[:n], f[:n], fac[0], fac[4], h)
        _chain_open(q[n:], v[n:], f[n:], fac[1], fac[5], h)
    dd, dm, ds, dp = terms.drv_dof, terms.drv_mode, terms.drv_shape, terms.drv_prm
    for s in range(1, nsteps + 1):
        t += h
        apply_prescribed(q, v, t, dd, dm, ds, dp)
        chain_uniform_force(q, u, with_kg, SC[s, 0], SC[s, 1], r, f)
        load_terms(q, (ldof, lval), f, True)
        position_forces(q, t, f, terms.con_ij, terms.con_prm, dd, dm, ds, dp)
        ST[s] = t
        if s < nsteps:
            _chain_close_open(q[:n], v[:n], f[:n], fac[0], fac[4], fac[2], h, SQ[s, :n], SV[s, :n], SF[s, :n], True)
            _chain_close_open(q[n:], v[n:], f[n:], fac[1], fac[5], fac[3], h, SQ[s, n:], SV[s, n:], SF[s, n:], True)
        else:
            _chain_close(v[:n], f[:n], fac[0], fac[2])
            _chain_close(v[n:], f[n:], fac[1], fac[3])
            SQ[s, :] = q
            SV[s, :] = v
            SF[s, :] = f


#: MXCSR bits: flush subnormal results to zero, treat subnormal inputs as zero (x86 SSE/AVX)
FTZ_DAZ = 0x8040
_X86 = platform.machine().lower() in ("x86_64", "amd64")


@intrinsic
def swap_mxcsr(typingctx, value):
    """Set the x86 floating-point control word (MXCSR) of this thread to ``value``; returns the
    previous one (elsewhere: nothing set, returns −1)."""

    def codegen(context, builder, signature, args):
        if not _X86:
            return ir.Constant(ir.IntType(64), -1)
        i32 = ir.IntType(32)
        fnty = ir.FunctionType(ir.VoidType(), [ir.IntType(8).as_pointer()])
        slot = cgutils.alloca_once(builder, i32)
        ptr = builder.bitcast(slot, ir.IntType(8).as_pointer())
        builder.call(cgutils.get_or_insert_function(builder.module, fnty, "llvm.x86.sse.stmxcsr"), [ptr])
        old = builder.load(slot)
        builder.store(builder.trunc(args[0], i32), slot)
        builder.call(cgutils.get_or_insert_function(builder.module, fnty, "llvm.x86.sse.ldmxcsr"), [ptr])
        return builder.zext(old, ir.IntType(64))

    return types.int64(types.int64), codegen


@jit
def flush_subnormals():
    """Flush subnormal results and inputs to zero on this thread (x86: MXCSR FTZ/DAZ from the
    default word); returns the previous word for ``swap_mxcsr`` to restore (−1 elsewhere)."""
    csr = swap_mxcsr(np.int64(0x1F80))
    if csr >= 0:
        swap_mxcsr(csr | FTZ_DAZ)
    return csr


@jit
def _uniform_update(lq, lv, lf, lw, kick, pre, h):
    """The close of a reverse step on one field: λw += h λq, λv = P λw, λf = K λw."""
    for k in range(lq.shape[0]):
        x = fma(h, lq[k], lw[k])
        lw[k] = x
        lv[k] = param(pre, k) * x
        lf[k] = param(kick, k) * x


@jit
def _field_open(lq, lv, lf, lw, v, f, GK, GV, kick, pre, post, h, close):
    """One field of a uniform chain's or sheet's reverse step's products at the state (v, f):
    λw = S λv, λf += K S λv, with z = λw + S λv: ∂J/∂K += z f, ∂J/∂P + S² ∂J/∂S += z v. If
    ``close``, first the close of the step before (λw += h λq, λv = P λw, λf = K λw) in the same
    pass. K, P, S: scalars or columns."""
    if close:
        for k in range(lq.shape[0]):
            x = fma(h, lq[k], lw[k])
            sl = param(post, k) * (param(pre, k) * x)
            z = x + sl
            GK[k] = fma(z, f[k], GK[k])
            GV[k] = fma(z, v[k], GV[k])
            lw[k] = sl
            lf[k] = param(kick, k) * z
    else:
        for k in range(lq.shape[0]):
            sl = param(post, k) * lv[k]
            z = lw[k] + sl
            GK[k] = fma(z, f[k], GK[k])
            GV[k] = fma(z, v[k], GV[k])
            lw[k] = sl
            lf[k] = fma(param(kick, k), sl, lf[k])


@jit
def _uniform_open(lq, lv, lf, lw, v, f, GK, GV, fac, nf, h, close):
    """``_field_open`` on each of the ``nf`` equal fields of a uniform chain's or sheet's DOFs;
    ``fac``: K per field, then S, then P (scalars or per-field columns)."""
    n = lq.shape[0] // nf
    for c in range(nf):
        a, b = c * n, (c + 1) * n
        _field_open(lq[a:b], lv[a:b], lf[a:b], lw[a:b], v[a:b], f[a:b], GK[a:b], GV[a:b], fac[c], fac[2 * nf + c],
                    fac[nf + c], h, close)


@jit
def _uniform_close(terms, fac, nf, t1, h, j, k0, stride, obs, dRq, dRv, dRf, lq, lv, lf, lw, gdrv, dg, ddg,
                   col=None):
    """The end of a uniform reverse step: the drives' adjoints, then, unless the objective
    enters before the next step's factor pass (which then folds the close in: returns True),
    the close on each field and the objective's injection."""
    dd, dm, ds, dp = terms.drv_dof, terms.drv_mode, terms.drv_shape, terms.drv_prm
    if dd.shape[0]:
        drive_force_adjoint(t1, lf, dd, dm, ds, dp, gdrv, dg, ddg)
        prescribed_adjoint(t1, lq, lw, dd, dm, ds, dp, gdrv, dg, ddg)
    k = k0 + j - 1
    pending = j > 1 and k % stride != 0
    if not pending:
        n = lq.shape[0] // nf
        for c in range(nf):
            a, b = c * n, (c + 1) * n
            _uniform_update(lq[a:b], lv[a:b], lf[a:b], lw[a:b], fac[c], fac[2 * nf + c], h)
        _inject(k, stride, obs, dRq, dRv, dRf, lq, lv, lf, col)
    return pending


@jit
def chain_uniform_reverse(terms, u, fac, SQ, SV, SF, ST, SC, h, k0, nsteps, stride, obs, dRq, dRv, dRf,
                          lq, lv, lf, lw, GK, GV, gcon, gdrv, acc, r, ldof, gload, col=None):
    """``reverse`` of a uniform chain (the same arguments where they exist; ``u``: its
    parameters, ``fac`` = (K_u, K_θ, S_u, S_θ, P_u, P_θ) scalars or per-field columns, acc the
    column accumulator (N_CA, n), r scratch (N_V, n + 1), SF, SC the replay's forces and
    cos/sin of θ0+θ, SC possibly empty: then taken here; ldof, gload: constant loads' DOFs and
    their values' adjoints). A step is four passes: cos/sin at the
    sites (unless kept); per field, the integrator factors' products (with the close of the step
    before, unless the objective enters between them), ∂J/∂K from the kept force, applied
    forces included (``_field_open``); the hinges (Hessian and parameter products); the sites
    (gathering, site parameters). Contacts, loads and drives as ``reverse``; ``col``: as
    ``_inject``'s.

    Subnormal numbers are flushed to zero during the sweep (x86: MXCSR FTZ/DAZ, restored at the
    end): the adjoint of a long damped run decays through the subnormal range (below 2.2e-308),
    where vectorised arithmetic runs ~1.6× slower (100 units × 1e6 steps,
    benchmarks/run.py gradient); only entries that small change (to zero or near it)."""
    csr = flush_subnormals()
    n = lq.shape[0] // 2
    dg = np.empty(4)
    ddg = np.empty(4)
    pending = False
    for j in range(nsteps, 0, -1):
        q1 = SQ[j]
        if SC.shape[0]:
            cs, sn = SC[j, 0], SC[j, 1]
        else:
            cs, sn = r[V_COS, :n], r[V_SIN, :n]
            chain_uniform_sites(q1[n:], u[U_TH0], cs, sn)
        _uniform_open(lq, lv, lf, lw, SV[j], SF[j], GK, GV, fac, 2, h, pending)
        chain_uniform_hinges(q1, lf, cs, sn, r, acc, u)
        chain_uniform_gather(q1, lf, lq, cs, sn, r, acc, u)
        contact_adjoint(q1, lf, lq, terms.con_ij, terms.con_prm, gcon)
        for k in range(ldof.shape[0]):
            gload[k] += lf[ldof[k]]
        pending = _uniform_close(terms, fac, 2, ST[j], h, j, k0, stride, obs, dRq, dRv, dRf, lq, lv, lf, lw, gdrv,
                                 dg, ddg, col)
    if csr >= 0:
        swap_mxcsr(csr)


# ---------------------------------------------------------------- uniform chains in spatial tiles
#
# On a long uniform chain a segment's replayed states (64 B a unit-step: q, v, f, cos/sin) are
# more than the cache holds well, and the segment is cut short to keep them there (12 steps at
# 10 000 units, 8 at 16 000), which stops the forward run's time blocks often.
# ``chain_uniform_tiles`` runs a segment's replay and reverse sweep one window of sites at a time instead, so segments
# can be longer and a window's states (~4.6 MB for 2180 sites × 33 states) stay in cache: the
# window's checkpoint and adjoints are copied out, replayed and swept back by the same kernels
# as the whole chain (``chain_uniform_replay``, ``chain_uniform_reverse``), and its interior
# written back. A window's ends act as the chain's ends, which is wrong unless they are; the
# error travels one site per step in each sweep (a step's force and adjoint reach the next
# site), so a window takes ``tile_halo(T)`` sites on each side of its interior for a T-step
# segment, and its interior gets the whole chain's bits. Adjoints of the state are written to a
# second set of arrays (the neighbours' windows read the old ones), accumulators (∂J/∂K, ∂J/∂P,
# the parameter columns, the drives) are copied out and back, so each entry is summed in the same
# order as by the whole chain.


def tile_halo(steps: int) -> int:
    """Sites on each side of a window so that its interior is exact after a segment of ``steps``
    steps replayed and swept back: one site a step in each sweep, and one more for the hinge
    that joins the interior's last site to the next."""
    return 2 * steps + 2


def tile_windows(n: int, width: int, halo: int) -> np.ndarray:
    """(tiles, 3) int64: the interior [a, b) and window start a0 of each tile of a chain of n
    sites, interiors ``width`` sites (the last one shorter), windows of one length L = min(n,
    width + 2 halo), held inside the chain (so an end tile's window has its halo on one side,
    twice as wide)."""
    a = np.arange(0, n, width, dtype=np.int64)
    b = np.minimum(a + width, n)
    length = min(n, width + 2 * halo)
    a0 = np.clip(a - halo, 0, n - length)
    return np.stack([a, b, a0], axis=1)


def tile_observed(obs: np.ndarray, n: int, windows: np.ndarray, length: int) -> tuple:
    """The observed DOFs of every tile's window (``length`` sites from a0; DOF d of the chain is
    site d mod n of field d // n): (start, local DOF, record column) int64 arrays, tile t's
    entries at start[t]:start[t + 1], local DOFs numbered as the window's (u..., θ...)."""
    field, site = np.divmod(np.asarray(obs, np.int64), n)
    starts, loc, col = [0], [], []
    for a0 in windows[:, 2]:
        inside = np.flatnonzero((site >= a0) & (site < a0 + length))
        loc.append(field[inside] * length + site[inside] - a0)
        col.append(inside)
        starts.append(starts[-1] + inside.size)
    return (np.array(starts, np.int64), np.concatenate(loc).astype(np.int64),
            np.concatenate(col).astype(np.int64))


@jit
def _window(x, a0, length, out):
    """The window of ``length`` sites from a0 of a chain's per-DOF array x (u..., θ...) into out."""
    n = x.shape[0] // 2
    out[:length] = x[a0 : a0 + length]
    out[length:] = x[n + a0 : n + a0 + length]


@jit
def _interior(x, out, a, b, a0, length):
    """Sites [a, b) of a window (from a0, ``length`` sites) written back to the chain's array out."""
    n = out.shape[0] // 2
    out[a:b] = x[a - a0 : b - a0]
    out[n + a : n + b] = x[length + a - a0 : length + b - a0]


def _cut(fac, a0, length):
    """The integrator factors of a window: themselves if scalars, else each column's sites."""
    if isinstance(fac[0], float):
        return fac
    return tuple(x[a0 : a0 + length] for x in fac)


if not NO_JIT:

    @overload(_cut, jit_options=JIT_OPTIONS)
    def _cut_overload(fac, a0, length):
        if isinstance(fac[0], types.Float):
            return lambda fac, a0, length: fac
        return lambda fac, a0, length: (fac[0][a0 : a0 + length], fac[1][a0 : a0 + length],
                                        fac[2][a0 : a0 + length], fac[3][a0 : a0 + length],
                                        fac[4][a0 : a0 + length], fac[5][a0 : a0 + length])


@jit
def _window_drives(terms, n, a0, length):
    """The drives of a window's DOFs, numbered as the window's, and their rows in ``terms``."""
    dd = terms.drv_dof
    rows = np.empty(dd.shape[0], np.int64)
    m = 0
    for d in range(dd.shape[0]):
        site = dd[d] % n
        if a0 <= site < a0 + length:
            rows[m] = d
            m += 1
    rows = rows[:m]
    dof = np.empty(m, np.int64)
    for k in range(m):
        dof[k] = (dd[rows[k]] // n) * length + dd[rows[k]] % n - a0
    local = Terms(terms.con_ij, terms.con_prm, terms.dash_ij, terms.dash_c, dof, terms.drv_mode[rows],
                  terms.drv_shape[rows], terms.drv_prm[rows])
    return local, rows


@jit
def chain_uniform_tiles(u, with_kg, fac, terms, q0, v0, f0, t0, h, k0, nsteps, windows, length, ostart, oloc, ocol,
                        stride, dRq, dRv, dRf, lq, lv, lf, lw, GK, GV, gcon, gdrv, acc, gload, SQ, SV, SF, ST, SC, r):
    """One segment's replay (from its checkpoint q0, v0, f0, t0) and reverse sweep of a uniform
    chain without contacts or loads, tile by tile (``windows``: ``tile_windows``; ``length``
    sites a window; ``ostart``, ``oloc``, ``ocol``: ``tile_observed``); the other arguments as
    ``chain_uniform_reverse``'s (gcon, gload untouched: no contacts, no loads), SQ, SV, SF,
    ST, SC, r a window's (2 × length DOFs)."""
    n = q0.shape[0] // 2
    m = 2 * length
    wq, wv, wf = np.empty(m), np.empty(m), np.empty(m)
    lq1, lv1, lf1, lw1 = np.empty_like(lq), np.empty_like(lv), np.empty_like(lf), np.empty_like(lw)
    wlq, wlv, wlf, wlw, wgk, wgv = np.empty(m), np.empty(m), np.empty(m), np.empty(m), np.empty(m), np.empty(m)
    wacc = np.empty((acc.shape[0], length))
    no_dof = np.empty(0, np.int64)
    no_val = np.empty(0)
    for t in range(windows.shape[0]):
        a, b, a0 = windows[t, 0], windows[t, 1], windows[t, 2]
        local, rows = _window_drives(terms, n, a0, length)
        wfac = _cut(fac, a0, length)
        _window(q0, a0, length, wq)
        _window(v0, a0, length, wv)
        _window(f0, a0, length, wf)
        chain_uniform_replay(u, with_kg, no_dof, no_val, wfac, local, wq, wv, wf, t0, h, nsteps, SQ, SV, SF, ST, SC, r)
        for x, w in ((lq, wlq), (lv, wlv), (lf, wlf), (lw, wlw), (GK, wgk), (GV, wgv)):
            _window(x, a0, length, w)
        wacc[:, :] = acc[:, a0 : a0 + length]
        wdrv = gdrv[rows]  # a copy (indexed by an array)
        o0, o1 = ostart[t], ostart[t + 1]
        chain_uniform_reverse(local, u, wfac, SQ, SV, SF, ST, SC, h, k0, nsteps, stride, oloc[o0:o1], dRq, dRv, dRf,
                              wlq, wlv, wlf, wlw, wgk, wgv, gcon, wdrv, wacc, r, no_dof, gload, ocol[o0:o1])
        for x, w in ((wlq, lq1), (wlv, lv1), (wlf, lf1), (wlw, lw1), (wgk, GK), (wgv, GV)):
            _interior(x, w, a, b, a0, length)
        acc[:, a:b] = wacc[:, a - a0 : b - a0]
        for k in range(rows.shape[0]):
            if a <= terms.drv_dof[rows[k]] % n < b:
                gdrv[rows[k]] = wdrv[k]
    lq[:] = lq1
    lv[:] = lv1
    lf[:] = lf1
    lw[:] = lw1

#
# The reverse sweep of a uniform grid sheet (``kernels.sheet_uniform``): ``reverse``'s steps
# (no contacts, no velocity terms) with the model part from the shared law
# (``kernels.sheet_uniform_adjoint``) and the integrator factors as scalars per field (u, v, θ)
# or per-DOF columns, through ``param``; the close of a step folded into the next step's
# factor pass unless the objective enters between them, as ``chain_uniform_reverse``.


@jit
def sheet_uniform_reverse(terms, p, nc, sgx, sgy, fac, SQ, SV, SF, ST, h, k0, nsteps, stride, obs, dRq, dRv, dRf,
                          lq, lv, lf, lw, GK, GV, gdrv, acc_x, acc_y, acc_t0, r):
    """``reverse`` of a uniform grid sheet (the same arguments where they exist; p, sgx, sgy, r:
    ``kernels.sheet_uniform_adjoint``'s; ``fac`` = (K_u, K_v, K_θ, S_u, S_v, S_θ, P_u, P_v, P_θ)
    scalars or per-field columns). Subnormals flushed to zero as ``chain_uniform_reverse``."""
    csr = flush_subnormals()
    dg = np.empty(4)
    ddg = np.empty(4)
    pending = False
    for j in range(nsteps, 0, -1):
        _uniform_open(lq, lv, lf, lw, SV[j], SF[j], GK, GV, fac, 3, h, pending)
        sheet_uniform_adjoint(SQ[j], lf, lq, p, nc, sgx, sgy, acc_x, acc_y, acc_t0, r)
        pending = _uniform_close(terms, fac, 3, ST[j], h, j, k0, stride, obs, dRq, dRv, dRf, lq, lv, lf, lw, gdrv,
                                 dg, ddg)
    if csr >= 0:
        swap_mxcsr(csr)
