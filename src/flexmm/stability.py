"""Largest linear frequency ω_max of a built system, for step-size limits (PHYSICS.md §3).

ω_max² is the largest eigenvalue of M^{-1/2} K M^{-1/2} over the free DOFs, with K the
Hessian of the energy at the reference state (q = 0), obtained from central differences of
the compiled force: K x ≈ −(F(q + εx) − F(q − εx)) / 2ε. One-sided contacts (a striker)
enter with their stiffness at the expected peak overlap, p k δ^(p−1), since a Hertz contact
stiffens with overlap.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse.linalg import ArpackNoConvergence, LinearOperator, eigsh

from flexmm.models.base import System

DENSE_LIMIT = 400


def _contact_stiffness(system: System, terms: dict) -> list[tuple[int, int, float]]:
    out = []
    for (i, j), (k, p, _) in zip(terms["con_ij"], terms["con_prm"]):
        if p == 1.0:
            out.append((int(i), int(j), float(k)))
            continue
        # overlap when all striker kinetic energy is stored: ½ M v² = k δ^(p+1)/(p+1)
        e_kin = 0.5 * system.mass[i] * system.v0[i] ** 2
        delta = ((p + 1.0) * e_kin / k) ** (1.0 / (p + 1.0)) if e_kin > 0 else 0.0
        out.append((int(i), int(j), float(p * k * delta ** (p - 1.0))))
    return out


def hessian_operator(system: System, terms: dict, q_ref: np.ndarray | None = None):
    """Matrix-free Hessian-vector product K x at ``q_ref`` (default: rest)."""
    q_ref = np.zeros(system.ndof) if q_ref is None else q_ref
    fp, fm = np.zeros(system.ndof), np.zeros(system.ndof)
    contacts = _contact_stiffness(system, terms)

    def matvec(x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, float).ravel()
        scale = np.max(np.abs(x))
        if scale == 0:
            return np.zeros_like(x)
        eps = 1e-6 / scale
        system.force(q_ref + eps * x, system.args, fp)
        system.force(q_ref - eps * x, system.args, fm)
        y = -(fp - fm) / (2 * eps)
        for i, j, k in contacts:
            d = x[i] - x[j]
            y[i] += k * d
            y[j] -= k * d
        return y

    return matvec


def omega_max(system: System, terms: dict, q_ref: np.ndarray | None = None) -> float:
    """Largest angular frequency of small oscillations (nondimensional)."""
    free = np.flatnonzero(system.inv_mass > 0)
    if free.size == 0:
        return 0.0
    w = np.sqrt(system.inv_mass[free])
    kx = hessian_operator(system, terms, q_ref)
    full = np.zeros(system.ndof)

    def op(y):
        full[:] = 0.0
        full[free] = w * np.asarray(y).ravel()
        return w * kx(full)[free]

    n = free.size
    if n <= DENSE_LIMIT:
        a = np.column_stack([op(e) for e in np.eye(n)])
        lam = np.linalg.eigvalsh(0.5 * (a + a.T))[-1]
    else:
        lin = LinearOperator((n, n), matvec=op, dtype=float)
        try:
            lam = eigsh(lin, k=1, which="LA", tol=1e-6, return_eigenvectors=False, maxiter=20 * n)[0]
        except ArpackNoConvergence as exc:
            lam = max(exc.eigenvalues) if len(exc.eigenvalues) else np.nan
    return float(np.sqrt(max(lam, 0.0)))
