"""Build the rotating-squares chain (docs/physics.md §1.1) from its config.

Nondimensionalisation: length a, time sqrt(m/k_l), mass m, so k_l = 1, K_s = k_s/k_l,
K_θ = k_θ/(k_l a²), α² = J/(m a²) and speeds are in units of c0 = a sqrt(k_l/m).
"""

from __future__ import annotations

import math
from functools import partial

import numpy as np

from flexmm.config.rigid import RotatingSquaresChain
from flexmm.models import predeform, variation
from flexmm.models.base import BOTTOM, LEFT, RIGHT, TOP, FieldSpec, System, UnitShapes, square_units
from flexmm.models.hinge import (
    ChainArgs,
    H_KL,
    H_REST,
    N_HINGE_PARAMS,
    N_SITE_PARAMS,
    S_KG,
    S_KR,
    S_THETA0,
)
from flexmm.models.rotating_sheet import hold_fixed_ends
from flexmm.units import Scales

FIELDS = (
    FieldSpec("u", "length", "longitudinal displacement", "x"),
    FieldSpec("theta", "angle", "staggered rotation"),
)


def nondimensional(cfg: RotatingSquaresChain) -> dict[str, float]:
    """K_s, K_θ, α² of docs/physics.md §1.1 from the SI config."""
    return {
        "Ks": cfg.k_shear_n_per_m / cfg.k_long_n_per_m,
        "Ktheta": cfg.k_rot_n_m_per_rad / (cfg.k_long_n_per_m * cfg.a_m**2),
        "alpha2": cfg.inertia_kg_m2 / (cfg.mass_kg * cfg.a_m**2),
    }


def theory_parameters(cfg: RotatingSquaresChain):
    """The chain's ``theory.rotating.RotatingChainND`` (docs/physics.md §1.1), from its config:
    what its soliton launcher reads."""
    from flexmm.theory.rotating import RotatingChainND

    return RotatingChainND.from_si(cfg.a_m, cfg.theta0_rad, cfg.k_long_n_per_m, cfg.k_shear_n_per_m, cfg.k_rot_n_m_per_rad,
                                   cfg.mass_kg, cfg.inertia_kg_m2, cfg.n_lateral, int(cfg.lateral_stretch))


