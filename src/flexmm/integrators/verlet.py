"""Velocity Verlet with semi-implicit linear damping (PHYSICS.md §3).

With on-site damping c_k (rate γ_k = c_k/m_k) one step of size h reads

    v½ = v + h/2 (F(q, v)/m − γ v)
    q' = q + h v½
    v' = (v½ + h/2 F(q', v½)/m) / (1 + h γ/2)

which is explicit, second order, symplectic when γ = 0 and keeps the linear stability limit
h ω_max < 2. Dashpots between units and contact forces enter F explicitly (dashpots with the
half-step velocity).
"""

from __future__ import annotations

from flexmm._jit import jit
from flexmm.integrators.common import apply_prescribed, dashpot_power, external_forces


@jit
def verlet_force(force, args, q, v, t, f, terms):
    """Total force at (q, v, t): model forces plus contacts, dashpots and applied forces."""
    con_ij, con_prm, dash_ij, dash_c, drv_dof, drv_mode, drv_shape, drv_prm = terms
    force(q, args, f)
    return external_forces(q, v, t, f, con_ij, con_prm, dash_ij, dash_c, drv_dof, drv_mode, drv_shape, drv_prm)


@jit
def verlet_advance(force, args, q, v, f, minv, damp, terms, t, h, nsteps, acc):
    """Advance ``nsteps`` steps of size ``h`` from time ``t``; returns the new time.

    ``f`` must hold the total force at entry and is kept current. ``acc`` (2,) accumulates
    the energy dissipated by damping and the work of applied forces.
    """
    con_ij, con_prm, dash_ij, dash_c, drv_dof, drv_mode, drv_shape, drv_prm = terms
    n = q.shape[0]
    hh = 0.5 * h
    for _ in range(nsteps):
        for k in range(n):
            g = damp[k] * minv[k]
            v[k] += hh * (f[k] * minv[k] - g * v[k])
            q[k] += h * v[k]
        t += h
        apply_prescribed(q, v, t, drv_dof, drv_mode, drv_shape, drv_prm)
        power = verlet_force(force, args, q, v, t, f, terms)
        diss = 0.0
        for k in range(n):
            g = damp[k] * minv[k]
            diss += damp[k] * v[k] * v[k] * (minv[k] > 0.0)
            v[k] = (v[k] + hh * f[k] * minv[k]) / (1.0 + hh * g)
        acc[0] += h * (diss + dashpot_power(v, dash_ij, dash_c))
        acc[1] += h * power
    return t
