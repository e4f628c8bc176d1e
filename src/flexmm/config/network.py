"""Config block of the general rigid-unit network (docs/physics.md §1.9).

Rigid polygons joined vertex to vertex by ligaments, each with the paper's three linear springs
(k_l along its axis, k_s across it, k_θ on the relative rotation of the two units). The geometry
comes from a generator: ``rotating_squares`` (the units of ``rotating_squares_sheet``, any θ0 and
ligament length, rotations unstaggered) or ``random_quads`` (the same lattice with every vertex of
every unit moved at random by up to ``vertex_jitter`` of a, seeded: the quads of a disordered sheet)
or ``rotating_triangles`` (the kagome of docs/physics.md §1.6). ``ligament_law`` chooses the
ligaments' law (the paper's springs, or DifFlexMM's with nonlinear or linearised strains) and
``contact`` adds an energy-based contact between units that share a pore.
"""

from __future__ import annotations

import math
from typing import ClassVar, Literal

from pydantic import Field, model_validator

from flexmm.config.base import Finite, GridUnits, NonNegative, Positive, Strict


class UnitContact(Strict):
    """Vertex–edge contact between units that share a pore: E = ½ k (c − d)³/d for a vertex at
    distance d < c from a facing edge (docs/physics.md §1.9)."""

    stiffness_n_per_m: Positive = Field(
        description="contact stiffness k (N/m): −dF/dd = k[(c/d)³ − 1], k at d = 0.79 c, 7k at c/2")
    cutoff_m: Positive = Field(description="distance c (m) below which a vertex and an edge repel")


class RigidNetwork(GridUnits):
    """Rigid polygons joined by ligaments at their vertices, from a geometry generator; u, v, θ
    per unit (θ the rotation from the reference geometry, not staggered). Unit = row · n_cols + col."""

    kind: Literal["rigid_network"]
    #: per-site coordinates of the built model, in state order (models.network.FIELDS)
    FIELD_NAMES: ClassVar[tuple[str, ...]] = ("u", "v", "theta")

    pattern: Literal["rotating_squares", "random_quads", "rotating_triangles"] = Field(
        "rotating_squares", description="geometry generator: squares of diagonal a at rest rotations ±θ0 "
        "(checkerboard), the same with every vertex moved at random (random_quads), or the kagome of "
        "equilateral triangles of side a twisted by ±θ0 (rotating_triangles)")
    a_m: Positive = Field(description="vertex-to-vertex size of a unit (m): a square's diagonal, a triangle's side")
    theta0_rad: Finite = Field(0.0, description="rest rotation of the units (rad), alternating in sign")
    ligament_length_m: NonNegative = Field(0.0, description="rest length of every ligament (m)")
    vertex_jitter: NonNegative = Field(
        0.0, le=0.2, description="random_quads: largest vertex displacement as a fraction of a")
    seed: int = Field(0, ge=0, description="random_quads: seed of the vertex displacements")
    k_long_n_per_m: Positive = Field(description="ligament stiffness along its axis k_l (N/m)")
    k_shear_n_per_m: NonNegative = Field(description="ligament stiffness across its axis k_s (N/m)")
    k_rot_n_m_per_rad: NonNegative = Field(description="ligament rotational stiffness k_θ (N m/rad)")
    areal_density_kg_m2: Positive = Field(
        description="mass per area of the units: each unit's mass and polar inertia follow from its polygon")
    ligament_law: Literal["paper", "difflexmm", "difflexmm_linear"] = Field(
        "paper", description="the ligaments' law: the paper's three linear springs on the gap, or DifFlexMM's "
        "ligament with nonlinear (difflexmm) or linearised (difflexmm_linear) axial, shear and rotational strains")
    contact: UnitContact | None = Field(
        None, description="energy-based contact between units sharing a pore (none: units may overlap)")

    def small_copy(self, n: int):
        """The same network cut to at most about ``n`` units (for cheap estimates; not validated)."""
        return self.grid_copy(n)

    @model_validator(mode="after")
    def _check(self):
        for a, b in (("left", "right"), ("bottom", "top")):
            if "periodic" in (getattr(self, a), getattr(self, b)):
                raise ValueError(f"{a}/{b}: a rigid_network's edges are free or fixed (periodic is not supported yet)")
        if self.pattern != "random_quads" and self.vertex_jitter:
            raise ValueError("vertex_jitter moves the vertices of random_quads: set pattern: random_quads")
        if self.ligament_law == "difflexmm" and not self.ligament_length_m:
            raise ValueError("ligament_law difflexmm measures the bond's stretch and angle: it needs "
                             "ligament_length_m > 0")
        if self.pattern == "rotating_triangles":
            if self.ligament_length_m:
                raise ValueError("rotating_triangles are hinged vertex to vertex: ligament_length_m must be 0")
            if not abs(self.theta0_rad) < math.pi / 3:
                raise ValueError(f"rotating_triangles: |theta0_rad| < π/3 (the pores close), got {self.theta0_rad}")
        return self
