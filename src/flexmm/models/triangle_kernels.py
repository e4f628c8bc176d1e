"""Compiled kernels of the rotating-triangles chain and sheet (docs/physics.md §1.6).

Each hinge joins vertex r_A of triangle A to vertex r_B of triangle B, on a hinge axis
e = (cos β, sin β) of its own (the kagome has three). The hinge is the paper's ligament law of
``ligaments`` (§1.9) on those two points: the triangles are a ligament network whose units turn
by σθ from the reference configuration (θ staggered, σ = ±1 the triangle's orientation), so
with S = diag(1, 1, σ) on the fields (u, v, θ)

    E(q) = E_net(S q),   F(q) = S F_net(S q),   ∂F/∂q = S (∂F_net/∂q) S,   ∂F/∂p = S ∂F_net/∂p.

The network's table (``rotating_triangles.triangle_args``) holds the hinge points at rest,
r_A = h R(σ_A θ0) e and r_B = −h R(σ_B θ0) e, and the rest offset D e (D = 2h cos θ0, the
centroids' distance); its rows are the model's differentiable parameters (``triangle_pack``).

State (nondimensional): q = [u (N), v (N), θ (N)]; ``args`` = ``TriangleArgs``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from flexmm._jit import jit
from flexmm.models import ligaments as lg


class TriangleArgs(NamedTuple):
    """What the triangle kernels read: ``network`` the hinges as ligaments (``ligaments.NetworkArgs``,
    the paper's law) on the units' rotations σθ, ``sigma`` (N,) the triangles' orientations σ = ±1."""

    network: lg.NetworkArgs
    sigma: np.ndarray


@jit
def staggered(x, sigma):
    """S x: a copy of the first 3N entries of x with its θ block times σ (N = sigma.size)."""
    n = sigma.shape[0]
    out = x[: 3 * n].copy()
    for i in range(n):
        out[2 * n + i] *= sigma[i]
    return out


@jit
def stagger_rotations(out, sigma):
    """The θ block of ``out`` times σ in place (S out)."""
    n = sigma.shape[0]
    for i in range(n):
        out[2 * n + i] *= sigma[i]


@jit
def triangle_force(q, args, out):
    """Generalised forces −∂E/∂q into ``out``; DOFs beyond 3N (if any) get zero."""
    lg.network_force(staggered(q, args.sigma), args.network, out)
    stagger_rotations(out, args.sigma)


@jit
def triangle_energy(q, args):
    """Potential energy (same arguments as ``triangle_force``)."""
    return lg.network_energy(staggered(q, args.sigma), args.network)


@jit
def triangle_adjoint(q, args, lam, out, g1, g2):
    """(∂F/∂q)ᵀλ = S (∂F_net/∂q)ᵀ S λ added to ``out``; (∂F/∂p)ᵀλ = (∂F_net/∂p)ᵀ S λ to g1 (the
    ligament table's gradient) and g2 (the contact table's: none)."""
    sigma = args.sigma
    part = np.zeros(out.shape[0])
    lg.network_adjoint(staggered(q, sigma), args.network, staggered(lam, sigma), part, g1, g2)
    stagger_rotations(part, sigma)
    for k in range(out.shape[0]):
        out[k] += part[k]


@jit
def triangle_tangent(q, args, dq, d1, d2, out):
    """(∂F/∂q) dq + (∂F/∂p)(d1, d2) = S [(∂F_net/∂q) S dq + (∂F_net/∂p)(d1, d2)] into ``out``."""
    sigma = args.sigma
    lg.network_tangent(staggered(q, sigma), args.network, staggered(dq, sigma), d1, d2, out)
    stagger_rotations(out, sigma)


def triangle_pack(args: TriangleArgs) -> tuple[np.ndarray, np.ndarray]:
    """The differentiable tables: the hinges' ligament table and the (empty) contact table."""
    return lg.network_pack(args.network)


def triangle_unpack(args: TriangleArgs, t1: np.ndarray, t2: np.ndarray) -> TriangleArgs:
    """``args`` with its ligament and contact tables replaced."""
    return args._replace(network=lg.network_unpack(args.network, t1, t2))


def triangle_reference(q: np.ndarray, args: TriangleArgs) -> tuple[float, np.ndarray]:
    """Numpy energy and forces: the network's reference at S q, its torques times σ."""
    sigma = args.sigma
    n = sigma.size
    qs = np.asarray(q[: 3 * n]).copy()
    qs[2 * n :] *= sigma
    energy, f = lg.network_reference(qs, args.network)
    f[2 * n :] *= sigma
    out = np.zeros(np.shape(q), f.dtype)
    out[: 3 * n] = f
    return energy, out
