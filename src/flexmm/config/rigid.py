"""Config blocks of the rigid-unit lattices (docs/physics.md §1): chain, sheet, linkage and their options.

Options shared by the rotating-squares chain and sheet:

- ``variation``: per-unit (θ0, mass, inertia) and per-hinge (k_l, k_s, k_θ) parameter fields
  (``flexmm.config.variation``, the schema every lattice shares);
- ``predeform``: static equilibrium under an applied strain or load, used as the initial state;
- ``magnets`` (sheet only): point dipoles fixed in the units (multistable rotating squares).
"""

from __future__ import annotations

import math
from typing import ClassVar, Literal

from pydantic import Field, model_validator

from flexmm.config.base import (EdgeCondition, EndCondition, Finite, NonNegative, Positive, Strict, check_periodic,
                                exactly_one)
from flexmm.config.variation import Variation, check_variations

#: parameters a variation may target (flexmm.config.variation): per unit, and per hinge
SITE_TARGETS = ("theta0_rad", "mass_kg", "inertia_kg_m2")
HINGE_TARGETS = ("k_long_n_per_m", "k_shear_n_per_m", "k_rot_n_m_per_rad")


# ---------------------------------------------------------------- predeformation
class EndLoad(Strict):
    """A constant force on an end's units (split evenly), kept during the dynamics."""

    end: Literal["left", "right", "top", "bottom"]
    force_n: Finite = Field(description="total force, positive into the lattice (compression)")


class Predeform(Strict):
    """Static equilibrium before the dynamics (energy minimisation), used as the initial state.

    ``strain_x`` (``strain_y``) holds the left/right (bottom/top) end units at displacements
    ∓ε L/2 along the axis (L = distance between the ends) during relaxation and dynamics;
    ``loads`` are constant end forces that stay on. With neither, the lattice just relaxes (e.g.
    after a θ0 variation). ``theta_guess_rad`` starts the minimiser from a uniform staggered
    rotation, which picks a branch past a buckling point. FIRE's state (residual below
    ``gradient_tolerance``) is then polished by Newton steps to round-off where the Hessian is
    positive definite (``newton``; docs/physics.md §1.2).
    """

    strain_x: Finite | None = Field(None, gt=-0.5, lt=0.5, description="nominal strain along x")
    strain_y: Finite | None = Field(None, gt=-0.5, lt=0.5, description="nominal strain along y")
    loads: list[EndLoad] = Field(default_factory=list)
    theta_guess_rad: Finite = 0.0
    gradient_tolerance: Positive = Field(1e-10, description="on the nondimensional forces")
    max_steps: int = Field(2_000_000, ge=1, description="of the FIRE minimiser")
    newton: bool = Field(True, description="polish FIRE's state with Newton steps to round-off (where the "
                         "Hessian is positive definite)")


# ---------------------------------------------------------------- magnets
class Magnets(Strict):
    """One point dipole at the middle of each face of every unit, fixed in the unit.

    A unit's hinge points are its corners (docs/physics.md §1.2), so its faces join neighbouring
    corners; the dipole sits ``recess_m`` inside the face, along the face normal. ``attract``:
    units with σ = +1 point their dipoles out, σ = −1 in, so facing magnets attract as the gap
    closes (open, clockwise and counter-clockwise states: tristable units); ``repel``: all out.
    Pair energy U = μ0/(4π r³)[m1·m2 − 3(m1·r̂)(m2·r̂)] between all magnets of neighbouring units
    (hinged, and diagonal across a void). A stiff core keeps two magnets at least 2·recess apart:
    the faces carrying them touch and the void they face is closed.
    """

    moment_a_m2: Positive = Field(description="dipole moment of each magnet (A m²)")
    recess_m: Positive = Field(description="depth of the dipole below the face (m)")
    polarity: Literal["attract", "repel"] = "attract"
    contact_stiffness_n_per_m: Positive | None = Field(
        None, description="stiffness of the core that keeps two magnets ≥ 2 recess_m apart (the faces "
        "touch); default 10 k_l"
    )


class RigidOptions(Strict):
    variation: list[Variation] = Field(default_factory=list)
    predeform: Predeform | None = None


