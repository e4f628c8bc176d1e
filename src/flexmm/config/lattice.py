"""Lattice sections of a scene: one model per ``kind`` (see ``flexmm.models.MODELS``)."""

from __future__ import annotations

import math
from typing import ClassVar, Literal, Union

from pydantic import Field, model_validator

from flexmm.config.base import Finite, NonNegative, Positive
from flexmm.config.mass_chain import MassChain, MassGrid, MassNetwork
from flexmm.config.rigid import BistableLinkage, RotatingSquaresSheet, RigidOptions, check_variation
from flexmm.config.triangles import RotatingTrianglesChain, RotatingTrianglesSheet

EndCondition = Literal["free", "fixed", "driven"]


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
    left: EndCondition = "free"
    right: EndCondition = "free"

    @model_validator(mode="after")
    def _geometry(self):
        if not abs(self.theta0_rad) < math.pi / 4:
            raise ValueError(f"theta0_rad must satisfy |θ0| < π/4 (got {self.theta0_rad})")
        check_variation(self.variation, self.n_units, 1, self.n_units)
        return self


LatticeConfig = Union[
    RotatingSquaresChain, RotatingSquaresSheet, BistableLinkage, MassChain, MassNetwork, MassGrid,
    RotatingTrianglesChain, RotatingTrianglesSheet,
]
