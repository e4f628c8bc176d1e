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
from flexmm.models.hinge import H_SIGN, param
from flexmm.models.sheet_kernels import (SheetArgs, grid_layout, grid_scratch, grid_x, grid_x_params, grid_y,
                                         sheet_angles, uniform_hinges)
from flexmm.integrators.common import (
    ACC_DISSIPATED,
    ACC_WORK,
    ACC_FEVALS,
    ACC_STEPS,
    MODE_DISPLACEMENT,
    MODE_FORCE,
    MODE_FRICTION,
    _friction,
    apply_prescribed,
    contact_forces,
    damping_power,
    dashpot_power,
    has_velocity_terms,
    total_force,
    velocity_forces,
    waveform,
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


# Drives: each applied force's waveform is evaluated once per step (at the step's end time; the
# next step's start-time power reuses it) instead of three times as ``common.external_forces``
# and ``common.applied_power`` would; the sums and their order are theirs, so the results are too.


@jit
def _drive_values(t, drv_dof, drv_mode, drv_shape, drv_prm, g):
    """Values at t of the applied forces (mode 1) into g (the other entries untouched)."""
    for d in range(drv_dof.shape[0]):
        if drv_mode[d] == MODE_FORCE:
            g[d], _ = waveform(drv_shape[d], drv_prm[d], t)


@jit
def _applied_power(v, f, g, drv_dof, drv_mode, drv_prm, prescribed=True):
    """``common.applied_power`` with the applied forces' values g (``prescribed=False``: without
    the work of the prescribed displacements, −f·v, for a caller whose ``f`` is not current yet)."""
    power = 0.0
    for d in range(drv_dof.shape[0]):
        if drv_mode[d] == MODE_DISPLACEMENT:
            if prescribed:
                power -= f[drv_dof[d]] * v[drv_dof[d]]
        elif drv_mode[d] == MODE_FORCE:
            power += g[d] * v[drv_dof[d]]
        elif drv_mode[d] == MODE_FRICTION:
            vel = v[drv_dof[d]]
            power += _friction(drv_prm[d], vel) * vel
    return power


@jit
def _position_forces(q, f, con_ij, con_prm, g, drv_dof, drv_mode):
    """``common.position_forces`` with the applied forces' values g."""
    contact_forces(q, f, con_ij, con_prm)
    for d in range(drv_dof.shape[0]):
        if drv_mode[d] == MODE_FORCE:
            f[drv_dof[d]] += g[d]


@jit
def scratch(terms, n):
    """The buffers of ``step_force``: the applied forces' values (one per drive), and (f_a, u),
    (n,) each with velocity-dependent terms, else empty."""
    m = n if has_velocity_terms(terms) else 0
    return np.zeros(terms.drv_dof.shape[0]), np.empty(m), np.empty(m)


@jit
def step_force(args, terms, kick, post, q, w, t, g, f, fa, u):
    """The force f' = F(q', t', u) closing a step, at the drifted q' and half-kicked w: the
    driven DOFs prescribed at t' (q', w changed there), the applied forces' values at t' into
    ``g`` (``_drive_values``), then the model, contact and applied forces G and the velocity
    terms V. Without velocity terms (``fa`` empty) f' = G + V(w) (V: nothing); with them
    fa = G + V(w), u = S (w + K fa) the predicted end-of-step velocity and f' = G + V(u)
    (module docstring). The one force of a step: the engine's loops and the gradient's
    sweeps (``design.sweeps``) both take it."""
    apply_prescribed(q, w, t, terms.drv_dof, terms.drv_mode, terms.drv_shape, terms.drv_prm)
    _drive_values(t, terms.drv_dof, terms.drv_mode, terms.drv_shape, terms.drv_prm, g)
    model_force(q, args, f)
    _terms_force(terms, kick, post, q, w, g, f, fa, u)


@jit
def _terms_force(terms, kick, post, q, w, g, f, fa, u):
    """``step_force`` after the model force (in ``f``): the external terms added."""
    con_ij, con_prm, dash_ij, dash_c = terms.con_ij, terms.con_prm, terms.dash_ij, terms.dash_c
    drv_dof, drv_mode, drv_prm = terms.drv_dof, terms.drv_mode, terms.drv_prm
    _position_forces(q, f, con_ij, con_prm, g, drv_dof, drv_mode)
    if fa.shape[0] == 0:
        velocity_forces(w, f, dash_ij, dash_c, drv_dof, drv_mode, drv_prm)
        return
    for k in range(q.shape[0]):
        fa[k] = f[k]
    velocity_forces(w, fa, dash_ij, dash_c, drv_dof, drv_mode, drv_prm)
    for k in range(q.shape[0]):
        u[k] = (w[k] + kick[k] * fa[k]) * post[k]
    velocity_forces(u, f, dash_ij, dash_c, drv_dof, drv_mode, drv_prm)


@jit
def step(args, terms, kick, pre, post, q, v, f, t, h, g, fa, u):
    """One step of size h in place from (q, v, f) at t (f: the force there); returns t + h.

    The opening half kick and drift (``_start``), the step's force (``step_force``; f_a of the
    step left in ``fa``) and the closing half kick (``_end``); ``g``, ``fa``, ``u``: the scratch
    of ``scratch``. ``verlet_advance`` runs these passes with the closing kick of one step and
    the opening of the next in one (``_end_start``): the same bits with on-site damping (the
    damped passes), a different rounding of the two undamped half kicks (v + 2Kf)."""
    _start(q, v, f, kick, pre, h, True)
    t1 = t + h
    step_force(args, terms, kick, post, q, v, t1, g, f, fa, u)
    _end(v, f, kick, post, True)
    return t1


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
    g, fa, u = scratch(terms, n)  # g: applied forces at t
    fs = fa if vdep else f  # the force the applied power reads: G + V(v½)
    _drive_values(t, drv_dof, drv_mode, drv_shape, drv_prm, g)
    _start(q, v, f, kick, pre, h, damped)
    for s in range(nsteps):
        power0 = _applied_power(v, f, g, drv_dof, drv_mode, drv_prm)  # with v½ at t
        t += h
        step_force(args, terms, kick, post, q, v, t, g, f, fa, u)
        power = 0.0
        if external:
            power = _applied_power(v, fs, g, drv_dof, drv_mode, drv_prm)
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
    g, fa, u = scratch(terms, n)  # g: applied forces at t
    fs = fa if vdep else f  # the force the applied power reads: G + V(v½)
    _drive_values(t, drv_dof, drv_mode, drv_shape, drv_prm, g)
    for b in prange(nb):
        lo, hi = b * n // nb, (b + 1) * n // nb
        _start(q[lo:hi], v[lo:hi], f[lo:hi], kick[lo:hi], pre[lo:hi], h, damped)
    for s in range(nsteps):
        power0 = _applied_power(v, f, g, drv_dof, drv_mode, drv_prm)
        t += h
        apply_prescribed(q, v, t, drv_dof, drv_mode, drv_shape, drv_prm)  # ``step_force``, threaded
        _drive_values(t, drv_dof, drv_mode, drv_shape, drv_prm, g)
        model_force_parallel(q, args, f)
        _terms_force(terms, kick, post, q, v, g, f, fa, u)
        power = 0.0
        if external:
            power = _applied_power(v, fs, g, drv_dof, drv_mode, drv_prm)
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


# ---------------------------------------------------------------- fused with the sheet force
#: drives (prescribed displacements, applied forces) the fused sheet kernel accepts
SHEET_MAX_DRIVES = 4096


def sheet_fusable(args, q: np.ndarray, minv: np.ndarray, damp: np.ndarray, terms) -> bool:
    """Whether ``sheet_verlet_advance`` applies (checked once in Python when a stepper is made):
    a sheet whose hinges are the builder's grid without wraps, only hinge forces (no magnets,
    joints or loads), 3N DOFs, on-site damping and drives that prescribe a displacement or
    apply a force, but no contacts, dashpots or ground friction."""
    if not isinstance(args, SheetArgs):
        return False
    n = args.theta0.shape[0]
    if q.shape[0] != 3 * n or args.dipoles[0].shape[0] + args.joints[0].shape[0] + args.loads[0].shape[0] > 0:
        return False
    if terms.con_ij.shape[0] + terms.dash_ij.shape[0] > 0 or terms.drv_dof.shape[0] > SHEET_MAX_DRIVES:
        return False
    if np.any((terms.drv_mode != 0) & (terms.drv_mode != MODE_FORCE)) or np.any(terms.drv_dof >= 3 * n):
        return False
    nc, x1, y0, y1 = grid_layout(args.hinge_a, args.hinge_b, args.hinge_axis, n)
    return nc > 0 and x1 == y0 and y1 == args.hinge_a.shape[0]


@jit
def _kick_field(q, v, f, kick, h, last):
    """``_end_start`` (``_end`` the last step) without damping, ``kick`` a column or a scalar
    (``hinge.param``: a field of equal masses streams no kicks)."""
    if last:
        for k in range(q.shape[0]):
            v[k] += param(kick, k) * f[k]
    else:
        for k in range(q.shape[0]):
            v[k] += 2.0 * param(kick, k) * f[k]
            q[k] += h * v[k]


@jit
def _sheet_sites_step(q, v, f, kick, pre, post, cd, h, n, lo, hi, last, damped, drv_dof, drv_mode, g, fkick):
    """Sites lo..hi−1 whose forces are complete: applied forces added (in drive order, as
    ``_position_forces``), damping power (v½), then the kicks and drift of ``verlet_advance``
    (``_end_start``; the last step ``_end``); ``fkick``: each field's kick if its masses are equal
    (and no damping), else nan. Returns the damping power."""
    for d in range(drv_dof.shape[0]):
        k = drv_dof[d]
        if drv_mode[d] == MODE_FORCE and lo <= k % n < hi:
            f[k] += g[d]
    diss = 0.0
    for fld in range(3):
        a, b = fld * n + lo, fld * n + hi
        if damped:
            diss += _onsite_power(v[a:b], cd[a:b])
        if fkick[fld] == fkick[fld]:
            _kick_field(q[a:b], v[a:b], f[a:b], fkick[fld], h, last)
        elif last:
            _end(v[a:b], f[a:b], kick[a:b], post[a:b], damped)
        else:
            _end_start(q[a:b], v[a:b], f[a:b], kick[a:b], pre[a:b], post[a:b], h, damped)
    return diss


@jit
def _field_kicks(kick, n, damped):
    """Each field's kick if all its DOFs have the same one (and no damping), else nan."""
    out = np.full(3, np.nan)
    if not damped:
        for fld in range(3):
            same = True
            k0 = kick[fld * n]
            for k in range(fld * n, (fld + 1) * n):
                same &= kick[k] == k0
            if same:
                out[fld] = k0
    return out


@jit
def _sheet_x(q, cs, sn, hprm, f, n, nc, w, pf, xprm, lo, hi, carry, uni, xsig, base):
    """``grid_x`` with the shared parameters (``uni``, if not nan) or the columns."""
    if xsig.shape[0] > 0:
        return grid_x(q, cs, sn, hprm, f, n, nc, w, pf, xprm, lo, hi, carry, uni, xsig, base)
    return grid_x(q, cs, sn, hprm, f, n, nc, w, pf, xprm, lo, hi, carry, None, None, base)


@jit
def _sheet_y(q, cs, sn, hprm, f, n, nc, y0, s0, m, w, uni, ysig, base):
    """``grid_y`` with the shared parameters (``uni``, if not nan) or the columns."""
    if ysig.shape[0] > 0:
        grid_y(q, cs, sn, hprm, f, n, nc, y0, s0, m, w, uni, ysig, base)
    else:
        grid_y(q, cs, sn, hprm, f, n, nc, y0, s0, m, w, None, None, base)


@jit
def _small_signs(x):
    """x as int8 (exact: the signs are ±1, and 0 for a row's dummy hinge), and whether it is exact."""
    out = np.empty(x.shape[0], np.int8)
    ok = True
    for k in range(x.shape[0]):
        out[k] = np.int8(x[k]) if -128.0 <= x[k] <= 127.0 else 0
        ok &= out[k] == x[k]
    return out, ok


@jit
def _sheet_prepare(args, minv, damp, h):
    """The tables of ``sheet_verlet_advance_prepared``: (grid layout (nc, y0, y1), per-DOF factors
    (kick, pre, post, c; ``_factors``), damped, the shared hinge parameters (``uniform_hinges``,
    nan if not shared), the horizontal hinges' parameters site-indexed (empty when shared), the
    shear signs of the horizontal and vertical hinges as int8 (±1 exactly: 2 bytes a site
    streamed instead of 16; empty when not shared), each field's kick if equal (``_field_kicks``))."""
    hprm, theta0 = args[3], args[4]
    n = theta0.shape[0]
    nc, _, y0, y1 = grid_layout(args[0], args[1], args[2], n)
    kick, pre, post, cd, damped = _factors(minv, damp, h)
    uni = uniform_hinges(hprm)
    xprm = grid_x_params(hprm, n, nc)
    xsig, okx = _small_signs(xprm[H_SIGN::7])
    ysig, oky = _small_signs(hprm[y0:y1, H_SIGN])
    if uni[0] == uni[0] and okx and oky:
        xprm = np.empty(0)
    else:
        uni = (np.nan, np.nan, np.nan, np.nan, np.nan, np.nan)
        xsig, ysig = xsig[:0], ysig[:0]
    return (nc, y0, y1), (kick, pre, post, cd), damped, uni, xprm, xsig, ysig, _field_kicks(kick, n, damped)


def sheet_prepare(args, minv: np.ndarray, damp: np.ndarray, h: float) -> tuple:
    """The tables of the fused sheet Verlet for these parameters, masses, damping and step: what
    ``sheet_verlet_advance_prepared`` takes, built once per stepper."""
    return _sheet_prepare(args, minv, damp, h)


@jit
def _slide(cw, sw, base, lo, hi):
    """Keep sites lo..hi−1 of the windows (site i at i − base) at their start; returns the new base."""
    for k in range(hi - lo):
        cw[k] = cw[lo - base + k]
        sw[k] = sw[lo - base + k]
    return lo


@jit
def sheet_verlet_advance_prepared(tables, args, q, v, f, minv, damp, terms, t, h, nsteps, acc):
    """``sheet_verlet_advance`` with its tables given (``sheet_prepare`` of the same args, minv, damp
    and h), so a stepper that calls it often pays their preparation once."""
    if nsteps <= 0:
        return t
    drv_dof, drv_mode, drv_shape, drv_prm = terms.drv_dof, terms.drv_mode, terms.drv_shape, terms.drv_prm
    hprm, theta0 = args[3], args[4]
    n = theta0.shape[0]
    (nc, y0, y1), (kick, pre, post, cd), damped, uni, xprm, xsig, ysig, fkick = tables
    w, pf = grid_scratch(n)
    nb = pf.shape[0] // 7
    ny = y1 - y0
    nw = min(n, nb + nc + 1)  # cos/sin of the sites in flight: a window, not an (N,) array
    cw, sw = np.empty(nw), np.empty(nw)
    g = np.zeros(drv_dof.shape[0])  # applied forces at t
    rate = np.zeros(drv_dof.shape[0])
    _drive_values(t, drv_dof, drv_mode, drv_shape, drv_prm, g)
    _start(q, v, f, kick, pre, h, damped)
    for s in range(nsteps):
        last = s == nsteps - 1
        power0 = _applied_power(v, f, g, drv_dof, drv_mode, drv_prm)  # with v½ at t
        t += h
        apply_prescribed(q, v, t, drv_dof, drv_mode, drv_shape, drv_prm)
        _drive_values(t, drv_dof, drv_mode, drv_shape, drv_prm, g)
        power = _applied_power(v, f, g, drv_dof, drv_mode, drv_prm, False)  # f is not at t yet
        for d in range(drv_dof.shape[0]):  # the imposed rates at t, for the prescribed work below
            rate[d] = v[drv_dof[d]]
        # one sweep: angles and horizontal hinges run ahead (to a row past the vertical block),
        # then the block's vertical hinges, then its sites (all forces in) are kicked and drifted;
        # cos/sin live in a window (cw, sw: site i at i − base) that slides along
        carry = (0.0, 0.0, 0.0, 0.0)
        xs = 0  # horizontal hinges done on sites < xs, angles on sites ≤ xs
        base = 0
        sheet_angles(q, theta0, cw, sw, 0, 1, base)
        diss = 0.0
        done = 0
        for s0 in range(0, ny, nb):
            m = min(nb, ny - s0)
            x1 = min(n, s0 + m + nc)
            base = _slide(cw, sw, base, s0, xs + 1)
            sheet_angles(q, theta0, cw, sw, xs + 1, min(n, x1 + 1), base)
            carry = _sheet_x(q, cw, sw, hprm, f, n, nc, w, pf, xprm, xs, x1, carry, uni, xsig, base)
            xs = x1
            _sheet_y(q, cw, sw, hprm, f, n, nc, y0, s0, m, w, uni, ysig, base)
            diss += _sheet_sites_step(q, v, f, kick, pre, post, cd, h, n, s0, s0 + m, last, damped, drv_dof,
                                      drv_mode, g, fkick)
            done = s0 + m
        if xs < n:
            base = _slide(cw, sw, base, xs, min(n, xs + 1))
            sheet_angles(q, theta0, cw, sw, xs + 1, n, base)
            _sheet_x(q, cw, sw, hprm, f, n, nc, w, pf, xprm, xs, n, carry, uni, xsig, base)
        diss += _sheet_sites_step(q, v, f, kick, pre, post, cd, h, n, done, n, last, damped, drv_dof, drv_mode, g,
                                  fkick)
        for d in range(drv_dof.shape[0]):  # prescribed displacements work against f at t
            if drv_mode[d] == MODE_DISPLACEMENT:
                power -= f[drv_dof[d]] * rate[d]
        if damped:
            acc[ACC_DISSIPATED] += h * diss
        acc[ACC_WORK] += 0.5 * h * (power0 + power)
    _count(acc, nsteps)
    return t


@jit
def sheet_verlet_advance(args, q, v, f, minv, damp, terms, t, h, nsteps, acc):
    """``verlet_advance`` for ``sheet_kernels.sheet_force`` (same arguments and results), fused.

    Each step is one sweep over blocks of sites: the angles and the horizontal hinges
    (``grid_x``) run a row ahead of the block's vertical hinges (``grid_y``); then the block's
    sites have all their forces and are kicked and drifted at once, while in cache. So the state
    streams through memory once per step (force + Verlet: about four times), cos/sin stay in a
    window of about a block and a row of sites, the shear signs of shared hinges are read as
    int8, and the layout and tables are checked once per call (``sheet_prepare``; a ``Stepper``
    keeps them: ``sheet_verlet_advance_prepared``). Bit-identical to ``verlet_advance`` but for
    the dissipation sum (summed by blocks). Only where ``sheet_fusable`` holds (the caller checks).
    """
    if nsteps <= 0:
        return t
    return sheet_verlet_advance_prepared(_sheet_prepare(args, minv, damp, h), args, q, v, f, minv, damp, terms, t,
                                         h, nsteps, acc)