# ---------------------------------------------------------------- lattices
class RotatingSquaresChain(RigidOptions):
    """1D chain of rigid squares joined by hinges (docs/physics.md §1.1), DOFs u and θ per unit."""

    kind: Literal["rotating_squares_chain"]
    #: per-site coordinates of the built model, in state order (models.rotating_chain.FIELDS)
    FIELD_NAMES: ClassVar[tuple[str, ...]] = ("u", "theta")

    @property
    def n_sites(self) -> int:
        """Number of units."""
        return self.n_units

    def small_copy(self, n: int):
        """The same lattice with at most ``n`` units (for cheap estimates; not validated)."""
        return self.model_copy(update={"n_units": min(self.n_units, n), "variation": [], "predeform": None})
    n_units: int = Field(ge=2, le=20_000_000, description="number of rigid units")
    a_m: Positive = Field(description="hinge-to-hinge size of a unit (m)")
    theta0_rad: Finite = Field(0.0, description="rest rotation of the units (rad)")
    k_long_n_per_m: Positive = Field(description="hinge longitudinal stiffness k_l (N/m)")
    k_shear_n_per_m: NonNegative = Field(description="hinge shear stiffness k_s (N/m)")
    k_rot_n_m_per_rad: NonNegative = Field(description="hinge rotational stiffness k_θ (N m/rad)")
    mass_kg: Positive = Field(description="unit mass m (kg)")
    inertia_kg_m2: Positive = Field(description="unit rotational inertia J (kg m²)")
    n_lateral: Literal[0, 1, 2] = Field(
        0, description="lateral hinges per unit n_v (0 single row, 2 planar wave in a sheet)"
    )
    lateral_stretch: bool = Field(
        False, description="s_v: lateral hinges resist stretching (lateral contraction blocked)"
    )
    left: EdgeCondition = Field("free", description="free, fixed, driven, or periodic (with right: a ring)")
    right: EdgeCondition = "free"

    @model_validator(mode="after")
    def _geometry(self):
        if not abs(self.theta0_rad) < math.pi / 4:
            raise ValueError(f"theta0_rad must satisfy |θ0| < π/4 (got {self.theta0_rad})")
        if check_periodic(self, "left", "right", self.n_units, "n_units", "checkerboard") and self.predeform:
            raise ValueError("a periodic chain (ring) cannot be predeformed by end loads or strains")
        check_variations(self.variation, n_cols=self.n_units, n_rows=1, site_targets=SITE_TARGETS,
                         bond_targets=HINGE_TARGETS)
        return self


class RotatingSquaresSheet(RigidOptions):
    """2D lattice of rigid squares joined at their corners (docs/physics.md §1.2), u, v, θ per unit.

    Site = row · n_cols + col; column 0 is the left edge, row 0 the bottom edge. Units are the
    squares of the checkerboard σ = (−1)^(row+col). Hinges are zero-length springs (k_l along
    the hinge axis, k_s across it, k_θ on the relative rotation); ``ligament_length_m`` > 0
    separates the hinge points by a finite ligament along the axis (same three springs, strains
    measured in the lattice frame). Mass and inertia are given, or follow from the areal density
    of a solid square of diagonal a: m = ρ a²/2, J = m a²/12.
    """

    kind: Literal["rotating_squares_sheet"]
    #: per-site coordinates of the built model, in state order (models.rotating_sheet.FIELDS)
    FIELD_NAMES: ClassVar[tuple[str, ...]] = ("u", "v", "theta")

    @property
    def n_sites(self) -> int:
        """Number of units (n_rows × n_cols)."""
        return self.n_rows * self.n_cols

    def small_copy(self, n: int):
        """The same sheet cut to at most about ``n`` units (for cheap estimates; not validated)."""
        side = max(2, int(n**0.5))
        return self.model_copy(update={"n_rows": min(self.n_rows, side), "n_cols": min(self.n_cols, side),
                                       "skew_cols": 0, "variation": [], "predeform": None})
    n_rows: int = Field(ge=1, le=100_000)
    n_cols: int = Field(ge=2, le=100_000)
    a_m: Positive = Field(description="hinge-to-hinge size (diagonal) of a unit (m)")
    theta0_rad: Finite = Field(0.0, description="rest rotation of the units (rad)")
    ligament_length_m: NonNegative = 0.0
    k_long_n_per_m: Positive
    k_shear_n_per_m: NonNegative
    k_rot_n_m_per_rad: NonNegative
    mass_kg: Positive | None = None
    inertia_kg_m2: Positive | None = None
    areal_density_kg_m2: Positive | None = None
    left: EdgeCondition = "free"
    right: EdgeCondition = "free"
    bottom: EdgeCondition = "free"
    top: EdgeCondition = "free"
    skew_cols: int = Field(
        0, description="bottom/top periodic wrap shifted by this many columns: the top row's upper "
        "neighbours are the bottom row's units skew_cols columns to the right. A sheet of n_rows rows "
        "then carries planar waves at φ = atan(skew_cols/n_rows) to the x axis (skew_cols ≡ n_rows mod 2)")
    magnets: Magnets | None = None

    @model_validator(mode="after")
    def _check(self):
        if not abs(self.theta0_rad) < math.pi / 4:
            raise ValueError(f"theta0_rad must satisfy |θ0| < π/4 (got {self.theta0_rad})")
        exactly_one(self, "mass_kg", "areal_density_kg_m2")
        for a, b, n, what in (("left", "right", self.n_cols, "n_cols"), ("bottom", "top", self.n_rows, "n_rows")):
            check_periodic(self, a, b, n, what, "checkerboard")
        if self.skew_cols:
            if self.bottom != "periodic":
                raise ValueError("skew_cols shifts the bottom/top periodic wrap: set bottom and top to periodic")
            if (self.skew_cols - self.n_rows) % 2:
                raise ValueError(f"skew_cols ({self.skew_cols}) and n_rows ({self.n_rows}) must have the same "
                                 "parity, or the wrap joins two units of the same checkerboard colour")
            if self.magnets is not None:
                raise ValueError("magnets are not supported on a skew-periodic sheet (skew_cols ≠ 0)")
        check_variations(self.variation, n_cols=self.n_cols, n_rows=self.n_rows, site_targets=SITE_TARGETS,
                         bond_targets=HINGE_TARGETS)
        return self

    @property
    def n_units(self) -> int:
        return self.n_rows * self.n_cols

    @property
    def unit_mass_kg(self) -> float:
        return self.mass_kg if self.mass_kg is not None else self.areal_density_kg_m2 * self.a_m**2 / 2

    @property
    def unit_inertia_kg_m2(self) -> float:
        return self.inertia_kg_m2 if self.inertia_kg_m2 is not None else self.unit_mass_kg * self.a_m**2 / 12


