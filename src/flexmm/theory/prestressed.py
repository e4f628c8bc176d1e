"""Rotating-squares chain held rotated by an end load: the prestressed theory (derived; docs/physics.md §1.1).

Deng et al. PRE 98, 053001 (2018) compress the chain statically before the dynamics; the loads stay
on. Derivation (nondimensional, k_l = a = 1, f = F/(k_l a) the compressive end force, gamma =
(4 + 2 n_v) Ktheta, h = n_v s_v/2, G_t0(theta) = cos t0 - cos(t0 + theta)):

1. Uniform equilibrium. With every hinge spring at Delta x = -f the chain's energy per unit plus the
   load's potential F (u_N - u_0) is stationary in theta when

       f_eff sin(theta0 + theta_s) = gamma theta_s,    f_eff = f - h G_theta0(theta_s)

   (static_rotation solves it; it is the "F a sin theta = (4 + 2 n_v) k_theta theta" of docs/physics.md
   §1.2 for theta0 = 0, s_v = 0).
2. Write theta = theta_s + phi, u = u_s + u~ with t0' = theta0 + theta_s. Each hinge's stretch is
   Delta x = -f + [u~_{i+1} - u~_i + cos t0' - (cos(t0' + phi_i) + cos(t0' + phi_{i+1}))/2], its shear
   is that of a chain with rest angle t0', and its torsion spring sees 2 theta_s + phi_i + phi_{i+1}.
   Expanding the squares, the energy is exactly that of the stress-free chain of rest angle t0'
   (in u~, phi) plus terms linear in Delta x~, phi and G_t0'(phi). The load's potential cancels the
   u~ part of the Delta x~ terms; what is left sums, hinge by hinge, to the on-site potential

       W(phi) = gamma theta_s phi - f_eff G_t0'(phi) = gamma theta_s [phi - G_t0'(phi)/sin t0']

   (using step 1). W has no gradient part, so the travelling-wave reduction of
   flexmm.theory.rotating.exact_soliton carries over with V -> V + W: the first integral becomes
   phi'^2 = -(S G^2 + gamma phi^2 + 2 W(phi))/D(phi), and the turning point phi = A gives the speed law
   c^2 = eta'^2 Q/(1 + Q), Q = (gamma A^2 + 2 W(A))/G(A)^2 + h, eta' = cos t0'. W''(0) =
   -gamma theta_s cot t0' softens the rotation (the linear dispersion's R(q) gains it), which makes
   the long-wave speed small near the buckling load.
3. Polarity: tensile pulses (U' = eta' G/(c^2 - eta'^2) > 0 needs G < 0, i.e. -2 t0' < A < 0) are
   rotations against theta_s: the units re-open. Such rarefaction solitons exist for the prestressed
   LEGO chain and get faster with amplitude; their compressive (A > 0) counterparts get slower.

The prestressed chain is therefore a RotatingChainND with theta0 = t0' and theta_s set
(prestressed_chain); speeds are in X units, X = n cos t0' (c / cos t0' sites per unit T).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from scipy import optimize

from flexmm.theory.rotating import RotatingChainND, hinge_stretch


def static_rotation(p: RotatingChainND, force: float) -> float:
    """theta_s of the uniform equilibrium under a compressive end force (nondimensional f = F/(k_l a)).

    Solves f_eff sin(theta0 + theta_s) = gamma theta_s (step 1 above) on the side of theta0's sign
    (theta_s = 0 at f = 0); ValueError for a stress-free chain argument with theta_s != 0, a
    tensile force, or no root below pi/2 - |theta0|.
    """
    if p.theta_s != 0:
        raise ValueError("pass the stress-free chain (theta_s = 0)")
    if force < 0:
        raise ValueError(f"force must be compressive (>= 0), got {force}")
    if force == 0:
        return 0.0
    sign = 1.0 if p.theta0 >= 0 else -1.0
    h = p.n_v * p.s_v / 2

    def residual(t):
        th = sign * t
        f_eff = force - h * float(hinge_stretch(p, th))
        return sign * f_eff * math.sin(p.theta0 + th) - p.gamma * t

    top = math.pi / 2 - abs(p.theta0)
    if p.theta0 == 0 and force <= p.gamma:  # a straight chain below its buckling load gamma
        return 0.0
    lo = 1e-9 if p.theta0 == 0 else 0.0
    if residual(top) > 0 or residual(lo) < 0:
        raise ValueError(f"no equilibrium rotation below pi/2 for f = {force}")
    return sign * optimize.brentq(residual, lo, top, xtol=1e-15, rtol=1e-15)


def prestressed_chain(p: RotatingChainND, theta_s: float) -> RotatingChainND:
    """The chain of rest angle p.theta0 held at p.theta0 + theta_s by its load (see module docstring)."""
    if p.theta_s != 0:
        raise ValueError("pass the stress-free chain (theta_s = 0)")
    return replace(p, theta0=p.theta0 + theta_s, theta_s=float(theta_s))


def equilibrium_force(p: RotatingChainND) -> float:
    """Compressive end force f (nondimensional) that holds a prestressed chain at its theta0 (step 1)."""
    if p.theta_s == 0:
        return 0.0
    rest = replace(p, theta0=p.theta0 - p.theta_s, theta_s=0.0)
    h = p.n_v * p.s_v / 2
    return p.gamma * p.theta_s / p.s0 + h * float(hinge_stretch(rest, p.theta_s))


def soliton_window(p: RotatingChainND, sign: int, n: int = 2000) -> tuple[float, float] | None:
    """(smallest, largest) signed amplitude of the solitons of polarity `sign`, on an n-point grid.

    Rarefaction (sign opposite to theta0) is searched in 0 < |A| < 2|theta0|, compression in
    0 < |A| < pi - |theta0|; None when soliton_exists finds none. Grid resolution, not exact ends.
    """
    from flexmm.theory.rotating import soliton_exists

    top = 2 * abs(p.theta0) if sign * p.theta0 < 0 else math.pi - abs(p.theta0)
    found = [a for a in top * (np.arange(1, n) / n) if soliton_exists(p, sign * a)]
    return (sign * min(found), sign * max(found)) if found else None
