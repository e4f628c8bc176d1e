"""Compiled forward (with checkpoints, or every state: the replay), reverse and tangent sweeps of a
kick/drift splitting (PEFRL, BM6).

One step of ``integrators.splitting.split_step`` (the engine's ``advance`` and the forward sweep
here both take it; a uniform chain's or sheet's: ``uniform_step``) with M drifts and M + 1
kicks (coefficients b_s, a_s; ``SPLITTINGS``) reads, with per-DOF kick factors
e_s = exp(−γτ_s), g_s = τ_s φ(γτ_s)/m (τ_s = b_s h, γ = c m⁻¹, φ(x) = (1 − e^{−x})/x, the
exact damped kick flow; e_s = 1, g_s = τ_s m⁻¹ undamped) and stage times T_s = t + Σ_{r≤s} a_r h:

    for s = 0 … M−1:
        v ← e_s v + g_s f_s                       (kick; skipped where b_s = 0)
        q ← q + a_s h v                           (drift)
        [q_D, v_D] ← [g(T_s), ġ(T_s)];  f_{s+1} = F(q, T_s; p)    (but not after a drift-first
                                                  method's last drift)
    v ← e_M v + g_M f_M                          (kick-first, "first same as last": f_M is f_0
                                                  of the next step)
    [q_D, v_D] ← [g(t + h), ġ(t + h)]

A kick-first method (BM6) carries the force of the step's end to the next step, so a state is
(q, v, f) as in velocity Verlet; a drift-first one (PEFRL) needs no force between steps, and the
force it records, F(q_n, t_n), is one more evaluation at each recorded step, differentiated too.

``reverse`` is the exact transpose of this step: it redoes the step's kicks and drifts from the
state at its start (q, v, f, t), reading the stage forces the replay kept (``forward``'s FS, one
row per force evaluation: PEFRL 4, BM6 11 a step, written there straight by the force) instead
of evaluating them (the same bits; with none kept it evaluates them, one more forward step), the
stage positions and the velocities entering the kicks in (2M + 1) × ndof scratch, and runs back
through them — kick and drift in one pass: x = λv + a_s h λq, ∂J/∂e_s += x ⊙ v, ∂J/∂g_s += x ⊙
f_s accumulated per kick (``GE``, ``GG``; the caller maps them to m⁻¹ and γ,
``kick_factor_gradients``), λf_s = g_s x, λv = e_s x; force: λq += (∂F/∂q)ᵀλf, parameters;
prescription: the adjoints of the overwritten q_D, v_D go to the drive parameters. A
drift-first method's recorded force is reversed only where its adjoint is nonzero (at the
records). The kick factors are scalars per field where they are (``field_factors``: no factor
rows streamed). ``tangent`` is the forward (tangent-linear) counterpart. Velocity-dependent
external terms (dashpots, friction: the engine integrates the kick with them by an RK4 flow)
are not differentiated (``gradient.Trajectory`` refuses them).

The model part of a stage's force and of its adjoint is the model's own (``model_force``;
``sweeps._force_adjoint`` with the run's column form) or, for a uniform chain or grid sheet
(``Uniform``), the shared law as scalars, with the kernels of velocity Verlet's uniform sweeps:
forces by ``kernels.chain_uniform_force`` or the sheet's grid path (``sheet_kernels.grid_x``,
``grid_y``; the model's bits, so still the engine's run), adjoints by
``kernels.chain_uniform_hinges``/``_gather`` or ``kernels.sheet_uniform_adjoint``.

Cost of a gradient (``python benchmarks/run.py gradient_splitting``: 1000-unit chain × 1000
steps, 40 × 20 sheet × 300 steps, lightly damped, every state kept; multiples of the engine's
run of the same integrator, min/median, load 1): PEFRL chain ×2.2/×2.0–2.2, BM6 chain
×2.2–2.3/×2.2, PEFRL sheet ×2.2–2.3/×2.2–2.8, BM6 sheet ×2.0–2.3/×2.1–2.3 (before the uniform
path ×3.5–4.5); the forward run keeping states and stage forces ×0.8–1.0 (the uniform forces
are cheaper than the engine's model force), the reverse sweep ×1.0–1.3.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from flexmm._jit import jit, runtime
from flexmm.design.kernels import (U_TH0, V_COS, V_SIN, W_COS, W_SIN, chain_uniform_force, chain_uniform_gather,
                                   chain_uniform_hinges, chain_uniform_sites, sheet_uniform_adjoint)
from flexmm.design.sweeps import (
    _checkpoint,
    _force_adjoint,
    _force_tangent,
    _inject,
    _record,
    flush_subnormals,
    swap_mxcsr,
)
from flexmm.design.terms import drive_force_adjoint, prescribed_adjoint, prescribed_tangent
from flexmm.integrators import composition
from flexmm.integrators import splitting as engine
from flexmm.integrators.splitting import kick
from flexmm.integrators.common import apply_prescribed, position_forces
from flexmm.models.hinge import param
from flexmm.models.kernels import model_force
from flexmm.models.sheet_kernels import grid_x, grid_y, sheet_angles

#: (kicks, drifts) of the engine's splittings (``integrators.INTEGRATORS``); one kick more than drifts
SPLITTINGS = {
    "pefrl": ((0.0, *engine.KICKS, 0.0), engine.DRIFTS),
    "blanes_moan6": composition.blanes_moan_6(),
}


def coefficients(name: str) -> tuple[np.ndarray, np.ndarray, bool]:
    """(kicks, drifts, fsal) of a splitting: fsal is True for a kick-first method."""
    kicks, drifts = SPLITTINGS[name]
    k = np.array(kicks, float)
    return k, np.array(drifts, float), bool(k[0] != 0.0)


# ---------------------------------------------------------------- the kick factors


def _phi_and_slope(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """φ(x) = (1 − e^{−x})/x and φ'(x) (series below 1e-3, where the closed form cancels)."""
    small = np.abs(x) < 1e-3
    xs = np.where(small, 1.0, x)
    phi = np.where(small, 1.0 - x / 2 + x * x / 6 - x**3 / 24, -np.expm1(-xs) / xs)
    slope = np.where(small, -0.5 + x / 3 - x * x / 8 + x**3 / 30 - x**4 / 144, (np.exp(-xs) - phi) / xs)
    return phi, slope


