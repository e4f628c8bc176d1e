"""Per-unit and per-hinge parameters of the rigid-unit lattices, from a run's stored config alone.

The render layer does not rebuild models (docs/architecture.md, layers); what it needs of a lattice
— rest rotations θ0 per unit, masses and inertias, hinge stiffnesses, the hinge list — is computed
here from the validated lattice config with the builders' own functions (their hinge lists and
checkerboard, the linkage's joint stiffness, variations by ``models.variation``).
``tests/render/test_energy.py`` checks every array against the built model.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from flexmm.models import rotating_chain
from flexmm.models.energies import joint_energies
from flexmm.models.hinge import S_KG, S_KR
from flexmm.models.linkage import joint_stiffness
from flexmm.models import lattice_hinges
from flexmm.models.rotating_sheet import checkerboard
from flexmm.models.variation import parameter_arrays


@dataclass
class RigidParams:
    """A rigid-unit lattice in SI: units (N,), hinges (H,) and how to draw them.

    ``half_m``: centre-to-hinge distance (a/2 or L/2); ``sigma`` the checkerboard sign;
    ``hinge_a/b`` the units a hinge joins, ``hinge_axis`` 0 horizontal (right corner of A to
    left corner of B) or 1 vertical (top of A to bottom of B), ``hinge_wrap`` True for the
    periodic wraps (not drawn); ``ligament_m`` the hinge points' rest separation.
    """

    kind: str
    n_rows: int
    n_cols: int
    half_m: float
    theta0_rad: np.ndarray
    sigma: np.ndarray
    mass_kg: np.ndarray
    inertia_kg_m2: np.ndarray
    hinge_a: np.ndarray
    hinge_b: np.ndarray
    hinge_axis: np.ndarray
    hinge_wrap: np.ndarray
    k_long_n_per_m: np.ndarray
    k_shear_n_per_m: np.ndarray
    k_rot_n_m_per_rad: np.ndarray
    ligament_m: float = 0.0
    n_lateral: int = 0
    #: a chain's lateral hinges as the builder's on-site law: (k_g, k_r) per unit (N, 2) in J, or None
    lateral_j: np.ndarray | None = None
    #: bistable joints of the linkage: (k J, β, ψ* rad), or None
    joint: tuple[float, float, float] | None = None
    #: face magnets of a sheet: (recess_m, polarity) or None
    magnets: tuple[float, str] | None = None

    @property
    def n_units(self) -> int:
        """Number of units."""
        return self.theta0_rad.size


def rigid_params(lat) -> RigidParams | None:
    """The RigidParams of a rotating_squares_chain, rotating_squares_sheet or bistable_linkage
    config (what the energy and well colourings read); None for other lattices."""
    make = {"rotating_squares_chain": _chain, "rotating_squares_sheet": _sheet, "bistable_linkage": _linkage}.get(lat.kind)
    return None if make is None else make(lat)


def _base(lat, mass: float, inertia: float) -> dict:
    return {"theta0_rad": lat.theta0_rad, "mass_kg": mass, "inertia_kg_m2": inertia,
            "k_long_n_per_m": lat.k_long_n_per_m, "k_shear_n_per_m": lat.k_shear_n_per_m,
            "k_rot_n_m_per_rad": lat.k_rot_n_m_per_rad}


def _chain(lat) -> RigidParams:
    n = lat.n_units
    ha, hb, axis, wrap = lattice_hinges(lat)
    sites, hinges = parameter_arrays(_base(lat, lat.mass_kg, lat.inertia_kg_m2), lat.variation,
                                     np.arange(n), np.zeros(n, np.int64), ha, hb)
    return RigidParams(
        lat.kind, 1, n, lat.a_m / 2, sites["theta0_rad"], checkerboard(1, n), sites["mass_kg"],
        sites["inertia_kg_m2"], ha, hb, axis, wrap, hinges["k_long_n_per_m"], hinges["k_shear_n_per_m"],
        hinges["k_rot_n_m_per_rad"], n_lateral=lat.n_lateral,
        lateral_j=rotating_chain.varied_tables(lat)[0].site_prm[:, [S_KG, S_KR]] * lat.k_long_n_per_m * lat.a_m**2)


def _sheet(lat) -> RigidParams:
    nr, nc = lat.n_rows, lat.n_cols
    ha, hb, axis, wrap = lattice_hinges(lat)
    row, col = np.divmod(np.arange(nr * nc), nc)
    sites, hinges = parameter_arrays(_base(lat, lat.unit_mass_kg, lat.unit_inertia_kg_m2), lat.variation, col, row, ha, hb)
    magnets = None if lat.magnets is None else (lat.magnets.recess_m, lat.magnets.polarity)
    return RigidParams(
        lat.kind, nr, nc, lat.a_m / 2, sites["theta0_rad"], checkerboard(nr, nc), sites["mass_kg"],
        sites["inertia_kg_m2"], ha, hb, axis, wrap, hinges["k_long_n_per_m"], hinges["k_shear_n_per_m"],
        hinges["k_rot_n_m_per_rad"], ligament_m=lat.ligament_length_m, magnets=magnets)


def _linkage(lat) -> RigidParams:
    nc, L, m = lat.n_cols, lat.bar_length_m, lat.mass_kg
    n = 2 * nc
    J = lat.inertia_kg_m2 if lat.inertia_kg_m2 is not None else m * L * L / 12
    ha, hb, axis, wrap = lattice_hinges(lat)
    switch = 2.0 * (lat.theta_deployed_rad - lat.theta0_rad)
    k = joint_stiffness(lat.released_energy_j, switch, lat.barrier_fraction)  # in J: ΔE is in J
    nh = ha.size
    return RigidParams(
        lat.kind, 2, nc, L / 2, np.full(n, lat.theta0_rad), checkerboard(2, nc), np.full(n, m), np.full(n, J),
        ha, hb, axis, wrap, np.full(nh, lat.k_pin_n_per_m), np.full(nh, lat.k_pin_n_per_m), np.zeros(nh),
        joint=(k, lat.barrier_fraction, switch))


def joint_energy_j(psi, joint: tuple[float, float, float]) -> np.ndarray:
    """Double-well energy (J) of a linkage joint at ψ (rad; any shape): the model's joint law
    (``models.joints.joint_law``) with k in J."""
    psi = np.asarray(psi, float)
    out = np.empty(psi.size)
    joint_energies(np.ascontiguousarray(psi.ravel()), np.asarray(joint, float), out)
    return out.reshape(psi.shape)


def lateral_energy_j(p: RigidParams, theta) -> np.ndarray:
    """Energy (J) of a chain unit's lateral hinges (docs/physics.md §1.1), shape like ``theta``:
    the builder's on-site law ½ k_g (cos θ0 − cos(θ0 + θ))² + ½ k_r θ² on its rows (``lateral_j``)."""
    if p.n_lateral == 0 or p.lateral_j is None:
        return np.zeros_like(theta)
    g = np.cos(p.theta0_rad) - np.cos(p.theta0_rad + theta)
    return 0.5 * (p.lateral_j[:, 0] * g * g + p.lateral_j[:, 1] * theta * theta)


__all__ = ["RigidParams", "joint_energy_j", "lateral_energy_j", "rigid_params"]
