"""Excitations of a scene, and their registry: one ``ExcitationSpec`` per ``kind``.

Every excitation class derives from ``Excitation``, whose methods are the per-kind behaviour the
scene checks and the planner read from a config (where it acts, what it imposes, whether it keeps
a planar wave planar); what it does to a built system is the ``apply`` hook of its spec, a
``"module:function"`` path into ``flexmm.assemble`` (imported when a system is assembled).
``ExcitationConfig`` (and the parts a ``combined`` excitation accepts) are derived from
``EXCITATIONS``: adding a kind is its class, its apply function and one registry line.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Annotated, ClassVar, Literal, Union, get_args

from pydantic import Field, model_validator

from flexmm.config.base import End, Finite, NonNegative, Positive, Strict, exactly_one


class Excitation(Strict):
    """Base of the excitation configs: the hooks, with the defaults of an excitation that does none
    of these things."""

    #: acts on an end (or listed sites of it) through ``end``/``sites``, so it can be what a
    #: lattice's ``driven`` end condition refers to
    at_end: ClassVar[bool] = False

    def components(self) -> list[Excitation]:
        """The excitations acting together (``combined``: its parts)."""
        return [self]

    def targets(self) -> list:
        """What acts on an end or listed sites: objects with ``end`` and ``sites``."""
        return [self] if self.at_end else []

    def launches(self) -> list:
        """Launched solitons: objects with ``amplitude_rad``, ``center_site``, ``direction``."""
        return []

    def sources(self) -> list[int | str] | None:
        """Where waves start: site indices and the ends ``left``/``right``; None if anywhere (or
        not known)."""
        return None

    def imposed_velocity_m_s(self) -> float:
        """Velocity scale the excitation imposes on the lattice (m/s, ≥ 0; 0 if none)."""
        return 0.0

    def planar_issue(self) -> str | None:
        """Why a sheet driven this way would not carry a wave uniform along its columns, or None."""
        return f"excitation {self.kind!r} is not planar"


def _edge_issue(end: str) -> str | None:
    return None if end in ("left", "right") else f"excitation on the {end} edge is not a wave along x"


def _sites_or_units(exc):
    """At most one of ``sites`` (indices) and ``units`` (a named set)."""
    if exc.sites is not None and exc.units is not None:
        raise ValueError("give sites (unit indices) or units (a named unit set), not both")
    return exc


def _end_sources(exc) -> list[int | str] | None:
    """An end drive starts waves at its end (left/right) or at its listed sites (a named unit set:
    anywhere, for all the config knows)."""
    if exc.end not in ("left", "right") or exc.units is not None:
        return None
    return [exc.end] if exc.sites is None else list(exc.sites)


class Striker(Strict):
    """A free mass that hits the first unit through a one-sided contact spring."""

    mass_kg: Positive
    contact_stiffness_n_per_m: Positive = Field(
        description="contact stiffness; with exponent 1.5 in N/m^1.5 (Hertz)"
    )
    exponent: Literal[1.0, 1.5] = 1.0


class Impact(Excitation):
    """Initial velocity on the end unit, or a striker mass hitting it (docs/physics.md §1)."""

    at_end: ClassVar[bool] = True
    kind: Literal["impact"]
    velocity_m_s: Finite = Field(description="impact velocity, positive into the lattice")
    end: End = "left"
    angular_velocity_rad_s: Finite = Field(0.0, description="initial spin of the hit unit")
    striker: Striker | None = None
    sites: list[Annotated[int, Field(ge=0)]] | None = Field(
        None, description="units hit (a point or a line); default every unit of the end"
    )
    units: str | None = Field(
        None, description="instead of sites: a named unit set of the lattice (a rigid network's unit_sets or "
        "geometry sets); the end still gives the direction"
    )

    @model_validator(mode="after")
    def _one_striker_site(self):
        _sites_or_units(self)
        if self.striker is not None and self.units is not None:
            raise ValueError("a striker hits one unit: give a single site, not units")
        if self.striker is not None and self.sites is not None and len(self.sites) != 1:
            raise ValueError("a striker hits one unit: give a single site (or none)")
        return self

    def sources(self):
        return _end_sources(self)

    def imposed_velocity_m_s(self) -> float:
        return abs(self.velocity_m_s)

    def planar_issue(self) -> str | None:
        if self.striker is not None or self.sites is not None or self.units is not None:
            return _edge_issue(self.end) or "the impact hits single units, not a whole edge"
        return _edge_issue(self.end)


class EndDrive(Excitation):
    """Where a drive acts: an end (or listed sites of it), in the end's normal direction or tilted."""

    at_end: ClassVar[bool] = True
    end: End = "left"
    angle_deg: Finite = Field(
        0.0, ge=-90.0, le=90.0, description="2D lattices: drive direction tilted from the end's inward "
        "normal by this angle, counter-clockwise (drives both in-plane displacements)"
    )
    sites: list[Annotated[int, Field(ge=0)]] | None = Field(
        None, description="units driven (a point or a line); default every unit of the end"
    )
    units: str | None = Field(
        None, description="instead of sites: a named unit set of the lattice (a rigid network's unit_sets or "
        "geometry sets); the end still gives the direction"
    )

    @model_validator(mode="after")
    def _where(self):
        return _sites_or_units(self)

    def sources(self):
        return _end_sources(self)

    def planar_issue(self) -> str | None:
        if self.units:
            return _edge_issue(self.end) or "the drive acts on a unit set, not a whole edge"
        if self.sites is not None:
            return _edge_issue(self.end) or "the drive moves listed units, not a whole edge"
        return _edge_issue(self.end)


