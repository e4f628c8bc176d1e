"""Config blocks of the rotating-triangles lattices (docs/physics.md §1.6): chain and kagome sheet.

Rigid equilateral triangles of side a joined at their vertices by zero-length hinges (k_l along
the hinge axis, k_s across it, k_θ on the relative rotation). Neighbouring triangles point up and
down (σ = ±1) and rotate in opposite senses; θ is the staggered rotation, θ0 the rest twist.
"""

from __future__ import annotations

import math
from typing import ClassVar, Literal

from pydantic import Field, model_validator

from flexmm.config.base import EdgeCondition, Finite, GridUnits, NonNegative, Positive, Strict, check_periodic
from flexmm.config.rigid import HINGE_TARGETS
from flexmm.config.variation import Variation, check_variations

#: the hexagonal pores of the kagome close when neighbouring triangles have turned by 2|θ0| = 120°
MAX_TWIST_RAD = math.pi / 3
#: per-triangle variation targets (the twist θ0 is the lattice's geometry: uniform); per hinge: HINGE_TARGETS
UNIT_TARGETS = ("mass_kg", "inertia_kg_m2")


class _TriangleUnits(Strict):
    """Parameters shared by the chain and the sheet."""

    a_m: Positive = Field(description="side of a triangle = distance between two of its hinges (m)")
    theta0_rad: Finite = Field(0.0, description="rest twist of the triangles (rad; 0: straight kagome)")
    k_long_n_per_m: Positive = Field(description="hinge stiffness along the hinge axis k_l (N/m)")
    k_shear_n_per_m: NonNegative = Field(description="hinge stiffness across the hinge axis k_s (N/m)")
    k_rot_n_m_per_rad: NonNegative = Field(description="hinge rotational stiffness k_θ (N m/rad)")
    mass_kg: Positive = Field(description="mass of one triangle m (kg)")
    inertia_kg_m2: Positive | None = Field(
        None, description="rotational inertia J of one triangle about its centroid (kg m²); default m a²/12 "
        "(a solid equilateral triangle)")
    variation: list[Variation] = Field(
        default_factory=list, description="per-triangle mass_kg, inertia_kg_m2 and per-hinge k_long_n_per_m, "
        "k_shear_n_per_m, k_rot_n_m_per_rad (docs/scenes.md, Parameter variation)")

    @property
    def unit_inertia_kg_m2(self) -> float:
        return self.inertia_kg_m2 if self.inertia_kg_m2 is not None else self.mass_kg * self.a_m**2 / 12

    def _check_twist(self) -> None:
        if not abs(self.theta0_rad) < MAX_TWIST_RAD:
            raise ValueError(f"theta0_rad must satisfy |θ0| < π/3 (the pores close at π/3), got {self.theta0_rad}")

    def _check_variation(self, n_cols: int, n_rows: int) -> None:
        check_variations(self.variation, n_cols=n_cols, n_rows=n_rows, site_targets=UNIT_TARGETS,
                         bond_targets=HINGE_TARGETS)


_ALTERNATE = "up and down triangles alternate"


class RotatingTrianglesChain(_TriangleUnits):
    """A strip of rigid triangles, alternately pointing up and down, hinged vertex to vertex
    (docs/physics.md §1.6); u, v, θ per triangle. Unit 0 points up; its centroid is the origin."""

    kind: Literal["rotating_triangles_chain"]
    #: per-site coordinates of the built model, in state order (models.rotating_triangles.FIELDS)
    FIELD_NAMES: ClassVar[tuple[str, ...]] = ("u", "v", "theta")

    n_units: int = Field(ge=2, le=20_000_000, description="number of triangles")
    left: EdgeCondition = "free"
    right: EdgeCondition = "free"

    @property
    def n_sites(self) -> int:
        return self.n_units

    def small_copy(self, n: int):
        """The same chain with at most ``n`` units (for cheap estimates; not validated)."""
        m = min(self.n_units, n)
        return self.model_copy(update={"n_units": m + (m % 2 if self.left == "periodic" else 0), "variation": []})

    @model_validator(mode="after")
    def _check(self):
        self._check_twist()
        check_periodic(self, "left", "right", self.n_units, "n_units", _ALTERNATE)
        self._check_variation(self.n_units, 1)
        return self


class RotatingTrianglesSheet(_TriangleUnits, GridUnits):
    """A kagome sheet of rigid triangles (docs/physics.md §1.6): n_rows zig-zag rows of n_cols
    triangles; site = row · n_cols + col, the triangle at (row, col) points up if row + col is
    even. Every triangle is hinged to its left and right neighbours, an up triangle also to the
    (down) triangle above it; u, v, θ per triangle."""

    kind: Literal["rotating_triangles_sheet"]
    #: per-site coordinates of the built model, in state order (models.rotating_triangles.FIELDS)
    FIELD_NAMES: ClassVar[tuple[str, ...]] = ("u", "v", "theta")

    def small_copy(self, n: int):
        """The same sheet cut to at most about ``n`` units, an even side (for cheap estimates; not validated)."""
        return self.grid_copy(n, even=True)

    @model_validator(mode="after")
    def _check(self):
        self._check_twist()
        check_periodic(self, "left", "right", self.n_cols, "n_cols", _ALTERNATE)
        check_periodic(self, "bottom", "top", self.n_rows, "n_rows", _ALTERNATE)
        self._check_variation(self.n_cols, self.n_rows)
        return self
