"""Exact and continuum waves of chains of masses as initial states (docs/physics.md §2).

Each launcher returns SI displacements and velocities of the chain's sites (n,) for one wave:

- ``toda_soliton``: the exact Toda soliton of bond stretch r_n, with its exact velocity field;
- ``toda_two_soliton``: the exact Toda two-soliton (Hirota's τ function), also mid-collision;
- ``sech2_pulse``: the long-wave sech² solitary wave of a polynomial bond k1 D + k2 D²;
- ``fpu_beta_pulse``: the long-wave sech (mKdV) solitary wave of an FPU-β bond k1 D + k3 D³;
- ``hertz_kdv_pulse``: the weak (KdV) solitary wave of a precompressed Hertz chain (Nesterenko);
- ``kink``: the sine-Gordon or φ⁴ kink of a linear chain on a sine or phi4 substrate, at rest or
  at the terminal speed of a constant driving force against viscous damping (McLaughlin–Scott);
- ``tanh_front``: the damped bistable front (L/2)(1 − tanh((x − X)/w)) of a bistable_cubic
  on-site term with linear coupling, at its predicted speed (or at rest: the kink saddle).

A wave of bond stretch D_n (bond n joins sites n and n+1) becomes displacements by summing
the stretches towards the side the wave moves away from, so the chain ahead of it is at rest
(u = 0, u̇ = 0).
"""

from __future__ import annotations

import math

import numpy as np

from flexmm.config.lattice import MODELS
from flexmm.theory import chains as th


def _sech2(z: np.ndarray) -> np.ndarray:
    """sech² z without overflow far from the centre."""
    e = np.exp(-2.0 * np.abs(z))
    return 4.0 * e / (1.0 + e) ** 2


def _from_bonds(r: np.ndarray, rdot: np.ndarray, direction: int) -> tuple[np.ndarray, np.ndarray]:
    """Site displacements/velocities (n = bonds + 1) at rest ahead of a wave moving ``direction``."""
    if direction > 0:  # ahead = right end: u_{N-1} = 0, u_i = −Σ_{k≥i} r_k
        u = np.append(-np.cumsum(r[::-1])[::-1], 0.0)
        ud = np.append(-np.cumsum(rdot[::-1])[::-1], 0.0)
    else:  # ahead = left end: u_0 = 0, u_i = Σ_{k<i} r_k
        u = np.concatenate([[0.0], np.cumsum(r)])
        ud = np.concatenate([[0.0], np.cumsum(rdot)])
    return u, ud


def _chain(lat, law: str):
    if not MODELS[lat.kind].chain_waves:
        raise ValueError(f"launches a wave of a mass_chain, not of a {lat.kind}")
    if lat.bond2 is not None or lat.variation:
        raise ValueError("the wave is exact only on a uniform nearest-neighbour chain (no variation, no bond2)")
    if law and lat.bond.law != law:
        raise ValueError(f"needs a {law} bond (lattice.bond.law is {lat.bond.law})")
    return lat.bond, lat.spacing_m, lat.mass_kg, lat.n_units


def toda_soliton(lat, kappa: float, center_site: float, direction: int) -> tuple[np.ndarray, np.ndarray]:
    """Exact Toda soliton e^(−b r_n) − 1 = sinh²κ sech²(κ(n − n0) − β t), β = sqrt(ab/m) sinh κ."""
    bond, _, m, n = _chain(lat, "toda")
    if lat.onsite:
        raise ValueError("the Toda soliton needs a chain without on-site terms")
    a, b = bond.a_n, bond.b_per_m
    beta = math.sqrt(a * b / m) * math.sinh(kappa)
    z = kappa * (np.arange(n - 1) + 0.5 - center_site)  # bond n sits between sites n and n+1
    s2 = math.sinh(kappa) ** 2 * _sech2(z)
    r = -np.log1p(s2) / b
    drdz = 2 * s2 * np.tanh(z) / (b * (1 + s2))
    return _from_bonds(r, drdz * (-direction * beta), direction)


def toda_two_soliton(lat, kappa, center_site, direction) -> tuple[np.ndarray, np.ndarray]:
    """Exact Toda two-soliton (``theory.chains.toda_two_soliton``) centred on the two sites; the
    chain ahead of both is at rest, or between them when they move in opposite directions."""
    bond, _, m, n = _chain(lat, "toda")
    if lat.onsite:
        raise ValueError("the Toda solitons need a chain without on-site terms")
    r, rdot = th.toda_two_soliton(bond.a_n, bond.b_per_m, m, tuple(kappa), tuple(center_site), tuple(direction),
                                  np.arange(n - 1) + 0.5)
    if direction[0] == direction[1]:
        return _from_bonds(r, rdot, direction[0])
    u, ud = _from_bonds(r, rdot, 1)
    mid = int(round(0.5 * (center_site[0] + center_site[1])))
    return u - u[mid], ud - ud[mid]


def sech2_pulse(lat, strain: float, center_site: float, direction: int) -> tuple[np.ndarray, np.ndarray]:
    """Long-wave solitary wave D_n = D_m sech²((n − n0)/W) of T(D) = k1 D + k2 D², moving at v."""
    bond, a, m, n = _chain(lat, "polynomial")
    if lat.onsite or bond.k3_n_per_m3 != 0 or bond.offset_m != 0:
        raise ValueError("the sech² wave needs a polynomial bond k1 D + k2 D² (k3 = 0) and no on-site terms")
    wave = th.softening_solitary_wave(bond.k1_n_per_m, bond.k2_n_per_m2, strain * a, m, a)
    z = (np.arange(n - 1) + 0.5 - center_site) / wave.W
    D = strain * a * _sech2(z)
    dDdz = -2 * D * np.tanh(z)
    return _from_bonds(D, dDdz * (-direction * wave.v / (a * wave.W)), direction)