def _along_or_about(exc, along: str, about: str, names: tuple[str, str], tilt: str):
    """Exactly one of an amplitude along the drive direction or about the rotation; a tilt
    (``angle_deg``) only for the former."""
    exactly_one(exc, along, about, names)
    if exc.angle_deg and getattr(exc, about) is not None:
        raise ValueError(f"angle_deg tilts {tilt} has no direction")
    return exc


class Shaker(EndDrive):
    """Harmonic boundary drive at 10 Hz–10 kHz, with a smooth ramp-up (and ramp-down)."""

    kind: Literal["shaker"]
    frequency_hz: float = Field(ge=10.0, le=10_000.0, description="drive frequency (Hz)")
    amplitude_m: Positive | None = Field(None, description="displacement amplitude (m)")
    amplitude_n: Positive | None = Field(None, description="force amplitude on each driven unit (N)")
    amplitude_rad: Positive | None = Field(
        None, description="instead: amplitude of a prescribed staggered rotation θ of the driven units (rad); "
        "u, v stay free"
    )
    ramp_cycles: NonNegative = Field(3.0, description="cycles of smooth ramp-up")
    duration_s: Positive | None = Field(None, description="drive stops (smoothly) after this")

    @model_validator(mode="after")
    def _one_amplitude(self):
        if self.amplitude_rad is None:
            return exactly_one(self, "amplitude_m", "amplitude_n", ("displacement", "force"))
        if self.amplitude_m is not None or self.amplitude_n is not None:
            raise ValueError("give exactly one of amplitude_m (displacement), amplitude_n (force) or "
                             "amplitude_rad (rotation)")
        if self.angle_deg:
            raise ValueError("angle_deg tilts a displacement drive; a prescribed rotation has no direction")
        return self

    @property
    def mode(self) -> str:
        return "force" if self.amplitude_n is not None else "displacement"

    def imposed_velocity_m_s(self) -> float:
        # a force drive imposes a strain, not a velocity; a prescribed rotation no velocity scale
        return 0.0 if self.amplitude_m is None else 2 * math.pi * self.frequency_hz * self.amplitude_m


class BoundaryDisplacement(EndDrive):
    """A prescribed displacement pulse u_0(t) of the end unit (or a prescribed rotation θ_0(t))."""

    kind: Literal["boundary_displacement"]
    shape: Literal["half_sine", "smooth_step", "gaussian"] = "half_sine"
    amplitude_m: Finite | None = Field(None, description="peak displacement, positive into the lattice (m)")
    amplitude_rad: Finite | None = Field(
        None, description="instead: peak staggered rotation θ of the driven units (rad); u, v stay free"
    )
    duration_s: Positive = Field(description="pulse length; FWHM for the gaussian; rise time for the step")

    @model_validator(mode="after")
    def _one_amplitude(self):
        return _along_or_about(self, "amplitude_m", "amplitude_rad", ("displacement", "rotation"),
                               "a displacement drive; a prescribed rotation")

    def imposed_velocity_m_s(self) -> float:
        # a prescribed rotation (amplitude_rad): no imposed velocity scale
        return 0.0 if self.amplitude_m is None else math.pi * abs(self.amplitude_m) / self.duration_s


class BoundaryForce(EndDrive):
    """A force pulse F_0(t) on the end units, or a moment pulse on their staggered rotation θ.

    Unlike a prescribed displacement it holds no DOF, so it also drives an end that a
    predeformation has displaced (a loaded end keeps its load; the pulse adds to it).
    """

    kind: Literal["boundary_force"]
    shape: Literal["half_sine", "smooth_step", "gaussian"] = "half_sine"
    amplitude_n: Finite | None = Field(None, description="peak force on each driven unit, positive into the "
                                       "lattice (N)")
    amplitude_n_m: Finite | None = Field(
        None, description="instead: peak moment on the staggered rotation θ of each driven unit (N m, "
        "positive increases θ); u, v stay free"
    )
    duration_s: Positive = Field(description="pulse length; FWHM for the gaussian; rise time for the step")

    @model_validator(mode="after")
    def _one_amplitude(self):
        return _along_or_about(self, "amplitude_n", "amplitude_n_m", ("force", "moment"), "a force drive; a moment")


class Soliton(Excitation):
    """Start from the exact continuum vector soliton (docs/physics.md §1.3) at a given site."""

    kind: Literal["soliton"]
    amplitude_rad: Finite = Field(description="peak staggered rotation A (sign = polarity)")
    center_site: int = Field(ge=0)
    direction: Literal[1, -1] = 1

    def launches(self) -> list:
        return [self]

    def sources(self):
        return [self.center_site]

    def planar_issue(self) -> None:
        return None


