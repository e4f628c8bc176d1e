"""Compiled pieces shared by all integrators: drives, contacts, dashpots and the total force.

Arrays (nondimensional):
- drives: ``drv_dof (D,)``, ``drv_mode (D,)`` (0 prescribed displacement, 1 applied force),
  ``drv_shape (D,)`` (see SHAPES), ``drv_prm (D, 4)``;
- contacts (one-sided power law, e.g. a striker): ``con_ij (C, 2)``, ``con_prm (C, 3)`` =
  (k, exponent p, direction d); overlap δ = d (q_i − q_j), force k δ₊^p pushes i back, j on;
- dashpots between DOFs: ``dash_ij (P, 2)``, ``dash_c (P,)``.
"""

from __future__ import annotations

import math

import numpy as np

from flexmm._jit import jit

#: waveform codes and the meaning of their parameter row (A = amplitude)
SHAPES = {
    "half_sine": 0,  # (A, T): A sin(πt/T) on 0 < t < T
    "smooth_step": 1,  # (A, T): A s(t/T), s = 6x⁵ − 15x⁴ + 10x³ clipped to [0, 1]
    "gaussian": 2,  # (A, σ, t_c): A exp(−(t − t_c)²/(2σ²))
    "harmonic": 3,  # (A, ω, T_ramp, t_stop): A r(t) sin(ωt), smooth ramp up and down
}
MODE_DISPLACEMENT = 0
MODE_FORCE = 1


@jit
def _smoothstep(x):
    """C² ramp 0 → 1 on [0, 1] and its derivative."""
    if x <= 0.0:
        return 0.0, 0.0
    if x >= 1.0:
        return 1.0, 0.0
    return x * x * x * (10.0 + x * (-15.0 + 6.0 * x)), 30.0 * x * x * (1.0 + x * (-2.0 + x))


@jit
def waveform(shape, prm, t):
    """Value and time derivative of a drive waveform at time ``t``."""
    amp = prm[0]
    if shape == 0:
        period = prm[1]
        if t <= 0.0 or t >= period:
            return 0.0, 0.0
        w = math.pi / period
        return amp * math.sin(w * t), amp * w * math.cos(w * t)
    if shape == 1:
        s, ds = _smoothstep(t / prm[1])
        return amp * s, amp * ds / prm[1]
    if shape == 2:
        sig = prm[1]
        z = (t - prm[2]) / sig
        g = amp * math.exp(-0.5 * z * z)
        return g, -g * z / sig
    w, t_ramp, t_stop = prm[1], prm[2], prm[3]
    r, dr = 1.0, 0.0
    if t_ramp > 0.0:
        r, dr = _smoothstep(t / t_ramp)
        dr /= t_ramp
    if t > t_stop - t_ramp:
        if t_ramp > 0.0:
            r2, dr2 = _smoothstep((t_stop - t) / t_ramp)
            dr = dr * r2 - r * dr2 / t_ramp
            r = r * r2
        elif t >= t_stop:
            r, dr = 0.0, 0.0
    st, ct = math.sin(w * t), math.cos(w * t)
    return amp * r * st, amp * (dr * st + r * w * ct)


@jit
def apply_prescribed(q, v, t, drv_dof, drv_mode, drv_shape, drv_prm):
    """Impose prescribed displacements (and their velocities) at time ``t``."""
    for d in range(drv_dof.shape[0]):
        if drv_mode[d] == 0:
            g, dg = waveform(drv_shape[d], drv_prm[d], t)
            q[drv_dof[d]] = g
            v[drv_dof[d]] = dg


@jit
def external_forces(q, v, t, f, con_ij, con_prm, dash_ij, dash_c, drv_dof, drv_mode, drv_shape, drv_prm):
    """Add contact, dashpot and applied-force terms to ``f``; return the applied-force power."""
    for c in range(con_ij.shape[0]):
        i = con_ij[c, 0]
        j = con_ij[c, 1]
        d = con_prm[c, 2]
        overlap = d * (q[i] - q[j])
        if overlap > 0.0:
            fc = con_prm[c, 0] * overlap ** con_prm[c, 1]
            f[i] -= d * fc
            f[j] += d * fc
    for p in range(dash_ij.shape[0]):
        i = dash_ij[p, 0]
        j = dash_ij[p, 1]
        fd = dash_c[p] * (v[j] - v[i])
        f[i] += fd
        f[j] -= fd
    power = 0.0
    for d in range(drv_dof.shape[0]):
        if drv_mode[d] == 1:
            g, _ = waveform(drv_shape[d], drv_prm[d], t)
            f[drv_dof[d]] += g
            power += g * v[drv_dof[d]]
    return power


@jit
def contact_energy(q, con_ij, con_prm):
    """Energy stored in the one-sided contacts: k δ₊^(p+1)/(p+1)."""
    e = 0.0
    for c in range(con_ij.shape[0]):
        overlap = con_prm[c, 2] * (q[con_ij[c, 0]] - q[con_ij[c, 1]])
        if overlap > 0.0:
            p = con_prm[c, 1]
            e += con_prm[c, 0] * overlap ** (p + 1.0) / (p + 1.0)
    return e


@jit
def dashpot_power(v, dash_ij, dash_c):
    """Power dissipated by the dashpots, Σ c (v_j − v_i)²."""
    s = 0.0
    for p in range(dash_ij.shape[0]):
        dv = v[dash_ij[p, 1]] - v[dash_ij[p, 0]]
        s += dash_c[p] * dv * dv
    return s


def empty_terms() -> dict[str, np.ndarray]:
    """Arrays for a system with no drives, contacts or dashpots."""
    return {
        "con_ij": np.zeros((0, 2), np.int64),
        "con_prm": np.zeros((0, 3)),
        "dash_ij": np.zeros((0, 2), np.int64),
        "dash_c": np.zeros(0),
        "drv_dof": np.zeros(0, np.int64),
        "drv_mode": np.zeros(0, np.int64),
        "drv_shape": np.zeros(0, np.int64),
        "drv_prm": np.zeros((0, 4)),
    }
