"""Second harmonic reflected by a nonlinear boundary: second-order perturbation theory (docs/physics.md §1.7).

A lattice M q̈ = F(q) (F = −∂E/∂q) is joined at a *port* DOF p to a semi-infinite linear monatomic
chain (mass m_c, spring k_c) on its left. A wave of amplitude I and frequency ω comes in along that
chain. Expanding q = q_s + q1 + q2 + … about the rest state q_s (F(q_s) = 0):

- first order, q1 = Re(X1 e^{−iωt}):   [H − ω² M − k_c (z1 − 1) e_p e_pᵀ] X1 = −2i k_c I sin q1 e_p,
- second order, 2ω part Re(X2 e^{−2iωt}): [H − 4ω² M − k_c (z2 − 1) e_p e_pᵀ] X2 = ¼ F''(X1, X1),

with H = −∂F/∂q at q_s, F''(a, b) the second directional derivative of F (the third derivative of
E, bilinear and symmetric) and z = e^{iq} the chain's outgoing root of k_c z² − (2k_c − m_c ω²) z
+ k_c = 0 (|z| < 1, or |z| = 1 with Im z > 0: the reflected wave runs left, or decays there). The
chain term is exact: the missing bond pulls the port with k_c (u_{−1} − u_0), and in the chain
u_n = I e^{iqn} + R e^{−iqn} gives u_{−1} = z u_0 − 2i I sin q. So the reflected waves are
R1 = X1[p] − I at ω and R2 = X2[p] at 2ω, the latter with the same amplitude |R2| at every site of
the chain (|R2| ∝ I² to this order). The derivatives are taken numerically from F alone: H by
central differences, F''(v, v) = [F(q_s + hv) − 2F(q_s) + F(q_s − hv)]/h² (error O(h²)), and
F''(a, b) by polarisation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np


@dataclass(frozen=True)
class BoundaryReflection:
    """The first- and second-order steady responses (complex amplitudes, per DOF) and the reflections."""

    x1: np.ndarray
    x2: np.ndarray
    r1: complex
    r2: complex
    q1: complex
    q2: complex


def outgoing_root(omega: float, k: float, m: float) -> complex:
    """z = e^{iq} of the monatomic chain at ω for a wave leaving to the left (see module docstring)."""
    roots = np.roots([k, -(2 * k - m * omega**2), k])
    inside = [z for z in roots if abs(z) < 1 - 1e-12]
    if inside:
        return complex(inside[0])
    return complex(max(roots, key=lambda z: z.imag))


def hessian(force: Callable[[np.ndarray], np.ndarray], q: np.ndarray, h: float = 1e-6,
            dofs: np.ndarray | None = None) -> np.ndarray:
    """H = −∂F/∂q at q by central differences over ``dofs`` (default all), symmetrised."""
    n = q.size
    dofs = np.arange(n) if dofs is None else np.asarray(dofs)
    hm = np.zeros((n, n))
    for j in dofs:
        qp, qm = q.copy(), q.copy()
        qp[j] += h
        qm[j] -= h
        hm[:, j] = -(force(qp) - force(qm)) / (2 * h)
    return 0.5 * (hm + hm.T)


def second_derivative(force: Callable[[np.ndarray], np.ndarray], q: np.ndarray, a: np.ndarray,
                      h: float = 1e-3) -> np.ndarray:
    """F''(a, a) for complex a (bilinear, not sesquilinear), by central differences and polarisation."""
    f0 = force(q)

    def d2(v: np.ndarray) -> np.ndarray:
        s = np.max(np.abs(v))
        if s == 0:
            return np.zeros_like(f0)
        w = h * v / s
        return (force(q + w) - 2 * f0 + force(q - w)) / (h / s) ** 2

    re, im = a.real, a.imag
    mixed = 0.25 * (d2(re + im) - d2(re - im))
    return d2(re) - d2(im) + 2j * mixed


def boundary_reflection(force: Callable[[np.ndarray], np.ndarray], rest: np.ndarray, mass: np.ndarray,
                        port: int, omega: float, incident: float, chain_k: float, chain_m: float,
                        free: np.ndarray | None = None, h_hess: float = 1e-6,
                        h_second: float = 1e-3) -> BoundaryReflection:
    """First- and second-order response of the lattice to a wave of amplitude ``incident`` at ω.

    ``force(q)`` is F = −∂E/∂q; ``free`` masks the DOFs that move (default all; held DOFs are
    kept at rest). Consistent units throughout (e.g. the models' nondimensional ones).
    """
    n = rest.size
    free = np.ones(n, bool) if free is None else np.asarray(free, bool)
    idx = np.flatnonzero(free)
    if not free[port]:
        raise ValueError("the port DOF must be free")
    hm = hessian(force, rest, h_hess, idx)[np.ix_(idx, idx)]
    m = np.diag(np.asarray(mass, float)[idx])
    p = int(np.searchsorted(idx, port))

    def solve(w: float, rhs: np.ndarray) -> tuple[np.ndarray, complex]:
        z = outgoing_root(w, chain_k, chain_m)
        a = hm - w**2 * m + 0j
        a[p, p] -= chain_k * (z - 1)
        return np.linalg.solve(a, rhs), z

    rhs1 = np.zeros(idx.size, complex)
    z1 = outgoing_root(omega, chain_k, chain_m)
    rhs1[p] = -2j * chain_k * incident * (z1 - 1 / z1) / 2j  # −2i k I sin q, sin q = (z − 1/z)/2i
    y1, z1 = solve(omega, rhs1)
    x1 = np.zeros(n, complex)
    x1[idx] = y1
    src = 0.25 * second_derivative(force, rest, x1, h_second)[idx]
    y2, z2 = solve(2 * omega, src)
    x2 = np.zeros(n, complex)
    x2[idx] = y2
    return BoundaryReflection(x1=x1, x2=x2, r1=complex(x1[port] - incident), r2=complex(x2[port]),
                              q1=complex(-1j * math.log(abs(z1)) + np.angle(z1)),
                              q2=complex(-1j * math.log(abs(z2)) + np.angle(z2)))