class BistableLinkage(Strict):
    """Deployable linkage: rigid crosses (two bars welded at their middles) pinned tip to tip.

    Two rows of n_cols crosses (site = row · n_cols + col); unit k (u, v, θ) has its bars at ±σ_k(θ0 + θ_k) to the axes
    (σ the checkerboard, docs/physics.md §1.2), so the soft mode is the counter-rotation of the units
    (scissor-like). Every pin carries a double well in the joint angle ψ = θ_a + θ_b,
    V′(ψ) = k ψ (ψ − βψ*)(ψ − ψ*): wells at ψ = 0 (bars at θ0) and ψ* = 2(θ_deployed − θ0),
    barrier at βψ*, released energy per joint ΔE = k ψ*⁴ (1 − 2β)/12 (0 < β < ½). Pins are stiff
    isotropic springs k_pin. ``left``/``right``: both units of the end column.
    """

    kind: Literal["bistable_linkage"]
    #: per-site coordinates of the built model, in state order (models.rotating_sheet.FIELDS)
    FIELD_NAMES: ClassVar[tuple[str, ...]] = ("u", "v", "theta")

    @property
    def n_sites(self) -> int:
        """Number of crosses (two rows)."""
        return 2 * self.n_cols

    def small_copy(self, n: int):
        """The same linkage with at most ``n`` crosses (for cheap estimates; not validated)."""
        return self.model_copy(update={"n_cols": min(self.n_cols, max(2, n // 2))})

    n_cols: int = Field(ge=2, le=1_000_000, description="units (crosses) per row; two rows")
    bar_length_m: Positive
    theta0_rad: float = Field(gt=0, lt=math.pi / 2, description="bar angle of the initial (folded) state")
    theta_deployed_rad: float = Field(gt=0, lt=math.pi / 2, description="bar angle of the other well")
    mass_kg: Positive = Field(description="mass of one cross")
    inertia_kg_m2: Positive | None = Field(None, description="of one cross; default m L²/12 (two slender bars)")
    k_pin_n_per_m: Positive
    released_energy_j: Positive = Field(description="energy released per joint switching")
    barrier_fraction: float = Field(0.3, gt=0, lt=0.5, description="β: barrier at βψ*")
    left: EndCondition = "free"
    right: EndCondition = "free"

    @model_validator(mode="after")
    def _check(self):
        if abs(self.theta_deployed_rad - self.theta0_rad) < 1e-3:
            raise ValueError("theta_deployed_rad must differ from theta0_rad")
        return self

    @property
    def n_units(self) -> int:
        return 2 * self.n_cols
