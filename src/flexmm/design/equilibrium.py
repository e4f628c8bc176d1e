"""Exact derivatives of a predeformed lattice's equilibrium with respect to its parameters.

The equilibrium q_eq of ``models.predeform.relax`` solves F(q_eq, p) = 0 on the DOFs the
minimiser moves (``Predeformation.free``), the others held (fixed, or at a strain's targets).
By the implicit function theorem its change along a change (δp, δq_held) of the parameter
tables and the held DOFs is

    δq_free = K⁻¹ [(∂F/∂p) δp + (∂F/∂q_held) δq_held],   K = −∂F/∂q_free,

with the exact tangent of the force (``kernels.model_tangent``). K is solved by the factorised
Hessian of the polish (``predeform.HessianFactor``: central differences of the force, relative
error ~1e-10), refined with exact products (iterative refinement: each round multiplies the
error by ‖K̃⁻¹(K − K̃)‖, cond(K) × 1e-10), so δq_free is exact to rounding. Along a free
translation (balanced loads on free ends: a zero mode of K) the equilibrium's mean is FIRE's
conserved start mean, a known function of the parameters: its derivative is taken from the
builder's differences and the rest of δq_free is as above.
"""

from __future__ import annotations

import numpy as np

from flexmm.design.kernels import model_tangent
from flexmm.models.base import System
from flexmm.models.predeform import HessianFactor

#: rounds of iterative refinement at most (each gains a factor ~cond(K) × 1e-10)
REFINE_MAX = 6


def equilibrium_tangents(system: System, dt1: np.ndarray, dt2: np.ndarray, dq: np.ndarray) -> np.ndarray | None:
    """The derivatives of the lattice's equilibrium q0 along each direction k of (dt1[k], dt2[k])
    (the parameter tables) and dq[k] (the lattice DOFs: the held DOFs' change is used, and the
    mean of each free translation): dq with the free DOFs' rows replaced, shape (K, ndof).

    None where the implicit function theorem gives nothing better than the builder's differences:
    no predeformation, or one whose Newton polish was not kept (its Hessian indefinite, the
    state FIRE's: not at an equilibrium to rounding)."""
    pre = system.predeformation
    if pre is None or not pre.newton_steps or pre.free is None:
        return None
    m = pre.rest_state.size
    q = np.ascontiguousarray(system.q0[:m], float)
    free = pre.free
    factor = HessianFactor.of(system, q, free)
    if factor is None:
        return None
    out = np.array(dq[:, :m], float)
    r = np.empty(m)
    zero1, zero2 = np.zeros_like(dt1[0]), np.zeros_like(dt2[0])
    for k in range(out.shape[0]):
        held = out[k].copy()
        held[free] = 0.0
        model_tangent(q, system.args, held, np.ascontiguousarray(dt1[k]), np.ascontiguousarray(dt2[k]), r)
        rhs = r[free].copy()
        x = factor.solve(rhs)
        last = np.inf
        for _ in range(REFINE_MAX):  # until the residual stops falling (rounding)
            step = np.zeros(m)
            step[free] = x
            model_tangent(q, system.args, step, zero1, zero2, r)
            res = rhs + r[free]  # r = (∂F/∂q) x = −K x
            size = np.abs(res[factor.solve_set]).max(initial=0.0)
            if not size < 0.5 * last:
                break
            x += factor.solve(res)
            last = size
        for idx in factor.translations:  # the mean along a translation: the builder's
            x[idx] += out[k, free[idx]].mean() - x[idx].mean()
        out[k, free] = x
    return out
