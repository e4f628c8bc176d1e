"""Classical fourth-order Runge–Kutta on the first-order form y = (q, v) (docs/physics.md §3).

    q' = v,   v' = a(q, v, t) = M⁻¹ (F(q, v, t) − c v)

with F the model force plus contacts, dashpots, applied forces and friction
(``common.acceleration``). Stage weights (1, 2, 2, 1)/6 at times t, t + h/2, t + h/2, t + h.
Prescribed DOFs take their waveform at every stage time. The energy ledger (dissipated power,
applied power) is integrated with the same weights, so it is fourth order too. Four force
evaluations per step; linear stability limit h ω_max < 2√2 (the imaginary-axis bound).
"""

from __future__ import annotations

import numpy as np

from flexmm._jit import jit
from flexmm.integrators.common import ACC_DISSIPATED, ACC_WORK, ACC_FEVALS, ACC_STEPS, acceleration, apply_prescribed

#: stage nodes and weights (×6)
_NODES = (0.0, 0.5, 0.5, 1.0)
_WEIGHTS = (1.0, 2.0, 2.0, 1.0)


@jit
def _stage(args, terms, minv, damp, ts, Q, V, f, A, sq, sv, w, q, v, c_next, h):
    """Slopes at stage state (Q, V, ts) added to the sums with weight ``w``; then the next stage state."""
    power, diss = acceleration(args, terms, minv, damp, ts, Q, V, f, A)
    for k in range(Q.shape[0]):
        vk = V[k]
        sq[k] += w * vk
        sv[k] += w * A[k]
        Q[k] = q[k] + c_next * h * vk
        V[k] = v[k] + c_next * h * A[k]
    return power, diss


@jit
def rk4_advance(args, q, v, f, minv, damp, terms, t, h, nsteps, acc):
    """Advance ``nsteps`` RK4 steps of size ``h`` from ``t``; returns the new time.

    ``f`` is scratch (holds the last stage's total force); ``acc`` as in ``common.ACC_*``.
    """
    n = q.shape[0]
    Q = np.empty(n)
    V = np.empty(n)
    A = np.empty(n)
    sq = np.empty(n)
    sv = np.empty(n)
    for _ in range(nsteps):
        Q[:] = q
        V[:] = v
        sq[:] = 0.0
        sv[:] = 0.0
        power = 0.0
        diss = 0.0
        for s in range(4):
            c_next = _NODES[s + 1] if s < 3 else 0.0
            p, d = _stage(args, terms, minv, damp, t + _NODES[s] * h, Q, V, f, A, sq, sv,
                          _WEIGHTS[s], q, v, c_next, h)
            power += _WEIGHTS[s] * p
            diss += _WEIGHTS[s] * d
        for k in range(n):
            q[k] += h / 6.0 * sq[k]
            v[k] += h / 6.0 * sv[k]
        acc[ACC_DISSIPATED] += h / 6.0 * diss
        acc[ACC_WORK] += h / 6.0 * power
        t += h
        apply_prescribed(q, v, t, terms.drv_dof, terms.drv_mode, terms.drv_shape, terms.drv_prm)
    if acc.shape[0] > ACC_STEPS:
        acc[ACC_FEVALS] += 4 * nsteps
        acc[ACC_STEPS] += nsteps
    return t
