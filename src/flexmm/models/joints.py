"""Bistable joints between neighbouring units (the linkage's, docs/physics.md §2): kernels.

``joints`` = (a (J,), b (J,), prm (J, 3)); each joint's energy depends on the relative rotation
of its two units (``joint_law``).
"""

from __future__ import annotations

import numpy as np

from flexmm._jit import jit


def empty_joints() -> tuple:
    """Joint arguments with no joints: (a (0,), b (0,), prm (0, 3))."""
    return (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3)))


@jit
def joint_law(psi, prm):
    """Energy and dE/dψ of the bistable joint (row ``prm`` = k, β, ψ*)."""
    k, beta, ps = prm[0], prm[1], prm[2]
    e = k * psi * psi * (0.25 * psi * psi - (1.0 + beta) * ps * psi / 3.0 + 0.5 * beta * ps * ps)
    return e, k * psi * (psi - beta * ps) * (psi - ps)


@jit
def joint_terms(q, n, joints, out, want_force):
    """Add the bistable-joint torques to ``out`` (if ``want_force``); return their energy.

    ``joints`` = (a (J,), b (J,), prm (J, 3) = k, β, ψ*); θ of site i is ``q[2n + i]``.
    """
    ja, jb, jp = joints
    e = 0.0
    for j in range(ja.shape[0]):
        a = 2 * n + ja[j]
        b = 2 * n + jb[j]
        ej, dv = joint_law(q[a] + q[b], jp[j])
        e += ej
        if want_force:
            out[a] -= dv
            out[b] -= dv
    return e


def joint_reference(q: np.ndarray, n: int, joints: tuple) -> tuple[float, np.ndarray]:
    """Numpy version of ``joint_terms`` (the law via numpy.polynomial), for the tests."""
    ja, jb, jp = joints
    f = np.zeros_like(q)
    energy = 0.0
    for j in range(ja.size):
        k, beta, ps = jp[j]
        dV = np.polynomial.Polynomial.fromroots([0.0, beta * ps, ps]) * k
        psi = q[2 * n + ja[j]] + q[2 * n + jb[j]]
        energy += float(dV.integ()(psi))
        f[2 * n + ja[j]] -= dV(psi)
        f[2 * n + jb[j]] -= dV(psi)
    return energy, f
