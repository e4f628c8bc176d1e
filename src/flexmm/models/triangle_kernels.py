"""Compiled kernels of the rotating-triangles chain and sheet (docs/physics.md §1.6).

Each hinge joins vertex r_A of triangle A to vertex r_B of triangle B along a hinge axis
e = (cos β, sin β) of its own (the kagome has three), n = (−sin β, cos β). In the hinge frame
the law is the rotating-squares hinge of ``hinge.hinge_law``: at rest the two centroids and the
shared vertex are collinear, so with d_l = e·(x_B − x_A), d_s = n·(x_B − x_A) the elongation and
shear of the hinge are those of §1 with h_A = h_B = a/√3 and σ = σ_A. The kernels rotate the
relative displacement into the hinge frame, call ``hinge_law`` and rotate its force back.

State (nondimensional): q = [u (N), v (N), θ (N)]; ``args`` = ``TriangleArgs``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from flexmm._jit import jit
from flexmm.models.hinge import H_HALF_A, H_HALF_B, H_KL, H_KS, H_KT, H_REST, H_SIGN, hinge_law
from flexmm.models.sheet_kernels import sheet_angles


class TriangleArgs(NamedTuple):
    """What the triangle kernels read.

    ``hinge_a``/``hinge_b`` (H,) the joined triangles, ``axis_cos``/``axis_sin`` (H,) the hinge
    axis (A → B at rest), ``hinge_prm`` (H, 7) the law's parameters (``hinge.H_*`` columns),
    ``theta0`` (N,) rest twists, ``cos``/``sin`` (N,) scratch for cos/sin(θ0 + θ).
    """

    hinge_a: np.ndarray
    hinge_b: np.ndarray
    axis_cos: np.ndarray
    axis_sin: np.ndarray
    hinge_prm: np.ndarray
    theta0: np.ndarray
    cos: np.ndarray
    sin: np.ndarray


@jit
def _triangle_hinges(q, args, out, want_force):
    """Energy of all hinges; with ``want_force`` their forces added into ``out``."""
    ha, hb, ec, es, hprm, theta0, cs, sn = args
    n = theta0.shape[0]
    sheet_angles(q, theta0, cs, sn)
    total = 0.0
    for h in range(ha.shape[0]):
        a = ha[h]
        b = hb[h]
        c = ec[h]
        s = es[h]
        dx = q[b] - q[a]
        dy = q[n + b] - q[n + a]
        e, fl, fs, gA, gB = hinge_law(c * dx + s * dy, c * dy - s * dx, q[2 * n + a], q[2 * n + b],
                                      cs[a], sn[a], cs[b], sn[b], hprm[h])
        total += e
        if want_force:
            fx = c * fl - s * fs  # ∂E/∂(x_B − x_A)
            fy = s * fl + c * fs
            out[a] += fx
            out[b] -= fx
            out[n + a] += fy
            out[n + b] -= fy
            out[2 * n + a] -= gA
            out[2 * n + b] -= gB
    return total


@jit
def triangle_force(q, args, out):
    """Generalised forces −∂E/∂q into ``out``; DOFs beyond 3N (if any) get zero."""
    for k in range(out.shape[0]):
        out[k] = 0.0
    _triangle_hinges(q, args, out, True)


@jit
def triangle_energy(q, args):
    """Potential energy (same arguments as ``triangle_force``)."""
    return _triangle_hinges(q, args, np.empty(0), False)


def triangle_reference(q: np.ndarray, args: tuple) -> tuple[float, np.ndarray]:
    """Numpy energy and forces from the vertex positions (the tests' oracle).

    Written from the geometry of docs/physics.md §1.6, not from ``hinge_law``: the vertices
    r_A = h_A R(φ_A) e, r_B = −h_B R(φ_B) e with the actual rotations φ = σ(θ0 + θ) (σ_B = −σ_A);
    the gap g = x_B − x_A + D e + r_B − r_A (D the rest length), elongation g·e, shear g·n,
    hinge rotation θ_A + θ_B. Forces: ∂E/∂x_B = −∂E/∂x_A = G = k_l (g·e) e + k_s (g·n) n;
    ∂E/∂φ of a vertex r moved by the unit is ±(ẑ × r)·G.
    """
    ha, hb, ec, es, hprm, theta0 = args[:6]
    n = theta0.size
    u, v, th = q[:n], q[n : 2 * n], q[2 * n : 3 * n]
    p = hprm.T
    sig_a = p[H_SIGN]
    e = np.stack([ec, es], 1)
    nrm = np.stack([-es, ec], 1)

    def rot(vec, ang):
        c, s = np.cos(ang), np.sin(ang)
        return np.stack([c * vec[:, 0] - s * vec[:, 1], s * vec[:, 0] + c * vec[:, 1]], 1)

    r_a = rot(p[H_HALF_A][:, None] * e, sig_a * (theta0[ha] + th[ha]))
    r_b = rot(-p[H_HALF_B][:, None] * e, -sig_a * (theta0[hb] + th[hb]))
    dx = np.stack([u[hb] - u[ha], v[hb] - v[ha]], 1)
    gap = dx + p[H_REST][:, None] * e + r_b - r_a
    el, es_ = np.sum(gap * e, 1), np.sum(gap * nrm, 1)
    ep = th[ha] + th[hb]
    energy = 0.5 * float(np.sum(p[H_KL] * el**2 + p[H_KS] * es_**2 + p[H_KT] * ep**2))
    G = (p[H_KL] * el)[:, None] * e + (p[H_KS] * es_)[:, None] * nrm
    cross = lambda r: -r[:, 1] * G[:, 0] + r[:, 0] * G[:, 1]  # noqa: E731 - (ẑ × r)·G
    f = np.zeros_like(q)
    for k, off in ((0, 0), (1, n)):
        np.add.at(f, off + ha, G[:, k])
        np.add.at(f, off + hb, -G[:, k])
    # ∂φ_A/∂θ_A = σ_A, ∂φ_B/∂θ_B = −σ_A; the gap moves with +r_B and −r_A
    np.add.at(f, 2 * n + ha, -(-sig_a * cross(r_a) + p[H_KT] * ep))
    np.add.at(f, 2 * n + hb, -(-sig_a * cross(r_b) + p[H_KT] * ep))
    return energy, f
