"""Compiled pieces shared by all integrators: drives, contacts, dashpots and the total force.

Arrays (nondimensional):
- drives: ``drv_dof (D,)``, ``drv_mode (D,)`` (0 prescribed displacement, 1 applied force,
  2 ground friction), ``drv_shape (D,)`` (see SHAPES), ``drv_prm (D, 4)``; a friction row is
  (F₊, v_ε, F₋, 0): force −F tanh(v/v_ε) with F = F₊ for v > 0, F₋ otherwise (regularised
  Coulomb, explicit, so h F/(m v_ε) must stay below ~1); its (negative) work counts as applied;
- contacts (one-sided power law, e.g. a striker): ``con_ij (C, 2)``, ``con_prm (C, 3)`` =
  (k, exponent p, direction d); overlap δ = d (q_i − q_j), force k δ₊^p pushes i back, j on;
- dashpots between DOFs: ``dash_ij (P, 2)``, ``dash_c (P,)``.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from flexmm._jit import jit
from flexmm.models.kernels import model_force

#: waveform codes and the meaning of their parameter row (A = amplitude)
SHAPES = {
    "half_sine": 0,  # (A, T): A sin(πt/T) on 0 < t < T
    "smooth_step": 1,  # (A, T): A s(t/T), s = 6x⁵ − 15x⁴ + 10x³ clipped to [0, 1]
    "gaussian": 2,  # (A, σ, t_c): A exp(−(t − t_c)²/(2σ²))
    "harmonic": 3,  # (A, ω, T_ramp, t_stop): A r(t) sin(ωt), smooth ramp up and down
}
MODE_DISPLACEMENT = 0
MODE_FORCE = 1
MODE_FRICTION = 2

#: Slots of the accumulator ``acc`` every ``advance`` updates (``IntegratorSpec.new_acc`` makes
#: it: ``ACC_HEADER`` slots, plus the state of an adaptive method; ``Accumulators`` reads it).
ACC_DISSIPATED = 0  # energy removed by damping, dashpots since t = 0
ACC_WORK = 1  # work of the drives since t = 0: applied forces, ground friction, prescribed displacements
ACC_FEVALS = 2  # model-force evaluations
ACC_STEPS = 3  # steps taken (accepted steps for adaptive methods)
ACC_REJECTED = 4  # rejected steps (adaptive) / Newton iterations (implicit)
ACC_LINEAR = 5  # Krylov iterations (implicit)
ACC_FAILED = 6  # steps whose Newton iteration did not converge (implicit)
ACC_HEADER = 8


class Terms(NamedTuple):
    """External terms shared by all models (arrays of the module docstring; numba takes it)."""

    con_ij: np.ndarray  # (C, 2) int64: contact pairs (i pushed back, j pushed on)
    con_prm: np.ndarray  # (C, 3): k, exponent p, direction d
    dash_ij: np.ndarray  # (P, 2) int64: dashpot pairs
    dash_c: np.ndarray  # (P,): dashpot coefficients
    drv_dof: np.ndarray  # (D,) int64: driven DOF
    drv_mode: np.ndarray  # (D,) int64: MODE_DISPLACEMENT, MODE_FORCE or MODE_FRICTION
    drv_shape: np.ndarray  # (D,) int64: waveform code (SHAPES)
    drv_prm: np.ndarray  # (D, 4): waveform parameters

    @property
    def drives(self) -> tuple:
        """(drv_dof, drv_mode, drv_shape, drv_prm), the arguments of ``apply_prescribed``."""
        return self.drv_dof, self.drv_mode, self.drv_shape, self.drv_prm


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
def contact_forces(q, f, con_ij, con_prm):
    """Add the one-sided contact forces."""
    for c in range(con_ij.shape[0]):
        i = con_ij[c, 0]
        j = con_ij[c, 1]
        d = con_prm[c, 2]
        overlap = d * (q[i] - q[j])
        if overlap > 0.0:
            fc = con_prm[c, 0] * overlap ** con_prm[c, 1]
            f[i] -= d * fc
            f[j] += d * fc


@jit
def position_forces(q, t, f, con_ij, con_prm, drv_dof, drv_mode, drv_shape, drv_prm):
    """Add the forces that depend on (q, t) only: one-sided contacts and applied forces."""
    contact_forces(q, f, con_ij, con_prm)
    for d in range(drv_dof.shape[0]):
        if drv_mode[d] == 1:
            g, _ = waveform(drv_shape[d], drv_prm[d], t)
            f[drv_dof[d]] += g


@jit
def _friction(prm, vel):
    level = prm[0] if vel > 0.0 else prm[2]
    return -level * math.tanh(vel / prm[1])


@jit
def velocity_forces(v, f, dash_ij, dash_c, drv_dof, drv_mode, drv_prm):
    """Add the velocity-dependent forces: dashpots between DOFs and ground friction."""
    for p in range(dash_ij.shape[0]):
        i = dash_ij[p, 0]
        j = dash_ij[p, 1]
        fd = dash_c[p] * (v[j] - v[i])
        f[i] += fd
        f[j] -= fd
    for d in range(drv_dof.shape[0]):
        if drv_mode[d] == 2:
            f[drv_dof[d]] += _friction(drv_prm[d], v[drv_dof[d]])


@jit
def applied_power(v, f, t, drv_dof, drv_mode, drv_shape, drv_prm):
    """Power fed in by the drives at (v, t) (the 'applied work' rate): applied forces, ground
    friction, and prescribed displacements, which work against the force ``f`` the rest of the
    system exerts on their DOF (−f·v; ``f`` the current total force, v the imposed rate)."""
    power = 0.0
    for d in range(drv_dof.shape[0]):
        if drv_mode[d] == 0:
            power -= f[drv_dof[d]] * v[drv_dof[d]]
        elif drv_mode[d] == 1:
            g, _ = waveform(drv_shape[d], drv_prm[d], t)
            power += g * v[drv_dof[d]]
        elif drv_mode[d] == 2:
            vel = v[drv_dof[d]]
            power += _friction(drv_prm[d], vel) * vel
    return power


@jit
def friction_power(v, drv_dof, drv_mode, drv_prm):
    """The ground-friction part of ``applied_power`` (the drives without a potential)."""
    power = 0.0
    for d in range(drv_dof.shape[0]):
        if drv_mode[d] == MODE_FRICTION:
            vel = v[drv_dof[d]]
            power += _friction(drv_prm[d], vel) * vel
    return power


@jit
def held_dashpot_power(v, dash_ij, dash_c, drv_dof, drv_mode):
    """Work rate of the prescribed displacements through the dashpots on their DOFs, −f_d·v (the
    energy they feed the dashpots, which ``damping_power`` counts as dissipated)."""
    power = 0.0
    for d in range(drv_dof.shape[0]):
        if drv_mode[d] == MODE_DISPLACEMENT:
            k = drv_dof[d]
            for p in range(dash_ij.shape[0]):
                fd = dash_c[p] * (v[dash_ij[p, 1]] - v[dash_ij[p, 0]])  # on i; −fd on j
                if dash_ij[p, 0] == k:
                    power -= fd * v[k]
                elif dash_ij[p, 1] == k:
                    power += fd * v[k]
    return power


@jit
def stage_power(q, f, t, drv_dof, drv_mode, drv_shape, drv_prm):
    """Work rate of the drives that move a potential in time, at a splitting's kick (stage time t,
    ``f`` the force of that stage): −f·ġ on a prescribed DOF, −ġ q for an applied force g (whose
    potential −g q is not in the system's energy; ``applied_force_energy`` adds the g q boundary
    terms). Weighted by the kick coefficients this is the momentum of time in the extended phase
    space, which the splitting integrates to its own order (docs/physics.md §3)."""
    power = 0.0
    for d in range(drv_dof.shape[0]):
        if drv_mode[d] == MODE_DISPLACEMENT:
            _, dg = waveform(drv_shape[d], drv_prm[d], t)
            power -= f[drv_dof[d]] * dg
        elif drv_mode[d] == MODE_FORCE:
            _, dg = waveform(drv_shape[d], drv_prm[d], t)
            power -= dg * q[drv_dof[d]]
    return power


@jit
def applied_force_energy(q, t, drv_dof, drv_mode, drv_shape, drv_prm):
    """Σ g(t) q over the applied forces: the work ∫ g q̇ dt = [g q] − ∫ ġ q dt (``stage_power``)."""
    e = 0.0
    for d in range(drv_dof.shape[0]):
        if drv_mode[d] == MODE_FORCE:
            g, _ = waveform(drv_shape[d], drv_prm[d], t)
            e += g * q[drv_dof[d]]
    return e


@jit
def external_forces(q, v, t, f, con_ij, con_prm, dash_ij, dash_c, drv_dof, drv_mode, drv_shape, drv_prm):
    """Add contact, dashpot, applied and friction forces to ``f``; return the applied power."""
    position_forces(q, t, f, con_ij, con_prm, drv_dof, drv_mode, drv_shape, drv_prm)
    velocity_forces(v, f, dash_ij, dash_c, drv_dof, drv_mode, drv_prm)
    return applied_power(v, f, t, drv_dof, drv_mode, drv_shape, drv_prm)


@jit
def total_force(args, q, v, t, f, terms):
    """Model force plus every external term at (q, v, t) into ``f``; returns the applied power."""
    model_force(q, args, f)
    return external_forces(q, v, t, f, terms.con_ij, terms.con_prm, terms.dash_ij, terms.dash_c,
                           terms.drv_dof, terms.drv_mode, terms.drv_shape, terms.drv_prm)


@jit
def has_velocity_terms(terms):
    """Whether the external terms depend on velocity (dashpots or ground friction)."""
    if terms.dash_ij.shape[0] > 0:
        return True
    for d in range(terms.drv_mode.shape[0]):
        if terms.drv_mode[d] == MODE_FRICTION:
            return True
    return False


@jit
def damping_power(v, cd, dash_ij, dash_c):
    """Power dissipated by on-site damping (``cd``: coefficients, 0 on held DOFs) and dashpots."""
    s = 0.0
    for k in range(v.shape[0]):
        s += cd[k] * v[k] * v[k]
    return s + dashpot_power(v, dash_ij, dash_c)


@jit
def free_damping(damp, minv):
    """On-site damping coefficients with held (fixed or prescribed) DOFs zeroed."""
    cd = np.empty_like(damp)
    for k in range(damp.shape[0]):
        cd[k] = damp[k] if minv[k] > 0.0 else 0.0
    return cd


@jit
def acceleration(args, terms, minv, damp, t, q, v, f, a):
    """Impose prescribed DOFs at ``t``, then a = M⁻¹(F(q, v, t) − c v); ``f`` gets F.

    Returns (applied power, dissipated power) at (q, v, t): the rates of the energy ledger.
    """
    apply_prescribed(q, v, t, terms.drv_dof, terms.drv_mode, terms.drv_shape, terms.drv_prm)
    power = total_force(args, q, v, t, f, terms)
    diss = dashpot_power(v, terms.dash_ij, terms.dash_c)
    for k in range(q.shape[0]):
        a[k] = minv[k] * (f[k] - damp[k] * v[k])
        if minv[k] > 0.0:
            diss += damp[k] * v[k] * v[k]
    return power, diss


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


def empty_terms() -> Terms:
    """Terms of a system with no drives, contacts or dashpots."""
    return Terms(np.zeros((0, 2), np.int64), np.zeros((0, 3)), np.zeros((0, 2), np.int64), np.zeros(0),
                 np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 4)))


class Accumulators:
    """Named view of an accumulator array (the energy ledger and the work counters)."""

    def __init__(self, acc: np.ndarray):
        self.array = acc

    @property
    def dissipated(self) -> float:
        """Energy removed by damping and dashpots since t = 0 (nondimensional)."""
        return float(self.array[ACC_DISSIPATED])

    @property
    def work(self) -> float:
        """Work of applied forces and ground friction since t = 0 (nondimensional)."""
        return float(self.array[ACC_WORK])

    @property
    def force_evaluations(self) -> int:
        return int(self.array[ACC_FEVALS])

    @property
    def steps(self) -> int:
        """Steps taken (accepted steps of an adaptive method)."""
        return int(self.array[ACC_STEPS])

    @property
    def rejected_or_newton(self) -> int:
        """Rejected steps (adaptive) or Newton iterations (implicit)."""
        return int(self.array[ACC_REJECTED])

    @property
    def krylov(self) -> int:
        return int(self.array[ACC_LINEAR])

    @property
    def failed(self) -> int:
        """Steps whose Newton iteration did not converge (implicit)."""
        return int(self.array[ACC_FAILED])

    def counters(self) -> dict[str, int]:
        """The work counters as a dict (dataset attrs, benchmarks)."""
        return {"force_evaluations": self.force_evaluations, "steps": self.steps,
                "rejected_or_newton": self.rejected_or_newton, "krylov": self.krylov,
                "failed": self.failed}