class Kick(Strict):
    """Initial velocities of chosen units: an end's units, listed sites, or a named unit set."""

    end: End | None = None
    sites: list[Annotated[int, Field(ge=0)]] | None = None
    velocity_x_m_s: Finite = 0.0
    velocity_y_m_s: Finite = Field(0.0, description="2D lattices only")
    angular_velocity_rad_s: Finite = Field(0.0, description="rate of the staggered rotation θ")
    units: str | None = Field(None, description="instead of end or sites: a named unit set of the lattice")

    @model_validator(mode="after")
    def _where(self):
        if self.units is not None:
            if self.end is not None or self.sites is not None:
                raise ValueError("give exactly one of end, sites or units (a named unit set)")
            return self
        return exactly_one(self, "end", "sites")


class Kicks(Excitation):
    """Several kicks at once (e.g. opposite spins at both ends: two colliding transition waves)."""

    kind: Literal["kicks"]
    kicks: list[Kick] = Field(min_length=1)

    def targets(self) -> list:
        return list(self.kicks)

    def sources(self):
        if any(k.units is not None for k in self.kicks):
            return None
        return [s for k in self.kicks for s in (k.sites if k.sites is not None else [k.end])]

    def planar_issue(self) -> str | None:
        for k in self.kicks:
            if k.sites is not None or k.units is not None or k.end not in ("left", "right") or k.velocity_y_m_s:
                return "a kick on listed units, a y edge, or along y is not planar"
        return None


class SolitonLaunch(Strict):
    """One launched soliton of a ``solitons`` excitation (fields as in ``soliton``)."""

    amplitude_rad: Finite
    center_site: int = Field(ge=0)
    direction: Literal[1, -1] = 1


class Solitons(Excitation):
    """Superposed exact solitons (well separated), e.g. two launched towards each other to collide."""

    kind: Literal["solitons"]
    pulses: list[SolitonLaunch] = Field(min_length=1)

    def launches(self) -> list:
        return list(self.pulses)

    def sources(self):
        return [p.center_site for p in self.pulses]

    def planar_issue(self) -> None:
        return None


class Combined(Excitation):
    """Several excitations acting together, e.g. a drive or an impact at each end."""

    kind: Literal["combined"]
    parts: list[Annotated[CombinablePart, Field(discriminator="kind")]] = Field(min_length=2)

    @model_validator(mode="after")
    def _one_striker(self):
        if sum(1 for p in self.parts if getattr(p, "striker", None) is not None) > 1:
            raise ValueError("at most one part may use a striker")
        return self

    def components(self) -> list[Excitation]:
        return list(self.parts)

    def targets(self) -> list:
        return [t for p in self.parts for t in p.targets()]


class NoExcitation(Excitation):
    """Nothing drives the lattice (free vibration of the imperfection or initial state)."""

    kind: Literal["none"]

    def sources(self):
        return []

    def planar_issue(self) -> None:
        return None


@dataclass(frozen=True)
class ExcitationSpec:
    """One excitation kind: its config class (its ``kind`` Literal names it), ``apply``, the
    ``"flexmm.assemble:function"`` that applies it to a built system as
    ``apply(system, scene, excitation, terms)``, and whether it may be a part of ``combined``."""

    config: type[Excitation]
    apply: str
    combinable: bool = False

    @property
    def kind(self) -> str:
        return get_args(self.config.model_fields["kind"].annotation)[0]


def _registry(*specs: ExcitationSpec) -> dict[str, ExcitationSpec]:
    return {s.kind: s for s in specs}


EXCITATIONS: dict[str, ExcitationSpec] = _registry(
    ExcitationSpec(Impact, "flexmm.assemble:apply_impact", combinable=True),
    ExcitationSpec(Shaker, "flexmm.assemble:apply_shaker", combinable=True),
    ExcitationSpec(BoundaryDisplacement, "flexmm.assemble:apply_boundary_displacement", combinable=True),
    ExcitationSpec(BoundaryForce, "flexmm.assemble:apply_boundary_force", combinable=True),
    ExcitationSpec(Soliton, "flexmm.assemble:apply_solitons"),
    ExcitationSpec(Solitons, "flexmm.assemble:apply_solitons"),
    ExcitationSpec(Kicks, "flexmm.assemble:apply_kicks", combinable=True),
    ExcitationSpec(Combined, "flexmm.assemble:apply_parts"),
    ExcitationSpec(NoExcitation, "flexmm.assemble:apply_nothing"),
)

#: the kinds a ``combined`` excitation may combine
CombinablePart = Union[tuple(s.config for s in EXCITATIONS.values() if s.combinable)]
Combined.model_rebuild()

#: the ``excitation`` section of a scene: any registered kind, discriminated on ``kind``
ExcitationConfig = Annotated[Union[tuple(s.config for s in EXCITATIONS.values())], Field(discriminator="kind")]