def fpu_beta_pulse(lat, strain: float, center_site: float, direction: int) -> tuple[np.ndarray, np.ndarray]:
    """Long-wave solitary wave D_n = D_m sech((n − n0)/W) of T(D) = k1 D + k3 D³, moving at v."""
    bond, a, m, n = _chain(lat, "polynomial")
    if lat.onsite or bond.k2_n_per_m2 != 0 or bond.offset_m != 0:
        raise ValueError("the FPU-β wave needs a polynomial bond k1 D + k3 D³ (k2 = 0) and no on-site terms")
    v, W = th.fpu_beta_solitary_wave(bond.k1_n_per_m, bond.k3_n_per_m3, strain * a, m, a)
    z = (np.arange(n - 1) + 0.5 - center_site) / W
    D = strain * a / np.cosh(np.clip(z, -700, 700))
    dDdz = -D * np.tanh(z)
    return _from_bonds(D, dDdz * (-direction * v / (a * W)), direction)


def hertz_kdv_pulse(lat, eps: float, center_site: float, direction: int) -> tuple[np.ndarray, np.ndarray]:
    """KdV solitary wave of a Hertz chain (exponent 3/2) precompressed by ``static_load_n`` or a
    held ``precompression_m``: excess strain eps ξ0 sech²((n − n0)/W), added to the rest state."""
    bond, a, m, n = _chain(lat, "hertz")
    if lat.onsite or bond.exponent != 1.5 or bond.offset_m != 0:
        raise ValueError("the KdV wave needs a Hertz bond of exponent 3/2 and no on-site terms")
    A = bond.stiffness_n_per_m_p
    delta0 = (abs(lat.static_load_n) / A) ** (2 / 3) if lat.static_load_n else bond.precompression_m
    if not delta0 > 0:
        raise ValueError("the KdV wave needs a precompressed chain (static_load_n or a held precompression_m)")
    wave = th.hertz_kdv_wave(A, m, a, delta0 / a, eps)
    z = (np.arange(n - 1) + 0.5 - center_site) / wave.W
    D = wave.Dm * _sech2(z)
    dDdz = -2 * D * np.tanh(z)
    return _from_bonds(D, dDdz * (-direction * wave.v / (a * wave.W)), direction)


def tanh_front(lat, eta: float | None, center_site: float, direction: int,
               static: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Bistable front u = (L/2)(1 − d tanh((x − X(t))/w)), X = x0 + d v t: state L behind, 0 ahead."""
    bond, a, m, n = _chain(lat, "linear")
    laws = [law for law in lat.onsite if law.law == "bistable_cubic"]
    if len(laws) != 1 or len(lat.onsite) != 1 or bond.offset_m != 0 or laws[0].offset_m != 0:
        raise ValueError("the tanh front needs one bistable_cubic on-site term and a linear bond")
    law = laws[0]
    alpha, beta, L, k = law.alpha_n_per_m3, law.beta, law.jump_m, bond.k_n_per_m
    if static:
        v, w = 0.0, math.sqrt(8 * k * a * a / (alpha * L * L))
    else:
        if eta is None:
            raise ValueError("a moving front needs damping.viscous.coefficient_n_s_per_m (its speed is set by η)")
        fr = th.bistable_front(alpha, beta, L, k, m, a, eta)
        v, w = fr.v, fr.w
    x = (np.arange(n) - center_site) * a
    th_ = np.tanh(direction * x / w)
    u = 0.5 * L * (1 - th_)
    dudx = -0.5 * L * direction * (1 - th_**2) / w
    return u, -direction * v * dudx


def chain_kink(lat) -> tuple[th.Kink, float, float]:
    """The continuum kink of a linear chain on one sine or phi4 substrate (plus at most one
    constant_force): (kink, lower well (m), driving force F (N))."""
    bond, a, m, _ = _chain(lat, "linear")
    subs = [law for law in lat.onsite if law.law in ("sine", "phi4")]
    drive = [law for law in lat.onsite if law.law == "constant_force"]
    if (len(subs) != 1 or len(drive) > 1 or len(subs) + len(drive) != len(lat.onsite) or bond.offset_m != 0
            or subs[0].offset_m != 0):
        raise ValueError("the kink needs a linear bond, one sine or phi4 on-site law and at most one "
                         "constant_force (no offsets)")
    law, k = subs[0], bond.k_n_per_m
    if law.law == "sine":
        kink, lower = th.sine_gordon_kink(law.amplitude_j, law.period_m, k, m, a), 0.0
    else:
        kink, lower = th.phi4_kink(law.barrier_j, law.half_distance_m, k, m, a), -law.half_distance_m
    return kink, lower, drive[0].force_n if drive else 0.0


def kink(lat, eta: float | None, center_site: float, direction: int,
         static: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Kink from the lower to the upper well, the favoured well (the one the force F pushes
    towards) behind it, moving ``direction`` at McLaughlin–Scott's terminal speed (or at rest)."""
    k, lower, force = chain_kink(lat)
    v = 0.0
    if not static and force != 0:
        if eta is None:
            raise ValueError("a driven kink needs damping.viscous.coefficient_n_s_per_m (its speed is set by η)")
        v = th.driven_kink_speed(k, force, eta)
    sign = 1.0 if force >= 0 else -1.0
    x = (np.arange(lat.n_units) - center_site) * lat.spacing_m
    u = lower + force / k.curvature + k.profile(-sign * direction * x, v)  # wells moved by the force
    dudx = -sign * direction * k.slope(-sign * direction * x, v)
    return u, -direction * v * dudx
