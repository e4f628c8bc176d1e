"""Continuum transition front of a damped chain of masses with any on-site law (docs/physics.md §2).

Nondimensional (length a, time sqrt(m/k_ref), as the model): with a linear bond of stiffness K,
on-site force V′(u) and on-site damping rate γ, a front u(ξ), ξ = x − vt, obeys

    (K − v²) u″ + γ v u′ − V′(u) = 0,

and joins the well it leaves behind (ξ → −∞) to the well ahead (ξ → +∞). Both wells are saddles
of this flow; in the phase plane p = u′(u), dp/du = (V′(u) − γ v p)/((K − v²) p), the branch
leaving the well behind and the one reaching the well ahead must meet at the barrier: v is the
root of their mismatch there (brentq), and u(ξ) follows from ξ = ∫ du/p. For the cubic law this
is the closed form of docs/physics.md §2 (tests check it); V′ comes from the model's own force kernel on a
uniform state, so the measured Raney energy, tables or polynomials work alike.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy import integrate, optimize


class NoFront(Exception):
    """No steady front (equal or inverted wells, no damping, no second well); message says why."""


@dataclass(frozen=True)
class FrontSolution:
    """Steady front: speed v, wells (ahead, behind), barrier, and the profile table u(ξ)."""

    v: float
    ahead: float
    behind: float
    barrier: float
    xi: np.ndarray  # increasing
    u: np.ndarray

    def profile(self, xi) -> np.ndarray:
        return np.interp(xi, self.xi, self.u, left=self.behind, right=self.ahead)

    def slope(self, xi) -> np.ndarray:
        return np.interp(xi, self.xi, np.gradient(self.u, self.xi), left=0.0, right=0.0)

    @property
    def jump(self) -> float:
        return self.behind - self.ahead

    @property
    def width_10_90(self) -> float:
        """Distance between the 10 % and 90 % levels of the jump (nondimensional)."""
        s = (self.u - self.ahead) / (self.behind - self.ahead)  # 1 behind, 0 ahead, decreasing
        return float(np.interp(0.1, s[::-1], self.xi[::-1]) - np.interp(0.9, s[::-1], self.xi[::-1]))


def wells(Vp: Callable[[float], float], start: float, direction: float, span: float = 2.9,
          n: int = 3001) -> tuple[float, float]:
    """(barrier, well) next to the well at ``start`` in the sign of ``direction``; NoFront if none."""
    u = start + np.sign(direction) * np.linspace(0.0, span, n)[1:]
    f = np.asarray(Vp(u), float)
    roots = []
    for k in np.flatnonzero(np.sign(f[:-1]) * np.sign(f[1:]) < 0):
        roots.append(optimize.brentq(lambda x: float(Vp(x)), u[k], u[k + 1], xtol=1e-14))
    if len(roots) < 2:
        raise NoFront(f"no second well within {span:g} units of {start:g} in that direction")
    return roots[0], roots[1]


N_STEPS = 4000  # RK4 steps in u per phase-plane branch


def _branch(Vp, Vpp, v, K, gamma, well, barrier, sign) -> tuple[float, np.ndarray, np.ndarray]:
    """p at the barrier and the branch (u, p) from ``well`` (unstable: sign +1; stable: −1).

    dp/du = (V′(u) − γ v p)/(D p), D = K − v², by classical RK4 on N_STEPS uniform steps in u,
    starting on the linear manifold p = λ (u − well) a small distance off the well.
    """
    D = K - v * v
    lam = np.roots([D, gamma * v, -Vpp(well)]).real
    lam = lam.max() if sign > 0 else lam.min()
    u0 = well + 1e-5 * (barrier - well)
    u = np.linspace(u0, barrier, N_STEPS + 1)
    du = u[1] - u[0]
    f_node = np.asarray(Vp(u), float)
    f_mid = np.asarray(Vp(u[:-1] + 0.5 * du), float)
    gv, p = gamma * v, lam * (u0 - well)
    out = np.empty(N_STEPS + 1)
    out[0] = p
    for k in range(N_STEPS):
        a, m, b = f_node[k], f_mid[k], f_node[k + 1]
        k1 = (a - gv * p) / (D * p)
        p2 = p + 0.5 * du * k1
        k2 = (m - gv * p2) / (D * p2)
        p3 = p + 0.5 * du * k2
        k3 = (m - gv * p3) / (D * p3)
        p4 = p + du * k3
        k4 = (b - gv * p4) / (D * p4)
        p = p + du * (k1 + 2 * k2 + 2 * k3 + k4) / 6
        out[k + 1] = p
    return float(p), u, out


def solve_front(Vp: Callable[[float], float], K: float, gamma: float, ahead: float,
                direction: float = -1.0) -> FrontSolution:
    """Steady front from the well ``ahead`` to its neighbour in ``direction`` (module docstring)."""
    if gamma <= 0:
        raise NoFront("no damping: the continuum front degenerates (v → c0, zero width)")
    barrier, behind = wells(Vp, ahead, direction)

    def V(u):  # energy relative to the well ahead
        return integrate.quad(lambda x: float(Vp(x)), ahead, u, limit=200)[0]

    if not V(behind) < -1e-6 * abs(V(barrier)):
        raise NoFront("the other well is not lower: no energy is released, no steady front")

    def Vpp(u, e=1e-6):
        return float(Vp(u + e) - Vp(u - e)) / (2 * e)

    def mismatch(v):
        return (_branch(Vp, Vpp, v, K, gamma, behind, barrier, +1)[0]
                - _branch(Vp, Vpp, v, K, gamma, ahead, barrier, -1)[0])

    c0 = math.sqrt(K)
    lo, hi = 1e-3 * c0, 0.999 * c0
    if mismatch(lo) * mismatch(hi) >= 0:
        grid = np.linspace(lo, hi, 24)
        m = [mismatch(v) for v in grid]
        k = next((i for i in range(len(m) - 1) if m[i] * m[i + 1] < 0), None)
        if k is None:
            raise NoFront("no front speed below c0 joins the wells")
        lo, hi = grid[k], grid[k + 1]
    v = optimize.brentq(mismatch, lo, hi, xtol=1e-10 * c0)
    segs = []
    for well, sign in ((behind, +1), (ahead, -1)):
        _, u, p = _branch(Vp, Vpp, v, K, gamma, well, barrier, sign)
        xi = integrate.cumulative_trapezoid(1.0 / p, u, initial=0.0)
        segs.append((xi - xi[-1], u))  # ξ = 0 at the barrier
    xi = np.concatenate([segs[0][0], segs[1][0][::-1]])
    u = np.concatenate([segs[0][1], segs[1][1][::-1]])
    xi, keep = np.unique(xi, return_index=True)
    return FrontSolution(v, ahead, behind, barrier, xi, u[keep])


def onsite_force(system, span: float = 3.0, n: int = 6001) -> Callable:
    """V′(u) of a mass chain, from its force kernel: minus the force on a middle site when every
    site is displaced by u (bonds unstretched), tabulated on |u| ≤ span and splined."""
    from scipy.interpolate import CubicSpline

    sites = system.n_sites
    q = np.zeros(system.ndof)
    f = np.zeros(system.ndof)
    mid = sites // 2
    grid = np.linspace(-span, span, n)
    vals = np.empty(n)
    for k, u in enumerate(grid):
        q[:sites] = u
        system.force(q, system.args, f)
        vals[k] = -f[mid]
    spline = CubicSpline(grid, vals)
    return spline
