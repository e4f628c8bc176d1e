"""Derivatives of the external terms (``integrators.common``): contacts, drive waveforms,
dashpots and ground friction.

Contacts F_i = −d k δ₊^p, F_j = +d k δ₊^p with δ = d (q_i − q_j): their Hessian-vector and
parameter products (k, p; the direction d is discrete). Drives: ∂g/∂prm and ∂ġ/∂prm of each
waveform of ``common.SHAPES`` — the amplitude for every shape, and the timing: T of
``half_sine``/``smooth_step``, σ and t_c of ``gaussian``, ω of ``harmonic`` (its ramp and stop
times get zero derivatives). Velocity forces (``common.velocity_forces``): dashpots
F_i = c (u_j − u_i) = −F_j, linear in u and c; friction −L tanh(u/v_ε) with L = F₊ for u > 0,
else F₋, smooth in (u, F₊, v_ε, F₋) except at u = 0 when F₊ ≠ F₋ (``gradient.check_differentiable``).
"""

from __future__ import annotations

import math

from flexmm._jit import jit
from flexmm.integrators.common import waveform


@jit
def _smooth(x):
    """s(x), s'(x), s''(x) of the C² ramp of ``common._smoothstep``."""
    if x <= 0.0 or x >= 1.0:
        return (1.0 if x >= 1.0 else 0.0), 0.0, 0.0
    return (x * x * x * (10.0 + x * (-15.0 + 6.0 * x)), 30.0 * x * x * (1.0 + x * (-2.0 + x)),
            60.0 * x * (1.0 + x * (-3.0 + 2.0 * x)))


@jit
def _ramp(prm, t):
    """Ramp factor r(t) of the harmonic waveform and dr/dt (as in ``common.waveform``)."""
    t_ramp, t_stop = prm[2], prm[3]
    r, dr = 1.0, 0.0
    if t_ramp > 0.0:
        r, dr, _ = _smooth(t / t_ramp)
        dr /= t_ramp
    if t > t_stop - t_ramp:
        if t_ramp > 0.0:
            r2, dr2, _ = _smooth((t_stop - t) / t_ramp)
            dr = dr * r2 - r * dr2 / t_ramp
            r = r * r2
        elif t >= t_stop:
            r, dr = 0.0, 0.0
    return r, dr


@jit
def waveform_dprm(shape, prm, t, dg, ddg):
    """∂g/∂prm_c into ``dg`` and ∂ġ/∂prm_c into ``ddg`` (4 each) at time t."""
    amp = prm[0]
    for c in range(4):  # dg holds the unit-amplitude parameters for a moment (no allocation)
        dg[c] = prm[c]
    dg[0] = 1.0
    g1, dg1 = waveform(shape, dg, t)
    for c in range(4):
        dg[c] = 0.0
        ddg[c] = 0.0
    dg[0], ddg[0] = g1, dg1
    if shape == 0:
        period = prm[1]
        if 0.0 < t < period:
            w = math.pi / period
            sn, cn = math.sin(w * t), math.cos(w * t)
            dg[1] = -amp * cn * w * t / period
            ddg[1] = amp * (-w * cn + w * w * t * sn) / period
    elif shape == 1:
        period = prm[1]
        x = t / period
        _, ds, d2s = _smooth(x)
        dg[1] = -amp * ds * x / period
        ddg[1] = -amp * (d2s * x + ds) / (period * period)
    elif shape == 2:
        sig = prm[1]
        z = (t - prm[2]) / sig
        e = math.exp(-0.5 * z * z)
        dg[1] = amp * e * z * z / sig
        dg[2] = amp * e * z / sig
        ddg[1] = -amp * e * z * (z * z - 2.0) / (sig * sig)
        ddg[2] = -amp * e * (z * z - 1.0) / (sig * sig)
    else:
        w = prm[1]
        r, dr = _ramp(prm, t)
        st, ct = math.sin(w * t), math.cos(w * t)
        dg[1] = amp * r * t * ct
        ddg[1] = amp * (dr * t * ct + r * ct - r * w * t * st)


@jit
def _same_waveform(d, e, drv_shape, drv_prm):
    """Whether drive d has the waveform (shape and parameters) of drive e (−1: none), so the
    same derivatives at any t: an edge driven as one (a shaker's column of sites) evaluates
    them once a step, not once a site."""
    if e < 0 or drv_shape[d] != drv_shape[e]:
        return False
    for c in range(drv_prm.shape[1]):
        if drv_prm[d, c] != drv_prm[e, c]:
            return False
    return True


@jit
def drive_force_adjoint(t, lf, drv_dof, drv_mode, drv_shape, drv_prm, gdrv, dg, ddg):
    """Add λ_f · ∂(applied forces)/∂prm to ``gdrv`` (force drives, mode 1)."""
    last = -1  # the drive whose derivatives dg holds
    for d in range(drv_dof.shape[0]):
        if drv_mode[d] == 1:
            if not _same_waveform(d, last, drv_shape, drv_prm):
                waveform_dprm(drv_shape[d], drv_prm[d], t, dg, ddg)
                last = d
            for c in range(4):
                gdrv[d, c] += lf[drv_dof[d]] * dg[c]


@jit
def prescribed_adjoint(t, lq, lv, drv_dof, drv_mode, drv_shape, drv_prm, gdrv, dg, ddg):
    """Reverse of ``common.apply_prescribed`` at t: the adjoints of the overwritten q, v of
    driven DOFs go to the drive parameters, and are zeroed."""
    last = -1
    for d in range(drv_dof.shape[0]):
        if drv_mode[d] == 0:
            k = drv_dof[d]
            if not _same_waveform(d, last, drv_shape, drv_prm):
                waveform_dprm(drv_shape[d], drv_prm[d], t, dg, ddg)
                last = d
            for c in range(4):
                gdrv[d, c] += lq[k] * dg[c] + lv[k] * ddg[c]
            lq[k] = 0.0
            lv[k] = 0.0


