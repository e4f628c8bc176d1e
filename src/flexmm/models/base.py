"""The built system: plain arrays plus compiled kernels, made from a config by a model builder.

State layout is field-major and flat: ``q[f * n_sites + i]`` is field ``f`` of site ``i``;
models may append extra DOFs after the lattice (a striker mass, for instance).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple, Callable

import numpy as np

from flexmm.io.run_dataset import OUTLINES
from flexmm.units import Scales


@dataclass(frozen=True)
class FieldSpec:
    """One generalised coordinate per site: its name, kind ('length'/'angle'), long name and, for
    a displacement, the axis it moves along ('x', 'y'): the roles ``System`` reads from them."""

    name: str
    kind: str
    long_name: str
    axis: str | None = None


#: the axis normal to each end of a lattice
END_AXES = {"left": "x", "right": "x", "bottom": "y", "top": "y"}


@dataclass(frozen=True)
class GroundFriction:
    """Regularised Coulomb friction against the ground, per listed site (nondimensional).

    The assembler turns it into explicit drive rows on the longitudinal field (``assemble.apply_friction``).
    """

    sites: np.ndarray
    """(k,) int64 site indices that feel friction."""
    forward: np.ndarray
    """(k,) friction force level for velocity > 0 (units of ``Scales.force``)."""
    backward: np.ndarray
    """(k,) friction force level for velocity < 0 (units of ``Scales.force``)."""
    velocity: float
    """Regularisation velocity v_ε below which the force ramps linearly (units of ``Scales.velocity``)."""


@dataclass(frozen=True)
class Predeformation:
    """The static equilibrium a predeformed lattice starts from (``models.predeform.relax``)."""

    rest_state: np.ndarray
    """(n_fields * n_sites,) nondimensional lattice state of the loaded equilibrium (no extra DOFs)."""
    residual: float
    """Max |force| over the free DOFs at the end of the minimisation and its Newton polish (nondimensional)."""
    steps: int
    """FIRE steps taken."""
    energy: float
    """Potential energy of the equilibrium, loads included (nondimensional)."""
    newton_steps: int = 0
    """Newton steps that polished FIRE's state to round-off (``predeform.polish``); 0: FIRE's state."""
    free: np.ndarray | None = None
    """The DOFs the minimiser moved (indices; the others were fixed or held by a strain)."""


@dataclass(frozen=True)
class UnitShapes:
    """What the rigid units look like and where they are joined (nondimensional lengths): stored
    with a run's dataset, so that ``flexmm render`` draws any model from it without rebuilding it.

    ``centres`` (N, 2): the units' centres in the reference configuration; ``vertices`` (N, V, 2):
    each unit's polygon there, relative to its centre; ``rotation_sign`` (N,): a unit turns by
    rotation_sign · θ (−1 on the counter-rotating sublattice of a staggered θ); ``links`` (L, 2) the
    units each hinge or ligament joins and ``link_points`` (L, 2, 2) its two attachment points
    relative to those units' centres.

    How to draw them: ``outline`` (``io.run_dataset.OUTLINES``); ``angle`` (N,) each unit's orientation in the
    reference configuration (its polygon is already turned by it; reported, not applied);
    ``markers`` (N, M, 2) points fixed to each unit (its magnets), relative to its centre in the
    reference configuration; ``link_joints``: a link carries a joint, drawn at its midpoint;
    ``images`` (N, K) the vertical offsets of mirror images of each unit (a chain's lateral hinges
    join each unit to its image across the row: image k is the unit reflected about the horizontal
    through its centre and shifted by ``images[:, k]``, joined at vertex ``image_vertex[k]`` of the
    unit to the reflection of that vertex).
    """

    centres: np.ndarray
    vertices: np.ndarray
    rotation_sign: np.ndarray
    links: np.ndarray
    link_points: np.ndarray
    outline: str = "polygon"
    angle: np.ndarray | None = None
    markers: np.ndarray | None = None
    link_joints: bool = False
    images: np.ndarray | None = None
    image_vertex: np.ndarray | None = None

    def __post_init__(self):
        if self.outline not in OUTLINES:
            raise ValueError(f"outline {self.outline!r}: expected one of {', '.join(OUTLINES)}")


#: the corners of ``square_units``' polygons, in their order
RIGHT, TOP, LEFT, BOTTOM = range(4)


def square_units(centres: np.ndarray, theta0: np.ndarray, sigma: np.ndarray, half: float, links: np.ndarray,
                 corners: np.ndarray, **drawing) -> UnitShapes:
    """The ``UnitShapes`` of square units (hinge-to-hinge diagonal 2·``half``) turning by σθ (σ =
    ``sigma`` per unit), their corners right, top, left, bottom (``RIGHT``...) at centre +
    half (cos(σθ0 + kπ/2), sin(σθ0 + kπ/2)); link l joins corner ``corners[l, 0]`` of unit
    ``links[l, 0]`` to corner ``corners[l, 1]`` of unit ``links[l, 1]``; ``drawing``: the other
    fields of ``UnitShapes``."""
    angle = np.asarray(sigma, float) * np.asarray(theta0, float)
    ang = angle[:, None] + 0.5 * np.pi * np.arange(4)
    vertices = half * np.stack([np.cos(ang), np.sin(ang)], -1)
    links = np.asarray(links, np.int64).reshape(-1, 2)
    corners = np.asarray(corners, np.int64).reshape(-1, 2)
    points = np.stack([vertices[links[:, k], corners[:, k]] for k in range(2)], 1).reshape(-1, 2, 2)
    return UnitShapes(np.asarray(centres, float), vertices, np.asarray(sigma, float).copy(), links, points,
                      angle=angle, **drawing)


@dataclass(frozen=True)
class PeriodicCell:
    """The periods of a network whose links wrap around: ``vectors`` (P, 2) its lattice vectors
    (nondimensional lengths; P = 1 or 2 periodic directions), ``link_shifts`` (L, P) int for each
    link the cell, in lattice vectors, of its second unit relative to its first (0 for a link inside
    the cell)."""

    vectors: np.ndarray
    link_shifts: np.ndarray


@dataclass
class System:
    """A model ready to integrate (nondimensional).

    Attributes
    ----------
    fields : per-site coordinates, in state order.
    n_sites : number of lattice sites.
    mass : (ndof,) generalised masses (inertia for angle DOFs), used for kinetic energy.
    inv_mass : (ndof,) inverse masses; 0 for fixed or prescribed DOFs.
    args : the model's NamedTuple of arrays its kernels read (connectivity, per-element
        parameters, scratch); its type selects the kernels (``models.kernels.KERNELS``):
        ``force``, ``energy`` and ``reference`` below are those kernels.
    q0, v0 : (ndof,) initial state.
    site_coords : name -> (n_sites,) rest coordinates in SI, for the dataset.
    extra_dofs : name -> (index, kind) of DOFs beyond the lattice (e.g. the striker).

    The fields after ``extra_dofs`` describe the lattice to the assembler, planners and analyses;
    each has its own docstring.
    """

    model: str
    fields: tuple[FieldSpec, ...]
    n_sites: int
    scales: Scales
    mass: np.ndarray
    inv_mass: np.ndarray
    args: NamedTuple
    q0: np.ndarray
    v0: np.ndarray
    spacing_m: float
    site_coords: dict[str, np.ndarray] = field(default_factory=dict)
    extra_dofs: dict[str, tuple[int, str]] = field(default_factory=dict)
    ends: dict[str, list[int]] = field(default_factory=dict)
    """End name ('left', 'right', 'bottom', 'top') -> its site indices (excitations, loads, fixed ends)."""
    omega_ref: float = 1.0
    """Reference angular frequency (nondimensional) that viscous damping ratios are relative to."""
    grid_shape: tuple[int, int] | None = None
    """(n_rows, n_cols) of a rectangular lattice with site = row * n_cols + col; None otherwise."""
    site_coord_attrs: dict[str, tuple[str, str]] = field(default_factory=dict)
    """site_coords name -> (units, long_name) for coordinates that are not lengths in m."""
    neighbour_pairs: np.ndarray | None = None
    """(P, 2) int site pairs joined by dashpots on the longitudinal field (nearest-neighbour bonds;
    x hinges of the rigid sheets); None: consecutive sites (i, i + 1)."""
    site_groups: dict[str, list[int]] = field(default_factory=dict)
    """Named site groups (branches and junctions of a mass network) -> site indices."""
    friction: GroundFriction | None = None
    """Ground friction on the longitudinal field, or None."""
    predeformation: Predeformation | None = None
    """The static equilibrium q0 was relaxed to (``lattice.predeform``); None for a stress-free start."""
    shapes: UnitShapes | Callable[[], UnitShapes] | None = None
    """The units' polygons and joints for drawing (rigid-unit models), or what makes them when a
    run writes them (so a model built only to be planned never makes them); read them with
    ``unit_shapes()``; else None."""
    initial_displacement_m: np.ndarray | None = None
    """(n_sites,) SI displacements of the initial (relaxed) state, folded into the element shifts so
    that q = 0 there (mass models); None for other models."""
    periodic: PeriodicCell | None = None
    """The lattice vectors and link shifts of a network with periodic boundaries (its links wrap: the
    Bloch cell of ``linear.network``); None for a network without, and for other models."""

    @property
    def axis_fields(self) -> dict[str, str]:
        """Axis ('x', 'y') -> the displacement field along it (``FieldSpec.axis``)."""
        return {f.axis: f.name for f in self.fields if f.axis is not None}

    @property
    def longitudinal_field(self) -> str:
        """Field along x: default field of ends, kicks and drives; dashpots and friction act on it."""
        return self.axis_fields["x"]

    @property
    def rotation_field(self) -> str | None:
        """Field of the unit rotations [rad] (the angle field); None for models without rotations."""
        return next((f.name for f in self.fields if f.kind == "angle"), None)

    def unit_shapes(self) -> UnitShapes | None:
        """``shapes``, made on first use."""
        if callable(self.shapes):
            self.shapes = self.shapes()
        return self.shapes

    @property
    def rest_state(self) -> np.ndarray | None:
        """(n_fields * n_sites,) predeformed equilibrium state, or None (the rest state is q = 0)."""
        return None if self.predeformation is None else self.predeformation.rest_state

    @property
    def field_reference(self) -> str:
        """What the lattice fields q measure (the datasets' ``reference`` attribute, docs/architecture.md).

        ``'rest_state'``: displacement from the rest state (mass models fold their initial,
        relaxed positions into the element shifts, so q = 0 there); ``'absolute'``: from the
        lattice's reference configuration (site coordinates, rotations from the built-in angle),
        the rest state being ``rest_state`` (predeformed) or q = 0.
        """
        return "rest_state" if self.initial_displacement_m is not None else "absolute"

    def rest_fields_si(self) -> dict[str, np.ndarray]:
        """Field name -> (n_sites,) SI values of the rest state, measured from the reference configuration.

        The predeformed equilibrium, the initial (relaxed) positions of a mass model, or zeros.
        """
        n = self.n_sites
        out = {f.name: np.zeros(n) for f in self.fields}
        if self.rest_state is not None:
            for k, f in enumerate(self.fields):
                out[f.name] = self.rest_state[k * n : (k + 1) * n] * self.scales.coordinate(f.kind)
        elif self.initial_displacement_m is not None:
            out[self.longitudinal_field] = np.asarray(self.initial_displacement_m, float).copy()
        return out

    @property
    def force(self) -> Callable[..., None]:
        """Compiled ``force(q, args, out)`` writing −∂E/∂q into ``out`` (ndof,)."""
        from flexmm.models.kernels import kernels_of

        return kernels_of(type(self.args)).force

    @property
    def energy(self) -> Callable[..., float]:
        """Compiled ``energy(q, args) -> float``, the potential energy."""
        from flexmm.models.kernels import kernels_of

        return kernels_of(type(self.args)).energy

    @property
    def reference(self) -> Callable[..., tuple[float, np.ndarray]]:
        """Numpy ``reference(q, args) -> (E, F)``: the tests' oracle for the compiled kernels."""
        from flexmm.models.kernels import kernels_of

        return kernels_of(type(self.args)).reference

    @property
    def ndof(self) -> int:
        return self.mass.shape[0]

    def end_field(self, end: str) -> str:
        """The field normal to ``end`` (drives, loads): the displacement along its axis
        (``END_AXES``), else the longitudinal field."""
        return self.axis_fields.get(END_AXES.get(end, "x"), self.longitudinal_field)

    def field_index(self, name: str) -> int:
        for k, f in enumerate(self.fields):
            if f.name == name:
                return k
        valid = ", ".join(f.name for f in self.fields)
        raise KeyError(f"model {self.model!r} has no field {name!r} (valid: {valid})")

    def dof(self, field_name: str, site: int) -> int:
        """Flat index of ``field_name`` at ``site``."""
        return self.field_index(field_name) * self.n_sites + site

    def kinetic_energy(self, v: np.ndarray) -> float:
        """½ Σ m v² (compiled, single-threaded: no BLAS call, whose threads contend on a busy
        machine, and the same sum in every process)."""
        from flexmm.models.hinge import weighted_square_sum

        return 0.5 * weighted_square_sum(self.mass, v)

    def site_grid(self) -> tuple[np.ndarray, np.ndarray]:
        """Integer site indices (ix, iy) (n_sites,): the ``col``/``row`` coordinates of a grid that
        has them (a kagome's rows are not one spacing apart), else from the rest coordinates (iy = 0
        for chains)."""
        if "col" in self.site_coords and "row" in self.site_coords:
            return (np.asarray(self.site_coords["col"], np.int64), np.asarray(self.site_coords["row"], np.int64))
        h = self.spacing_m
        x = np.asarray(self.site_coords.get("x", np.arange(self.n_sites) * h), float)
        y = np.asarray(self.site_coords.get("y", np.zeros(self.n_sites)), float)
        return np.rint((x - x.min()) / h).astype(np.int64), np.rint((y - y.min()) / h).astype(np.int64)