def kick_factors(kicks: np.ndarray, minv: np.ndarray, damp: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    """(E, G), (M + 1, ndof): e_s and g_s of every kick, the engine's (``splitting.kick_factors``)."""
    return engine.kick_factors(np.asarray(kicks, float), minv, damp, h)


def field_factors(E: np.ndarray, G: np.ndarray, nf: int) -> tuple[np.ndarray, np.ndarray]:
    """E, G as (M + 1, nf) scalars per field if every kick's factors are constant on each of the
    ``nf`` equal fields of DOFs (a chain's u, θ; a sheet's u, v, θ; one field otherwise), so the
    sweeps stream no factors; else unchanged (per DOF: a held DOF's m⁻¹ = 0, graded masses)."""
    m = E.shape[1] // nf
    if m > 1 and all(np.all(X[:, i * m : (i + 1) * m] == X[:, i * m : i * m + 1]) for X in (E, G) for i in range(nf)):
        return np.ascontiguousarray(E[:, ::m]), np.ascontiguousarray(G[:, ::m])
    return E, G


def kick_factor_partials(kicks: np.ndarray, minv: np.ndarray, damp: np.ndarray, h: float) -> tuple:
    """∂e_s/∂m⁻¹, ∂e_s/∂γ', ∂g_s/∂m⁻¹, ∂g_s/∂γ' per kick and DOF ((M + 1, ndof) each), γ' the
    on-site damping coefficient (the raw ``damp``; the rate is γ = γ' m⁻¹)."""
    tau = (kicks * h)[:, None]
    x = damp * minv * tau
    phi, slope = _phi_and_slope(x)
    e = np.exp(-x)
    return (-e * damp * tau, -e * minv * tau, tau * phi + minv * tau * slope * damp * tau,
            minv * tau * slope * minv * tau)


def kick_factor_gradients(kicks, minv, damp, h, GE, GG) -> tuple[np.ndarray, np.ndarray]:
    """(∂J/∂m⁻¹, ∂J/∂γ') from the kick-factor adjoints GE = ∂J/∂e_s, GG = ∂J/∂g_s."""
    de_m, de_c, dg_m, dg_c = kick_factor_partials(kicks, minv, damp, h)
    return (GE * de_m + GG * dg_m).sum(axis=0), (GE * de_c + GG * dg_c).sum(axis=0)


# ---------------------------------------------------------------- the sweeps
#
# Every sweep takes ``uni`` (``Uniform``, built by ``steps.Split.uniform``): the
# model's own kernels, or a uniform chain's or grid sheet's shared law (the module docstring).

#: ``Uniform.kind``: the model's own kernels, a uniform chain, a uniform grid sheet
UNI_NONE, UNI_CHAIN, UNI_SHEET = 0, 1, 2


class Uniform(NamedTuple):
    """What the sweeps read of a uniform chain or grid sheet (``steps.Split.uniform``;
    kind UNI_NONE: nothing, every array empty)."""

    #: UNI_NONE, UNI_CHAIN, UNI_SHEET
    kind: int
    #: a chain's lateral stretch (k_g ≠ 0: 1), a sheet's number of columns
    flag: int
    #: the shared law: ``kernels.chain_uniform``'s u, ``kernels.sheet_uniform``'s p
    law: np.ndarray
    #: a sheet's shear signs of its x hinges (n − 1, site-indexed, 0 at the rows' ends) and y hinges (n − n_cols)
    sgx: np.ndarray
    sgy: np.ndarray
    #: the parameter-adjoint accumulators of the run's column form: a chain's (N_CA, n) (``acc``);
    #: a sheet's x and y families' and θ0's (``acc``, ``acc_y``, ``acc_t0``)
    acc: np.ndarray
    acc_y: np.ndarray
    acc_t0: np.ndarray
    #: scratch of the adjoint (and of a chain's force): (N_V, n + 1), a sheet's ``sheet_uniform_scratch``
    r: np.ndarray
    #: a sheet's force scratch (``sheet_kernels.grid_scratch``'s w), hinge table, θ0 per unit
    w: np.ndarray
    hprm: np.ndarray
    theta0: np.ndarray


@jit
def _uniform_sheet_force(q, uni, f):
    """A uniform grid sheet's model force: ``sheet_kernels.sheet_force``'s grid path with the
    shared law as scalars and the shear signs (as the engine's fused sheet kernel: the same
    operations, the same bits)."""
    n, nc, p, w = uni.theta0.shape[0], uni.flag, uni.law, uni.w
    cs, sn = uni.r[W_COS, :n], uni.r[W_SIN, :n]
    sheet_angles(q, uni.theta0, cs, sn)
    law = (p[0], p[1], p[2], p[3], p[4], p[5])
    none = uni.law[:0]
    grid_x(q, cs, sn, uni.hprm, f, n, nc, w, none, none, 0, -1, (0.0, 0.0, 0.0, 0.0), law, uni.sgx)
    nb = w.shape[1] - 1
    for s0 in range(0, n - nc, nb):  # the y hinges (no wraps: ``kernels.sheet_grid``)
        grid_y(q, cs, sn, uni.hprm, f, n, nc, 0, s0, min(nb, n - nc - s0), w, law, uni.sgy)


@jit
def _total_force(args, terms, uni, q, t, f):
    """The position-dependent total force at (q, t) into f: the model's (a uniform chain's or
    sheet's from its law, the same bits), contacts, applied forces."""
    if uni.kind == UNI_CHAIN:
        r = uni.r
        n = r.shape[1] - 1
        chain_uniform_force(q, uni.law, uni.flag != 0, r[V_COS, :n], r[V_SIN, :n], r, f)
    elif uni.kind == UNI_SHEET:
        _uniform_sheet_force(q, uni, f)
    else:
        model_force(q, args, f)
    position_forces(q, t, f, terms.con_ij, terms.con_prm, terms.drv_dof, terms.drv_mode, terms.drv_shape,
                    terms.drv_prm)


@jit
def _stage_force(args, terms, uni, q, v, t, f):
    """Prescribe the driven DOFs at t, then the position-dependent total force (as the engine)."""
    apply_prescribed(q, v, t, terms.drv_dof, terms.drv_mode, terms.drv_shape, terms.drv_prm)
    _total_force(args, terms, uni, q, t, f)


def n_stage_forces(drifts: np.ndarray, fsal: bool) -> int:
    """The forces a step evaluates (after each drift but a drift-first method's last): the rows
    of a step's stage forces kept by the replay (``forward``'s FS)."""
    return drifts.size if fsal else drifts.size - 1


@jit
def split_step(args, terms, uni, kicks, drifts, E, G, fsal, q, v, f, t, h, FS):
    """One step in place: the engine's (``integrators.splitting.split_step``; no ledger) or, for
    a uniform chain or sheet, ``uniform_step``; returns t + h. The stage forces go to the rows
    of FS (stage forces, ndof: kept for the reverse sweep, the carried force copied to f) if it
    has rows, else to f."""
    if uni.kind == UNI_NONE:
        n = q.shape[0]
        return engine.split_step(args, terms, kicks, drifts, E, G, np.arange(kicks.shape[0]), fsal, q, v, f, t, t, h,
                                 FS, np.empty(0), np.empty(n), np.empty(n), np.empty((6, 0)))[0]
    return uniform_step(args, terms, uni, kicks, drifts, E, G, fsal, q, v, f, t, h, FS)


@jit
def uniform_step(args, terms, uni, kicks, drifts, E, G, fsal, q, v, f, t, h, FS):
    """``integrators.splitting.split_step`` with the stage forces of a uniform chain or sheet
    from its shared law (``_total_force``: the model's bits, faster), the same operations in
    the same order, so the same run (tests/design/test_gradient_splitting.py). An accelerator:
    the engine's step, written again around a force the engine's layer cannot reach."""
    n = q.shape[0]
    M = drifts.shape[0]
    keep = FS.shape[0] > 0
    dd, dm, ds, dp = terms.drv_dof, terms.drv_mode, terms.drv_shape, terms.drv_prm
    ts = t
    fk = f
    for s in range(M):
        c = drifts[s] * h
        if kicks[s] != 0.0:
            kick(E, G, s, v, fk, c, q, q[:0], q[:0])
        else:
            for k in range(n):
                q[k] += c * v[k]
        ts += c
        if s == M - 1 and not fsal:
            break
        fk = FS[s] if keep else f
        _stage_force(args, terms, uni, q, v, ts, fk)
    if fsal:
        kick(E, G, M, v, fk, 0.0, q[:0], q[:0], q[:0])
        if keep:
            f[:] = fk
    t1 = t + h
    apply_prescribed(q, v, t1, dd, dm, ds, dp)
    return t1


@jit
def _record_state(args, terms, uni, fsal, q, v, f, t, fr, obs, Rq, Rv, Rf, j):
    """Record (q, v, F(q, t))[obs]: a drift-first method evaluates the force here (into fr)."""
    if fsal:
        _record(q, v, f, obs, Rq, Rv, Rf, j)
    else:
        _total_force(args, terms, uni, q, t, fr)
        _record(q, v, fr, obs, Rq, Rv, Rf, j)


@jit
def forward(args, terms, uni, kicks, drifts, E, G, fsal, q, v, f, t, h, nsteps, seg, stride, obs, CQ, CV, CF, CT,
            Rq, Rv, Rf, FS):
    """Run ``nsteps`` from (q, v, f, t) (f: the force at the start) in place; checkpoint every
    ``seg`` steps, record every ``stride`` steps (as ``sweeps.forward``); returns t. With
    ``seg`` = 1 it is the replay of a segment (every state kept). FS (nsteps, stage forces,
    ndof) keeps each step's stage forces for ``reverse``; with no columns (shape (1, 0, ndof))
    none are kept."""
    n = q.shape[0]
    save = FS.shape[1] > 0
    fr = np.empty(n)
    for k in range(nsteps + 1):
        if k % seg == 0:
            _checkpoint(q, v, f, t, CQ, CV, CF, CT, k // seg)
        if k % stride == 0:
            if k == 0:  # the caller's f is the force at the start
                _record(q, v, f, obs, Rq, Rv, Rf, 0)
            else:
                _record_state(args, terms, uni, fsal, q, v, f, t, fr, obs, Rq, Rv, Rf, k // stride)
        if k < nsteps:
            t = split_step(args, terms, uni, kicks, drifts, E, G, fsal, q, v, f, t, h, FS[k if save else 0])
    return t


@jit
def _stage_states(terms, kicks, drifts, E, G, fsal, q0, v0, f0, FS, t, h, VB, QS, TS):
    """The stages of the step from (q0, v0, f0) at t, as ``split_step`` computes them (the same
    operations, so the same bits), reading its stage forces FS (stage forces, ndof): the
    velocity entering each kick s ≥ 1 (VB[s]; kick 0's is v0) and each stage's position and
    time (QS[s], TS[s]: the force f_{s+1} = F(QS[s], TS[s])), up to the last kick."""
    n = q0.shape[0]
    M = drifts.shape[0]
    ts = t
    for s in range(M if fsal else M - 1):
        src = v0 if s == 0 else VB[s]
        qs = q0 if s == 0 else QS[s - 1]
        dst, qd = VB[s + 1], QS[s]
        c = drifts[s] * h
        if kicks[s] != 0.0:
            kick(E, G, s, src, f0 if s == 0 else FS[s - 1], c, qs, dst, qd)
        else:
            for k in range(n):
                x = src[k]
                dst[k] = x
                qd[k] = qs[k] + c * x
        ts += c
        apply_prescribed(qd, dst, ts, terms.drv_dof, terms.drv_mode, terms.drv_shape, terms.drv_prm)
        TS[s] = ts


@jit
def _stage_adjoint(args, terms, uni, q, t, lam, lq, g1, g2, gcon, gdrv, dg, ddg, form):
    """λq += (∂F/∂q)ᵀλ at a stage (q, t), parameter adjoints: ``sweeps._force_adjoint`` with
    ``form``, or for a uniform chain or sheet (``Uniform``) the model's part from its shared law
    (into the column form's accumulators) and the applied forces'."""
    if uni.kind == UNI_NONE:
        _force_adjoint(args, terms, q, t, lam, lq, g1, g2, gcon, gdrv, dg, ddg, form, runtime(False))
        return
    if uni.kind == UNI_CHAIN:
        u, acc, r = uni.law, uni.acc, uni.r
        n = r.shape[1] - 1
        cs, sn = r[V_COS, :n], r[V_SIN, :n]
        chain_uniform_sites(q[n:], u[U_TH0], cs, sn)
        chain_uniform_hinges(q, lam, cs, sn, r, acc, u)
        chain_uniform_gather(q, lam, lq, cs, sn, r, acc, u)
    else:
        sheet_uniform_adjoint(q, lam, lq, uni.law, uni.flag, uni.sgx, uni.sgy, uni.acc, uni.acc_y, uni.acc_t0, uni.r)
    if terms.drv_dof.shape[0]:
        drive_force_adjoint(t, lam, terms.drv_dof, terms.drv_mode, terms.drv_shape, terms.drv_prm, gdrv, dg, ddg)


@jit
def _kick_adjoint_field(e, g, c, lv, lq, lf, lk, vb, fk, ge, gg):
    """One field of the reverse of a kick and its drift: x = λv + c λq, then ∂J/∂e += x v,
    ∂J/∂g += x f (v, f: the velocity and force entering the kick), λf = g x (+ lf unless empty:
    the last kick's force is also the one carried), λv = e x."""
    if lf.shape[0]:
        for k in range(lv.shape[0]):
            x = lv[k] + c * lq[k]
            ge[k] += x * vb[k]
            gg[k] += x * fk[k]
            lk[k] = lf[k] + param(g, k) * x
            lv[k] = param(e, k) * x
    else:
        for k in range(lv.shape[0]):
            x = lv[k] + c * lq[k]
            ge[k] += x * vb[k]
            gg[k] += x * fk[k]
            lk[k] = param(g, k) * x
            lv[k] = param(e, k) * x


@jit
def _kick_adjoint(E, G, s, c, lv, lq, lf, lk, vb, fk, ge, gg):
    """``_kick_adjoint_field`` of kick s (and drift s, c = a_s h) on each field (E, G as ``engine.kick``)."""
    n = lv.shape[0]
    if E.shape[1] < n:
        m = n // E.shape[1]
        for i in range(E.shape[1]):
            a, b = i * m, (i + 1) * m
            _kick_adjoint_field(E[s, i], G[s, i], c, lv[a:b], lq[a:b], lf[a:b], lk[a:b], vb[a:b], fk[a:b], ge[a:b],
                                gg[a:b])
    else:
        _kick_adjoint_field(E[s], G[s], c, lv, lq, lf, lk, vb, fk, ge, gg)


@jit
def _any(x):
    """Whether any entry of x is nonzero."""
    for k in range(x.shape[0]):
        if x[k] != 0.0:
            return True
    return False


@jit
def reverse(args, terms, uni, kicks, drifts, E, G, fsal, SQ, SV, SF, ST, FS, h, k0, nsteps, stride, obs, dRq, dRv,
            dRf, lq, lv, lf, GE, GG, g1, g2, gcon, gdrv, form):
    """Reverse the steps k0 + nsteps → k0 of a replayed segment (SQ, SV, SF, ST rows 0..nsteps;
    FS rows 0..nsteps − 1: the stage forces the replay kept, or no columns: recomputed here,
    one more forward step).

    (lq, lv, lf) enter as the adjoints of the state at step k0 + nsteps (its records included)
    and leave as those at step k0 (records included); lf is the adjoint of the force carried
    into the next step (kick-first) or of the recorded force only (drift-first: reversed only
    where nonzero, at the records). The adjoints of the parameters, of the kick factors (GE, GG:
    (M + 1, ndof)) accumulate. Subnormals are flushed to zero during the sweep as
    ``sweeps.chain_uniform_reverse`` (only entries below 2.2e-308 change).
    """
    csr = flush_subnormals()
    n = lq.shape[0]
    M = drifts.shape[0]
    dd, dm, ds, dp = terms.drv_dof, terms.drv_mode, terms.drv_shape, terms.drv_prm
    dg = np.empty(4)
    ddg = np.empty(4)
    VB = np.empty((M + 1, n))
    QS = np.empty((M, n))
    TS = np.empty(M)
    lk = np.zeros(n)  # the adjoint of the force of the kick being reversed
    read = FS.shape[1] > 0
    stages = np.empty((0 if read else (M if fsal else M - 1), n))
    q = np.empty(0 if read else n)
    v = np.empty(0 if read else n)
    for j in range(nsteps, 0, -1):
        t1 = ST[j]
        if read:
            FSj = FS[j - 1]
        else:  # the step's stage forces again
            q[:] = SQ[j - 1]
            v[:] = SV[j - 1]
            split_step(args, terms, uni, kicks, drifts, E, G, fsal, q, v, SF[j - 1].copy(), ST[j - 1], h, stages)
            FSj = stages
        if not fsal and _any(lf):  # the recorded force F(q_j, t_j)
            _stage_adjoint(args, terms, uni, SQ[j], t1, lf, lq, g1, g2, gcon, gdrv, dg, ddg, form)
            lf[:] = 0.0
        prescribed_adjoint(t1, lq, lv, dd, dm, ds, dp, gdrv, dg, ddg)
        _stage_states(terms, kicks, drifts, E, G, fsal, SQ[j - 1], SV[j - 1], SF[j - 1], FSj, ST[j - 1], h, VB, QS, TS)
        if fsal:  # the last kick: its force is the one carried to the next step
            _kick_adjoint(E, G, M, 0.0, lv, lq, lf, lk, VB[M], FSj[M - 1], GE[M], GG[M])
        for s in range(M - 1, -1, -1):
            if s < M - 1 or fsal:  # the force f_{s+1} = F(QS[s], TS[s]) after drift s
                _stage_adjoint(args, terms, uni, QS[s], TS[s], lk, lq, g1, g2, gcon, gdrv, dg, ddg, form)
                prescribed_adjoint(TS[s], lq, lv, dd, dm, ds, dp, gdrv, dg, ddg)
            c = drifts[s] * h
            if kicks[s] != 0.0:
                _kick_adjoint(E, G, s, c, lv, lq, lq[:0], lk, SV[j - 1] if s == 0 else VB[s],
                              SF[j - 1] if s == 0 else FSj[s - 1], GE[s], GG[s])
            else:
                for k in range(n):
                    lv[k] += c * lq[k]
        if fsal:  # the adjoint of the force at the step's start
            lf[:] = lk
        _inject(k0 + j - 1, stride, obs, dRq, dRv, dRf, lq, lv, lf)
    if csr >= 0:
        swap_mxcsr(csr)


@jit
def _forces_tangent(args, terms, q, t, dq, D1, D2, DCON, DDRV, out, dg, ddg):
    """Tangents of the force at (q, t) along every direction m (rows of dq, D*, out)."""
    for m in range(dq.shape[0]):
        _force_tangent(args, terms, q, t, dq[m], D1[m], D2[m], DCON[m], DDRV[m], out[m], dg, ddg)


@jit
def _prescribed_tangents(t, dq, dv, terms, DDRV, dg, ddg):
    for m in range(dq.shape[0]):
        prescribed_tangent(t, dq[m], dv[m], terms.drv_dof, terms.drv_mode, terms.drv_shape, terms.drv_prm, DDRV[m],
                           dg, ddg)


@jit
def _kick_tangent(s, E, G, DE, DG, q, v, f, dv, df):
    """Tangent of kick s (before the primal kick: it reads the velocity entering it), then the kick."""
    n = v.shape[0]
    for m in range(dv.shape[0]):
        for k in range(n):
            dv[m, k] = E[s, k] * dv[m, k] + DE[m, s, k] * v[k] + G[s, k] * df[m, k] + DG[m, s, k] * f[k]
    for k in range(n):
        v[k] = E[s, k] * v[k] + G[s, k] * f[k]


@jit
def tangent(args, terms, uni, kicks, drifts, E, G, DE, DG, fsal, q, v, f, t, h, nsteps, stride, obs,
            D1, D2, DCON, DDRV, DQ0, DV0, Rq, Rv, Rf, TQ, TV, TF):
    """Forward run with tangents along several directions (index m of every D*), as
    ``sweeps.tangent``; DE, DG (dirs, M + 1, ndof) are the directions of the kick factors.
    From (q, v) at t (prescribed and force computed here); returns t."""
    n = q.shape[0]
    M = drifts.shape[0]
    nd = D1.shape[0]
    dg = np.empty(4)
    ddg = np.empty(4)
    dq = DQ0.copy()
    dv = DV0.copy()
    df = np.zeros((nd, n))
    fr = np.empty(n)
    dfr = np.zeros((nd, n))
    dd, dm, ds, dp = terms.drv_dof, terms.drv_mode, terms.drv_shape, terms.drv_prm
    _stage_force(args, terms, uni, q, v, t, f)
    _prescribed_tangents(t, dq, dv, terms, DDRV, dg, ddg)
    _forces_tangent(args, terms, q, t, dq, D1, D2, DCON, DDRV, df, dg, ddg)
    for k in range(nsteps + 1):
        if k % stride == 0:
            j = k // stride
            if fsal or k == 0:
                _record(q, v, f, obs, Rq, Rv, Rf, j)
                for m in range(nd):
                    _record(dq[m], dv[m], df[m], obs, TQ[m], TV[m], TF[m], j)
            else:
                _record_state(args, terms, uni, fsal, q, v, f, t, fr, obs, Rq, Rv, Rf, j)
                _forces_tangent(args, terms, q, t, dq, D1, D2, DCON, DDRV, dfr, dg, ddg)
                for m in range(nd):
                    _record(dq[m], dv[m], dfr[m], obs, TQ[m], TV[m], TF[m], j)
        if k == nsteps:
            break
        ts = t
        for s in range(M):
            if kicks[s] != 0.0:
                _kick_tangent(s, E, G, DE, DG, q, v, f, dv, df)
            c = drifts[s] * h
            for i in range(n):
                q[i] += c * v[i]
            for m in range(nd):
                for i in range(n):
                    dq[m, i] += c * dv[m, i]
            ts += c
            if s == M - 1 and not fsal:
                break
            _stage_force(args, terms, uni, q, v, ts, f)
            _prescribed_tangents(ts, dq, dv, terms, DDRV, dg, ddg)
            _forces_tangent(args, terms, q, ts, dq, D1, D2, DCON, DDRV, df, dg, ddg)
        if fsal:
            _kick_tangent(M, E, G, DE, DG, q, v, f, dv, df)
        t += h
        apply_prescribed(q, v, t, dd, dm, ds, dp)
        _prescribed_tangents(t, dq, dv, terms, DDRV, dg, ddg)
    return t
