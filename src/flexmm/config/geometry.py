"""The geometry file of a rigid network (``lattice: {kind: rigid_network, geometry: FILE}``) and
the named unit sets a network's clamps and drives act on (docs/physics.md §1.9, docs/scenes.md).

A geometry file is YAML, lengths in metres::

    units:                      # rigid convex polygons, vertices in order (either sense)
      - vertices_m: [[0, 0], [0.01, 0], [0.01, 0.01], [0, 0.01]]
      - vertices_m: [[0.011, 0], [0.021, 0], [0.021, 0.01], [0.011, 0.01]]
        mass_kg: 2.0e-3         # optional, with inertia_kg_m2 (polar, about the centroid);
        inertia_kg_m2: 3.3e-8   # default: lattice.areal_density_kg_m2 times the polygon
    ligaments:                  # vertex i of unit a to vertex j of unit b (indices from 0)
      - {a: 0, i: 1, b: 1, j: 0}
      - {a: 0, i: 2, b: 1, j: 3, rest_gap_m: [0.001, 0], axis: [1, 0], k_shear_n_per_m: 500}
    sets:                       # named unit sets for lattice.fixed_units and excitation.units
      left: {box_m: [-1, -1, 0.005, 1]}

With ``lattice_vectors_m: [[x1, y1]]`` or ``[[x1, y1], [x2, y2]]`` (m) the file's units are one cell
repeated by those vectors, and a ligament with ``shift: [s]`` (or ``[s1, s2]``, each −1, 0 or 1) joins vertex i of a
to vertex j of the copy of b in the cell displaced by s1 times the first vector plus s2 times the
second: the links that cross the cell's boundary, which wrap around in a run (a unit may be linked
to its own copy). The network is then periodic: its runs wrap and ``linear.network`` gives its
Bloch bands.

A ligament's ``rest_gap_m`` is its rest vector from vertex i of a to vertex j of b (default: the
two vertices' separation in the file, so the file's geometry is stress-free); its ``axis`` the
direction of its longitudinal spring (default: along the rest gap, or from the centroid of a to
that of b when the gap is shorter than 10⁻⁹ of the units' size); its stiffnesses default to the
lattice's. The schema is ``GeometryFile``; it is checked, and the geometry itself — convex,
simple polygons without repeated vertices, no two units overlapping, ligaments naming existing
units and vertices, one connected piece (``models.geometry.geometry_issues``) — when the network
is built (``models.network.read_geometry``), every fault reported at its file:line. A scene's
validation reads only the number of units and the set names (``raw_geometry``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

from pydantic import Field, model_validator

from flexmm.config.base import Finite, NonNegative, Positive, Strict

Point = Annotated[list[Finite], Field(min_length=2, max_length=2)]


class UnitSet(Strict):
    """A named set of units: listed, the units whose reference centre lies in a box, or in a circle."""

    units: list[Annotated[int, Field(ge=0)]] | None = Field(None, min_length=1, description="unit indices")
    box_m: list[Finite] | None = Field(None, min_length=4, max_length=4,
                                       description="[x_min, y_min, x_max, y_max] of the units' centres (m)")
    circle_m: list[Finite] | None = Field(None, min_length=3, max_length=3,
                                          description="[x, y, radius] around the units' centres (m)")

    @model_validator(mode="after")
    def _one(self):
        given = [k for k in ("units", "box_m", "circle_m") if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError("give exactly one of units, box_m or circle_m")
        if self.box_m is not None and not (self.box_m[0] < self.box_m[2] and self.box_m[1] < self.box_m[3]):
            raise ValueError(f"box_m {self.box_m}: need x_min < x_max and y_min < y_max")
        if self.circle_m is not None and not self.circle_m[2] > 0:
            raise ValueError(f"circle_m {self.circle_m}: the radius must be positive")
        return self


class GeometryUnit(Strict):
    """One rigid unit: its polygon (m), and optionally its mass and polar inertia."""

    vertices_m: list[Point] = Field(min_length=3, max_length=64, description="polygon vertices in order (m)")
    mass_kg: Positive | None = None
    inertia_kg_m2: Positive | None = Field(None, description="polar moment of inertia about the centroid")

    @model_validator(mode="after")
    def _both(self):
        if (self.mass_kg is None) != (self.inertia_kg_m2 is None):
            raise ValueError("give both mass_kg and inertia_kg_m2, or neither (then both follow from the "
                             "polygon and lattice.areal_density_kg_m2)")
        return self


class GeometryLigament(Strict):
    """A ligament from vertex ``i`` of unit ``a`` to vertex ``j`` of unit ``b``."""

    a: int = Field(ge=0, description="first unit")
    i: int = Field(ge=0, description="its vertex")
    b: int = Field(ge=0, description="second unit")
    j: int = Field(ge=0, description="its vertex")
    rest_gap_m: Point | None = Field(None, description="rest vector from vertex i of a to vertex j of b "
                                     "(default: their separation in the file: stress-free)")
    axis: Point | None = Field(None, description="direction of the longitudinal spring (default: along the "
                               "rest gap, or centroid of a to centroid of b for a zero gap)")
    k_long_n_per_m: Positive | None = None
    k_shear_n_per_m: NonNegative | None = None
    k_rot_n_m_per_rad: NonNegative | None = None
    shift: list[Annotated[int, Field(ge=-1, le=1)]] | None = Field(
        None, min_length=1, max_length=2, description="periodic files: the cell of b, in lattice vectors, "
        "relative to a's (default: the same cell)")

    @model_validator(mode="after")
    def _axis(self):
        if self.axis is not None and self.axis[0] == 0 and self.axis[1] == 0:
            raise ValueError("axis [0, 0] has no direction")
        if self.a == self.b and not any(self.shift or ()):
            raise ValueError(f"a ligament joins two units (or a unit to its copy in another cell: shift): "
                             f"a = b = {self.a}")
        return self


class GeometryFile(Strict):
    """The units, ligaments and named unit sets of a rigid network."""

    units: list[GeometryUnit] = Field(min_length=2)
    ligaments: list[GeometryLigament] = Field(min_length=1)
    sets: dict[str, UnitSet] = Field(default_factory=dict)
    lattice_vectors_m: list[Point] | None = Field(
        None, min_length=1, max_length=2, description="the periods of a periodic network (m): the units are one cell")

    @model_validator(mode="after")
    def _periods(self):
        p = 0 if self.lattice_vectors_m is None else len(self.lattice_vectors_m)
        if p == 2:
            (x1, y1), (x2, y2) = self.lattice_vectors_m
            if abs(x1 * y2 - x2 * y1) <= 1e-12 * (x1 * x1 + y1 * y1 + x2 * x2 + y2 * y2):
                raise ValueError(f"lattice_vectors_m {self.lattice_vectors_m}: the two vectors are parallel")
        elif p == 1 and self.lattice_vectors_m[0] == [0, 0]:
            raise ValueError("lattice_vectors_m [[0, 0]] has no length")
        for k, g in enumerate(self.ligaments):
            if g.shift is not None and len(g.shift) != p:
                raise ValueError(f"ligaments.{k}.shift {g.shift}: give one entry per lattice vector "
                                 f"({p} in lattice_vectors_m)" if p else
                                 f"ligaments.{k}.shift: only a periodic file (lattice_vectors_m) has other cells")
        return self


_RAW: dict[tuple, dict] = {}


def raw_geometry(path: str | Path) -> dict:
    """The geometry file as plain YAML data, read once per version of the file (path, size,
    modification time), for what a scene's validation needs of it: the number of units and the
    names of its sets. ValueError if it is not a YAML mapping with a list of units (its schema is
    checked, at file:line, when the network is built: ``models.network.read_geometry``)."""
    import yaml

    st = Path(path).stat()
    key = (str(path), st.st_size, st.st_mtime_ns)
    if key not in _RAW:
        try:
            data = yaml.safe_load(Path(path).read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
            raise ValueError(f"geometry file {str(path)!r} cannot be read as YAML: "
                             f"{str(exc).splitlines()[0] if str(exc) else type(exc).__name__}") from None
        if not isinstance(data, dict) or not isinstance(data.get("units"), list) or len(data["units"]) < 2:
            raise ValueError(f"geometry file {str(path)!r}: expected a mapping with a list of (two or more) units "
                             "and ligaments (docs/scenes.md, Geometry sources)")
        if len(_RAW) > 32:
            _RAW.clear()
        _RAW[key] = data
    return _RAW[key]


def set_names(data: dict) -> list[str]:
    """The names of a geometry file's unit sets."""
    sets = data.get("sets")
    return [str(k) for k in sets] if isinstance(sets, dict) else []


def resolved_path(value: str, base_dir) -> str:
    """``value`` relative to the config's directory ``base_dir`` (else the working directory)."""
    p = Path(value).expanduser()
    return str(p if p.is_absolute() or base_dir is None else (Path(base_dir) / p).resolve())


__all__ = ["GeometryFile", "GeometryLigament", "GeometryUnit", "UnitSet", "raw_geometry", "resolved_path",
           "set_names"]