def hinge_pairs(n: int, periodic: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(hinge_a, hinge_b) of an n-unit chain: h joins h and h + 1; a ring adds (n − 1, 0)."""
    ha = np.arange(n if periodic else n - 1, dtype=np.int64)
    return ha, (ha + 1) % n


def chain_tables(
    n: int, theta0: np.ndarray, Ks: np.ndarray | float, Ktheta: np.ndarray | float,
    n_lateral: int, lateral_stretch: bool, periodic: bool = False,
) -> tuple:
    """Connectivity and parameter tables of an n-unit chain (nondimensional, a = 1).

    ``theta0`` may vary per site; ``Ks``, ``Ktheta`` per hinge (scalars broadcast). ``periodic``:
    a ring of an even n (the hinge signs alternate), closed by the hinge (n − 1, 0).
    Returns the ``args`` tuple of ``chain_force``.
    """
    theta0 = np.broadcast_to(np.asarray(theta0, float), (n,))
    ha, hb = hinge_pairs(n, periodic)
    hprm = np.empty((ha.size, N_HINGE_PARAMS))
    hprm[:, 0] = 0.5 * (np.cos(theta0[ha]) + np.cos(theta0[hb]))
    hprm[:, 1] = 0.5
    hprm[:, 2] = 0.5
    hprm[:, 3] = np.where(ha % 2 == 0, 1.0, -1.0)
    hprm[:, 4] = 1.0
    hprm[:, 5] = Ks
    hprm[:, 6] = Ktheta
    sprm = np.empty((n, N_SITE_PARAMS))
    sprm[:, 0] = theta0
    sprm[:, 1] = n_lateral * (1.0 if lateral_stretch else 0.0) * 0.5
    sprm[:, 2] = 2.0 * n_lateral * np.broadcast_to(np.asarray(Ktheta, float), (ha.size,)).mean()
    return ChainArgs(ha, hb, hprm, sprm, np.zeros(n), np.zeros(n))


def lattice_hinges(cfg) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(a, b, axis) of the chain's hinges, all along x (its ``ModelSpec.hinges``)."""
    a, b = hinge_pairs(cfg.n_units, cfg.left == "periodic")
    return a, b, np.zeros(a.size, np.int64)


def varied_tables(cfg: RotatingSquaresChain) -> tuple[tuple, np.ndarray, np.ndarray]:
    """``chain_tables`` with the config's per-unit/per-hinge variation; also (mass (2N,), x (N,)).

    Lateral hinges of a unit (n_v of them) take the mean k_l, k_θ of the unit's chain hinges.
    """
    n, kl, a, m = cfg.n_units, cfg.k_long_n_per_m, cfg.a_m, cfg.mass_kg
    base = {"theta0_rad": cfg.theta0_rad, "mass_kg": m, "inertia_kg_m2": cfg.inertia_kg_m2,
            "k_long_n_per_m": kl, "k_shear_n_per_m": cfg.k_shear_n_per_m,
            "k_rot_n_m_per_rad": cfg.k_rot_n_m_per_rad}
    periodic = cfg.left == "periodic"
    ha, hb = hinge_pairs(n, periodic)
    site, hinge = variation.parameter_arrays(base, cfg.variation, np.arange(n), np.zeros(n, int), ha, hb)
    kt = hinge["k_rot_n_m_per_rad"] / (kl * a * a)
    args = chain_tables(n, site["theta0_rad"], hinge["k_shear_n_per_m"] / kl, kt,
                        cfg.n_lateral, cfg.lateral_stretch, periodic)
    hprm, sprm = args[2], args[3]
    hprm[:, H_KL] = hinge["k_long_n_per_m"] / kl
    deg = np.bincount(ha, minlength=n) + np.bincount(hb, minlength=n)
    local_kl = (np.bincount(ha, hprm[:, H_KL], n) + np.bincount(hb, hprm[:, H_KL], n)) / deg
    local_kt = (np.bincount(ha, kt, n) + np.bincount(hb, kt, n)) / deg
    sprm[:, S_KG] = cfg.n_lateral * float(cfg.lateral_stretch) * 0.5 * local_kl
    sprm[:, S_KR] = 2.0 * cfg.n_lateral * local_kt
    mass = np.concatenate([site["mass_kg"], site["inertia_kg_m2"] / a**2]) / m
    x = np.concatenate([[0.0], np.cumsum(hprm[: n - 1, H_REST])]) * a
    return args, mass, x


def build(cfg: RotatingSquaresChain) -> System:
    """The chain as a System: state (u_0..u_{N−1}, θ_0..θ_{N−1}), ends free or fixed, or a ring.

    ``cfg.variation`` makes parameters vary by unit or hinge; ``cfg.predeform`` starts the
    dynamics from the static equilibrium under an applied strain or load (``predeform.relax``).
    """
    n = cfg.n_units
    nd = nondimensional(cfg)
    scales = Scales(cfg.a_m, math.sqrt(cfg.mass_kg / cfg.k_long_n_per_m), cfg.mass_kg)
    args = chain_tables(n, cfg.theta0_rad, nd["Ks"], nd["Ktheta"], cfg.n_lateral, cfg.lateral_stretch,
                        cfg.left == "periodic")
    mass = np.concatenate([np.ones(n), np.full(n, nd["alpha2"])])
    x = np.arange(n) * cfg.a_m * math.cos(cfg.theta0_rad)
    if cfg.variation:
        args, mass, x = varied_tables(cfg)
    inv_mass = 1.0 / mass
    ends = {"left": [0], "right": [n - 1]}
    hold_fixed_ends(cfg, inv_mass, ends, n, n_fields=2)
    spacing = cfg.a_m * math.cos(cfg.theta0_rad)
    system = System(model=cfg.kind, fields=FIELDS, n_sites=n, scales=scales, mass=mass, inv_mass=inv_mass, args=args,
                    q0=np.zeros(2 * n), v0=np.zeros(2 * n), spacing_m=spacing, site_coords={"x": x},
                    shapes=partial(chain_shapes, args, x / cfg.a_m, cfg.n_lateral), ends=ends)
    if cfg.predeform is not None:
        predeform.relax(system, cfg.predeform)
    return system


def chain_shapes(args, x: np.ndarray, n_lateral: int) -> UnitShapes:
    """The chain's squares (diagonal 1, σ alternating) at x along the row, drawn as crosses, each
    hinge from the right corner of a unit to the left corner of the next; a lateral hinge joins
    the bottom (top) corner of a unit to its mirror image a cos θ0 below (above)."""
    n = x.size
    theta0 = args.site_prm[:, S_THETA0]
    sigma = np.where(np.arange(n) % 2 == 0, 1.0, -1.0)
    gap = np.cos(theta0)
    images = np.stack([-gap, gap], 1)[:, :n_lateral]
    links = np.stack([args.hinge_a, args.hinge_b], 1)
    return square_units(np.stack([x, np.zeros(n)], 1), theta0, sigma, 0.5, links,
                        np.tile([RIGHT, LEFT], (links.shape[0], 1)), outline="cross", images=images,
                        image_vertex=np.array([BOTTOM, TOP][:n_lateral], np.int64))


def launch_soliton(system: System, cfg: RotatingSquaresChain, amplitude: float, center: int, direction: int) -> None:
    """Overwrite q0, v0 with the exact continuum vector soliton (docs/physics.md §1.3).

    On a predeformed chain (``system.rest_state``) this is the prestressed soliton of
    flexmm.theory.prestressed about the rest rotation θ_s at ``center``, written as the
    displacement from the rest state (the caller adds the rest state).
    """
    from flexmm.theory.prestressed import prestressed_chain, soliton_window
    from flexmm.theory.rotating import soliton_exists, soliton_initial_state

    n = system.n_sites
    p = theory_parameters(cfg)
    rest = system.rest_state
    if rest is not None:
        theta = rest[n : 2 * n]
        near = theta[max(center - 10, 0) : center + 11]
        if np.ptp(near) > 1e-4:  # rad; the boundary layers of the ends must have decayed
            raise ValueError(f"the predeformed state is not uniform around unit {center} "
                             f"(θ varies by {np.ptp(near):.2g} rad); launch the soliton further from the ends")
        p = prestressed_chain(p, float(theta[center]))
        if not soliton_exists(p, amplitude):
            window = soliton_window(p, 1 if amplitude > 0 else -1, n=400)
            span = "none of this polarity" if window is None else f"{window[0]:.3f} to {window[1]:.3f} rad"
            raise ValueError(f"no soliton of amplitude {amplitude} rad on this predeformed chain "
                             f"(θ_s = {p.theta_s:.4f} rad; amplitudes: {span})")
    U, T, dU, dT = soliton_initial_state(p, amplitude, n, center, direction)
    system.q0[:n], system.q0[n : 2 * n] = U, T
    system.v0[:n], system.v0[n : 2 * n] = dU, dT
