"""Config block of the general rigid-unit network (docs/physics.md §1.9).

Rigid polygons joined vertex to vertex by ligaments, each with the paper's three linear springs
(k_l along its axis, k_s across it, k_θ on the relative rotation of the two units). The geometry
comes from a generator: ``rotating_squares`` (the units of ``rotating_squares_sheet``, any θ0 and
ligament length, rotations unstaggered) or ``random_quads`` (the same lattice with every vertex of
every unit moved at random by up to ``vertex_jitter`` of a, seeded: the quads of a disordered sheet)
or ``rotating_triangles`` (the kagome of docs/physics.md §1.6) or ``rotating_hexagons`` (that kagome
with regular hexagons, joined at alternate vertices) or ``rectangles`` (the squares' sheet with
rectangles of side ratio ``aspect_ratio``); or from a geometry file (``geometry``,
``config.geometry``). A ``mask`` cuts a generated sheet to an outline with holes; named unit sets
(``unit_sets``, and a file's ``sets``) are what ``fixed_units`` clamps and excitations drive
(``excitation.units``). ``ligament_law`` chooses the
ligaments' law (the paper's springs, or DifFlexMM's with nonlinear or linearised strains) and
``contact`` adds an energy-based contact between units that share a pore.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import ClassVar, Literal

from pydantic import Field, ValidationInfo, model_validator

from flexmm.config.base import Finite, GridUnits, NonNegative, Positive, Strict, check_periodic
from flexmm.config.geometry import Point, UnitSet, raw_geometry, resolved_path, set_names

#: the patterns a generator makes (``models.network.geometry``)
Pattern = Literal["rotating_squares", "random_quads", "rotating_triangles", "rotating_hexagons", "rectangles"]


class Hole(Strict):
    """A hole of a mask: a circle or a polygon; units whose centre lies inside are removed."""

    circle_m: list[Finite] | None = Field(None, min_length=3, max_length=3, description="[x, y, radius] (m)")
    polygon_m: list[Point] | None = Field(None, min_length=3, description="vertices in order (m)")

    @model_validator(mode="after")
    def _one(self):
        if (self.circle_m is None) == (self.polygon_m is None):
            raise ValueError("give exactly one of circle_m or polygon_m")
        if self.circle_m is not None and not self.circle_m[2] > 0:
            raise ValueError(f"circle_m {self.circle_m}: the radius must be positive")
        return self


class Mask(Strict):
    """Cut a generated sheet: keep the units whose reference centre lies inside ``outline_m`` (a
    polygon; default the whole sheet) and outside every hole, with the ligaments between kept units.
    The kept units are numbered in grid order; ``lattice.n_units`` still counts the whole grid (the
    config does not build the geometry), so cost estimates are upper bounds: address units of a
    masked sheet by named sets (box, circle) rather than by index."""

    outline_m: list[Point] | None = Field(None, min_length=3, description="outline polygon, vertices in order (m)")
    holes: list[Hole] = Field(default_factory=list)

    @model_validator(mode="after")
    def _something(self):
        if self.outline_m is None and not self.holes:
            raise ValueError("a mask needs an outline_m or holes")
        return self


class UnitContact(Strict):
    """Vertex–edge contact between units that share a pore: E = ½ k (c − d)³/d for a vertex at
    distance d < c from a facing edge (docs/physics.md §1.9)."""

    stiffness_n_per_m: Positive = Field(
        description="contact stiffness k (N/m): −dF/dd = k[(c/d)³ − 1], k at d = 0.79 c, 7k at c/2")
    cutoff_m: Positive = Field(description="distance c (m) below which a vertex and an edge repel")


class Region(Strict):
    """A part of a network with its own ligaments and density (an interface between two materials, a
    stiff inclusion): the units of a named unit set (``units``); the fields given replace the
    lattice's for the ligaments between two of its units and for its units' mass. A ligament joining a
    unit of the region to a unit outside it (the interface) is two half-ligaments in series: each
    stiffness is 2 k₁k₂/(k₁ + k₂) of the two sides' (docs/physics.md §1.9). Springs a geometry file
    gives a ligament stay the file's. A region of rotating squares may have its own rest rotation
    ``theta0_rad`` on the lattice's grid of centres; the ligaments across its boundary must then reach:
    each no longer than the longer of the two sides' ligaments (``RigidNetwork.interface_issue``).
    ``ligament_law`` mixes the paper's law and DifFlexMM's linearised one (the network runs the
    latter, whose ℓ = 0 case is the paper's law): the region's inner ligaments take it, those across
    its boundary the lattice's."""

    units: str = Field(description="the named unit set (lattice.unit_sets, a geometry file's sets) of the region")
    k_long_n_per_m: Positive | None = None
    k_shear_n_per_m: NonNegative | None = None
    k_rot_n_m_per_rad: NonNegative | None = None
    areal_density_kg_m2: Positive | None = Field(
        None, description="the region's units' mass per area (units whose mass a geometry file gives keep it)")
    theta0_rad: Finite | None = Field(
        None, description="rotating_squares: the region's rest rotation (its units turn ±θ0 about the lattice's "
        "centres; its ligaments span the rest of the pitch, pitch − a cos θ0)")
    ligament_law: Literal["paper", "difflexmm_linear"] | None = Field(
        None, description="the law of the ligaments between two of the region's units (paper or difflexmm_linear; "
        "those across its boundary keep the lattice's)")

    @model_validator(mode="after")
    def _something(self):
        if all(getattr(self, k) is None for k in REGION_FIELDS):
            raise ValueError(f"a region changes at least one of {', '.join(REGION_FIELDS)}")
        return self


#: the lattice fields a region may replace
REGION_FIELDS = ("k_long_n_per_m", "k_shear_n_per_m", "k_rot_n_m_per_rad", "areal_density_kg_m2", "theta0_rad",
                 "ligament_law")


class RigidNetwork(GridUnits):
    """Rigid polygons joined by ligaments at their vertices, from a geometry generator; u, v, θ
    per unit (θ the rotation from the reference geometry, not staggered). Unit = row · n_cols + col."""

    kind: Literal["rigid_network"]
    #: per-site coordinates of the built model, in state order (models.network.FIELDS)
    FIELD_NAMES: ClassVar[tuple[str, ...]] = ("u", "v", "theta")

    pattern: Pattern = Field(
        "rotating_squares", description="geometry generator: squares of diagonal a at rest rotations ±θ0 "
        "(checkerboard), the same with every vertex moved at random (random_quads), the kagome of "
        "equilateral triangles of side a twisted by ±θ0 (rotating_triangles), that kagome of regular "
        "hexagons of side a (rotating_hexagons), or rectangles of diagonal a (rectangles)")
    a_m: Positive = Field(description="vertex-to-vertex size of a unit (m): a square's or rectangle's diagonal, "
                          "a triangle's or hexagon's side; with a geometry file its default is the units' median size")
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

    aspect_ratio: float = Field(1.0, gt=0.0, le=1.0, description="rectangles: short side / long side "
                                "(1: the squares)")
    geometry: str | None = Field(None, description="a geometry file (YAML: units, ligaments, sets; "
                                 "config.geometry) instead of a generator; relative to the config file")
    mask: Mask | None = Field(None, description="generated sheets: keep the units inside an outline and "
                              "outside holes")
    unit_sets: dict[str, UnitSet] = Field(default_factory=dict, description="named unit sets (listed, box, "
                                          "circle) for fixed_units and excitation.units")
    fixed_units: list[str] = Field(default_factory=list, description="named unit sets whose units are held "
                                   "(every DOF)")
    regions: list[Region] = Field(default_factory=list, description="parts of the network (named unit sets, "
                                  "no unit in two) with their own ligament stiffnesses and density: interfaces")

    @model_validator(mode="before")
    @classmethod
    def _from_file(cls, data, info: ValidationInfo):
        """A geometry file sets the unit count (one row of N units) and, by default, a_m."""
        if not isinstance(data, dict) or not isinstance(data.get("geometry"), str):
            return data
        path = resolved_path(data["geometry"], (info.context or {}).get("base_dir"))
        if not Path(path).is_file():
            raise ValueError(f"geometry file {path!r} not found")
        units = raw_geometry(path)["units"]
        n = len(units)
        data = dict(data, geometry=path)
        for key, value in (("n_rows", 1), ("n_cols", n)):
            if data.setdefault(key, value) != value:
                raise ValueError(f"{key}: the geometry file gives {n} units in one row (n_rows 1, n_cols {n}); "
                                 "leave n_rows and n_cols out")
        if "a_m" not in data:
            try:
                sizes = sorted(max(math.dist(p, q) for p in u["vertices_m"] for q in u["vertices_m"]) for u in units)
            except (TypeError, KeyError, ValueError):
                sizes = None
            # a malformed unit: a placeholder scale, the file's schema check when it is built says where
            data["a_m"] = sizes[len(sizes) // 2] if sizes and sizes[len(sizes) // 2] > 0 else 1.0
        return data

    def pitch_m(self) -> float:
        """The distance between neighbouring rotating squares (m): a cos θ0 + ℓ."""
        return self.a_m * math.cos(self.theta0_rad) + self.ligament_length_m

    def region_lattice(self, region: Region | None = None) -> "RigidNetwork":
        """This lattice with no regions and the fields ``region`` gives in place of its own: the
        uniform medium of that part of the network. A region's own θ0 keeps the lattice's pitch, its
        ligaments spanning the rest (pitch − a cos θ0)."""
        update: dict = {"regions": []}
        if region is not None:
            update |= {k: getattr(region, k) for k in REGION_FIELDS if getattr(region, k) is not None}
            if region.theta0_rad is not None:
                update["ligament_length_m"] = max(self.pitch_m() - self.a_m * math.cos(region.theta0_rad), 0.0)
        return self.model_copy(update=update)

    def interface_issue(self, first: Region | None, second: Region | None) -> str | None:
        """Why the ligaments between the squares of two media (None: the lattice's) cannot join them,
        or None: a medium's squares wider than the pitch, or an interface ligament (right vertex of
        one square to the left vertex of its neighbour, rest rotations ±θ₁ and ∓θ₂) longer than the
        longer of the two media's ligaments, (p − a(cos θ₁ + cos θ₂)/2, a(sin θ₂ − sin θ₁)/2)."""
        sides = [self.region_lattice(r) for r in (first, second)]
        for side, region in zip(sides, (first, second)):
            if region is not None and region.theta0_rad is not None and \
                    self.a_m * math.cos(region.theta0_rad) > self.pitch_m() * (1 + 1e-12):
                return (f"region {region.units!r}: its squares at theta0_rad = {region.theta0_rad:g} are wider "
                        f"({self.a_m * math.cos(region.theta0_rad):.4g} m) than the pitch {self.pitch_m():.4g} m")
        t1, t2 = (s.theta0_rad for s in sides)
        gap = math.hypot(self.pitch_m() - 0.5 * self.a_m * (math.cos(t1) + math.cos(t2)),
                         0.5 * self.a_m * (math.sin(t2) - math.sin(t1)))
        reach = max(s.ligament_length_m for s in sides)
        if gap > reach + 1e-9 * self.a_m:
            names = " and ".join("the lattice" if r is None else f"region {r.units!r}" for r in (first, second))
            return (f"the squares of {names} (theta0_rad {t1:g}, {t2:g}) do not meet: the ligaments between them "
                    f"would be {gap:.4g} m long, longer than either side's ({reach:.4g} m); make the rotations "
                    "closer or the ligaments longer (ligament_length_m)")
        return None

    def unit_set_names(self) -> list[str]:
        """The names ``fixed_units`` and ``excitation.units`` may use: ``unit_sets`` and the file's ``sets``."""
        names = list(self.unit_sets)
        if self.geometry is not None:
            names += set_names(raw_geometry(self.geometry))
        return names

    @property
    def trim_issue(self) -> str | None:
        """Why the planner may not cut the sheet along x (None: it may)."""
        if self.geometry is not None:
            return "the units come from a geometry file"
        if self.mask is not None:
            return "the sheet is masked"
        if self.unit_sets:
            return "named unit sets are placed on the whole sheet"
        if self.regions:
            return "the network has regions"
        if self.periodic_axes:
            return "the sheet is periodic"
        return None

    @property
    def periodic_axes(self) -> tuple[str, ...]:
        """The directions a generated sheet wraps around in (``x``: left/right periodic, ``y``: bottom/top)."""
        return tuple(ax for ax, end in (("x", self.left), ("y", self.bottom)) if end == "periodic")

    def small_copy(self, n: int):
        """The same network cut to at most about ``n`` units (for cheap estimates; not validated); a
        network whose units are not a full grid, or carry named sets placed on it, whole."""
        return self if self.trim_issue else self.grid_copy(n)

    @model_validator(mode="after")
    def _check(self):
        for a, b, n, what in (("left", "right", self.n_cols, "n_cols"), ("bottom", "top", self.n_rows, "n_rows")):
            if check_periodic(self, a, b, n, what, "the units alternate"):
                why = ("the geometry file gives its periods (lattice_vectors_m)" if self.geometry is not None
                       else "a mask cuts the sheet" if self.mask is not None
                       else None)
                if why:
                    raise ValueError(f"{a}/{b} periodic: {why}")
        if self.geometry is not None:
            given = [k for k in ("pattern", "theta0_rad", "ligament_length_m", "vertex_jitter", "seed",
                                 "aspect_ratio", "mask") if getattr(self, k) != type(self).model_fields[k].default]
            if given:
                raise ValueError(f"geometry: the file gives the units and ligaments; remove {', '.join(given)}")
        names = self.unit_set_names()
        if len(set(names)) != len(names):
            raise ValueError(f"unit_sets: a name is given twice (here and in the geometry file): {names}")
        for what, used in (("fixed_units", self.fixed_units), ("regions", [r.units for r in self.regions])):
            unknown = [s for s in used if s not in names]
            if unknown:
                raise ValueError(f"{what} {unknown}: not a named unit set (unit_sets"
                                 f"{', geometry sets' if self.geometry else ''}: {', '.join(names) or 'none'})")
        tilted = [r for r in self.regions if r.theta0_rad is not None]
        if tilted and (self.pattern != "rotating_squares" or self.geometry is not None):
            raise ValueError(f"regions.{self.regions.index(tilted[0])}.theta0_rad: a region's own rest rotation "
                             "turns the squares of pattern rotating_squares (not a geometry file or another pattern)")
        for i, first in enumerate([None, *self.regions]):
            for second in self.regions[i:]:
                if first is not None and first.theta0_rad is None and second.theta0_rad is None:
                    continue
                issue = self.interface_issue(first, second)
                if issue:
                    at = second if second.theta0_rad is not None else first
                    raise ValueError(f"regions.{self.regions.index(at)}.theta0_rad: {issue}")
        mixed = [r for r in self.regions if r.ligament_law not in (None, self.ligament_law)]
        if mixed and self.ligament_law == "difflexmm":
            raise ValueError(f"regions.{self.regions.index(mixed[0])}.ligament_law: the nonlinear difflexmm law "
                             "cannot share a network with another law (one law per network kernel); use "
                             "difflexmm_linear for the lattice")
        if self.pattern != "rectangles" and self.aspect_ratio != 1.0:
            raise ValueError("aspect_ratio shapes the units of rectangles: set pattern: rectangles")
        if self.pattern != "random_quads" and self.vertex_jitter:
            raise ValueError("vertex_jitter moves the vertices of random_quads: set pattern: random_quads")
        if self.ligament_law == "difflexmm" and not self.ligament_length_m:
            raise ValueError("ligament_law difflexmm measures the bond's stretch and angle: it needs "
                             "ligament_length_m > 0")
        if self.pattern in ("rotating_triangles", "rotating_hexagons"):
            if self.ligament_length_m:
                raise ValueError(f"{self.pattern} are hinged vertex to vertex: ligament_length_m must be 0")
            limit = math.pi / 3 if self.pattern == "rotating_triangles" else math.pi / 6
            if not abs(self.theta0_rad) < limit:
                raise ValueError(f"{self.pattern}: |theta0_rad| < {'π/3' if limit > 1 else 'π/6'} (the pores "
                                 f"close), got {self.theta0_rad}")
        return self
