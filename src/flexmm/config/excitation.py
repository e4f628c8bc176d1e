"""Excitations of a scene: impact, shaker, prescribed boundary pulse, launched soliton."""

from __future__ import annotations

from typing import Annotated, Literal, Union

from pydantic import Field, model_validator

from flexmm.config.base import End, Finite, NonNegative, Positive, Strict, exactly_one


class Striker(Strict):
    """A free mass that hits the first unit through a one-sided contact spring."""

    mass_kg: Positive
    contact_stiffness_n_per_m: Positive = Field(
        description="contact stiffness; with exponent 1.5 in N/m^1.5 (Hertz)"
    )
    exponent: Literal[1.0, 1.5] = 1.0


class Impact(Strict):
    """Initial velocity on the end unit, or a striker mass hitting it (docs/physics.md §1)."""

    kind: Literal["impact"]
    velocity_m_s: Finite = Field(description="impact velocity, positive into the lattice")
    end: End = "left"
    angular_velocity_rad_s: Finite = Field(0.0, description="initial spin of the hit unit")
    striker: Striker | None = None
    sites: list[Annotated[int, Field(ge=0)]] | None = Field(
        None, description="units hit (a point or a line); default every unit of the end"
    )

    @model_validator(mode="after")
    def _one_striker_site(self):
        if self.striker is not None and self.sites is not None and len(self.sites) != 1:
            raise ValueError("a striker hits one unit: give a single site (or none)")
        return self


class EndDrive(Strict):
    """Where a drive acts: an end (or listed sites of it), in the end's normal direction or tilted."""

    end: End = "left"
    angle_deg: Finite = Field(
        0.0, ge=-90.0, le=90.0, description="2D lattices: drive direction tilted from the end's inward "
        "normal by this angle, counter-clockwise (drives both in-plane displacements)"
    )
    sites: list[Annotated[int, Field(ge=0)]] | None = Field(
        None, description="units driven (a point or a line); default every unit of the end"
    )


class Shaker(EndDrive):
    """Harmonic boundary drive at 10 Hz–10 kHz, with a smooth ramp-up (and ramp-down)."""

    kind: Literal["shaker"]
    frequency_hz: float = Field(ge=10.0, le=10_000.0, description="drive frequency (Hz)")
    amplitude_m: Positive | None = Field(None, description="displacement amplitude (m)")
    amplitude_n: Positive | None = Field(None, description="force amplitude (N)")
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
        exactly_one(self, "amplitude_m", "amplitude_rad", ("displacement", "rotation"))
        if self.angle_deg and self.amplitude_rad is not None:
            raise ValueError("angle_deg tilts a displacement drive; a prescribed rotation has no direction")
        return self


class Soliton(Strict):
    """Start from the exact continuum vector soliton (docs/physics.md §1.3) at a given site."""

    kind: Literal["soliton"]
    amplitude_rad: Finite = Field(description="peak staggered rotation A (sign = polarity)")
    center_site: int = Field(ge=0)
    direction: Literal[1, -1] = 1


class Kick(Strict):
    """Initial velocities of chosen units: an end's units, or listed sites."""

    end: End | None = None
    sites: list[Annotated[int, Field(ge=0)]] | None = None
    velocity_x_m_s: Finite = 0.0
    velocity_y_m_s: Finite = Field(0.0, description="2D lattices only")
    angular_velocity_rad_s: Finite = Field(0.0, description="rate of the staggered rotation θ")

    @model_validator(mode="after")
    def _where(self):
        return exactly_one(self, "end", "sites")


class Kicks(Strict):
    """Several kicks at once (e.g. opposite spins at both ends: two colliding transition waves)."""

    kind: Literal["kicks"]
    kicks: list[Kick] = Field(min_length=1)


class SolitonLaunch(Strict):
    """One launched soliton of a ``solitons`` excitation (fields as in ``soliton``)."""

    amplitude_rad: Finite
    center_site: int = Field(ge=0)
    direction: Literal[1, -1] = 1


class Solitons(Strict):
    """Superposed exact solitons (well separated), e.g. two launched towards each other to collide."""

    kind: Literal["solitons"]
    pulses: list[SolitonLaunch] = Field(min_length=1)


class Combined(Strict):
    """Several excitations acting together, e.g. a drive or an impact at each end."""

    kind: Literal["combined"]
    parts: list[Annotated[Union[Impact, Shaker, BoundaryDisplacement, Kicks], Field(discriminator="kind")]] = (
        Field(min_length=2)
    )

    @model_validator(mode="after")
    def _one_striker(self):
        if sum(1 for p in self.parts if p.kind == "impact" and p.striker is not None) > 1:
            raise ValueError("at most one part may use a striker")
        return self


class NoExcitation(Strict):
    """Nothing drives the lattice (free vibration of the imperfection or initial state)."""

    kind: Literal["none"]


ExcitationConfig = Annotated[
    Union[Impact, Shaker, BoundaryDisplacement, Soliton, Solitons, Kicks, Combined, NoExcitation],
    Field(discriminator="kind"),
]