@jit
def prescribed_tangent(t, dq, dv, drv_dof, drv_mode, drv_shape, drv_prm, ddrv, dg, ddg):
    """Tangent of ``apply_prescribed``: driven DOFs take the waveform's variation along ``ddrv``."""
    for d in range(drv_dof.shape[0]):
        if drv_mode[d] == 0:
            k = drv_dof[d]
            waveform_dprm(drv_shape[d], drv_prm[d], t, dg, ddg)
            a = 0.0
            b = 0.0
            for c in range(4):
                a += dg[c] * ddrv[d, c]
                b += ddg[c] * ddrv[d, c]
            dq[k] = a
            dv[k] = b


@jit
def drive_force_tangent(t, out, drv_dof, drv_mode, drv_shape, drv_prm, ddrv, dg, ddg):
    """Add the variation of the applied forces along ``ddrv`` to ``out``."""
    for d in range(drv_dof.shape[0]):
        if drv_mode[d] == 1:
            waveform_dprm(drv_shape[d], drv_prm[d], t, dg, ddg)
            for c in range(4):
                out[drv_dof[d]] += dg[c] * ddrv[d, c]


@jit
def _contact(q, con_ij, con_prm, c):
    """(i, j, d, overlap δ, k, p, δ₊^p) of contact c."""
    i = con_ij[c, 0]
    j = con_ij[c, 1]
    d = con_prm[c, 2]
    delta = d * (q[i] - q[j])
    p = con_prm[c, 1]
    return i, j, d, delta, con_prm[c, 0], p, max(delta, 0.0) ** p


@jit
def contact_adjoint(q, lam, out, con_ij, con_prm, gcon):
    """Add (∂F_c/∂q)ᵀλ to ``out`` and (∂F_c/∂(k, p))ᵀλ to ``gcon`` for the one-sided contacts."""
    for c in range(con_ij.shape[0]):
        i, j, d, delta, k, p, dp = _contact(q, con_ij, con_prm, c)
        if delta > 0.0:
            stiff = k * p * delta ** (p - 1.0)
            w = stiff * d * (lam[i] - lam[j])
            out[i] -= d * w
            out[j] += d * w
            gcon[c, 0] += d * (lam[j] - lam[i]) * dp
            gcon[c, 1] += d * (lam[j] - lam[i]) * k * dp * math.log(delta)


@jit
def contact_tangent(q, dq, out, con_ij, con_prm, dcon):
    """Add the variation of the contact forces along (dq, dcon) to ``out``."""
    for c in range(con_ij.shape[0]):
        i, j, d, delta, k, p, dp = _contact(q, con_ij, con_prm, c)
        if delta > 0.0:
            w = k * p * delta ** (p - 1.0) * d * (dq[i] - dq[j]) + dcon[c, 0] * dp + k * dp * math.log(delta) * dcon[c, 1]
            out[i] -= d * w
            out[j] += d * w


@jit
def _friction_d(prm, x):
    """φ(x) = −L tanh(x/ε) of ``common._friction`` (L = F₊ for x > 0, else F₋): dφ/dx and
    ∂φ/∂(F₊, ε, F₋) — the derivatives of the branch the engine takes (at x = 0 the F₋ side)."""
    eps = prm[1]
    th = math.tanh(x / eps)
    sech2 = 1.0 - th * th
    level = prm[0] if x > 0.0 else prm[2]
    return -level * sech2 / eps, level * sech2 * x / (eps * eps), -th, x > 0.0


@jit
def velocity_adjoint(u, lam, out, dash_ij, dash_c, gdash, drv_dof, drv_mode, drv_prm, gdrv):
    """Reverse of ``common.velocity_forces`` at the velocity u: add (∂F/∂u)ᵀλ to ``out`` (∂F/∂u
    is symmetric), λ·∂F/∂c to ``gdash`` and λ·∂F/∂(F₊, v_ε, F₋) to the friction rows of ``gdrv``."""
    for p in range(dash_ij.shape[0]):
        i = dash_ij[p, 0]
        j = dash_ij[p, 1]
        dl = lam[j] - lam[i]
        c = dash_c[p]
        out[i] += c * dl
        out[j] -= c * dl
        gdash[p] -= (u[j] - u[i]) * dl
    for d in range(drv_dof.shape[0]):
        if drv_mode[d] == 2:
            k = drv_dof[d]
            slope, d_eps, d_level, forward = _friction_d(drv_prm[d], u[k])
            out[k] += slope * lam[k]
            gdrv[d, 1] += d_eps * lam[k]
            gdrv[d, 0 if forward else 2] += d_level * lam[k]


@jit
def velocity_tangent(u, du, out, dash_ij, dash_c, ddash, drv_dof, drv_mode, drv_prm, ddrv):
    """Add the variation of ``common.velocity_forces`` at u along (du, ddash, ddrv) to ``out``."""
    for p in range(dash_ij.shape[0]):
        i = dash_ij[p, 0]
        j = dash_ij[p, 1]
        fd = dash_c[p] * (du[j] - du[i]) + ddash[p] * (u[j] - u[i])
        out[i] += fd
        out[j] -= fd
    for d in range(drv_dof.shape[0]):
        if drv_mode[d] == 2:
            k = drv_dof[d]
            slope, d_eps, d_level, forward = _friction_d(drv_prm[d], u[k])
            out[k] += slope * du[k] + d_eps * ddrv[d, 1] + d_level * ddrv[d, 0 if forward else 2]
