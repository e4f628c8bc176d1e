"""Scales between SI units (config, datasets) and the nondimensional units used inside.

Every model picks a length, time and mass scale once; the solver works with numbers of order
one and the dataset writer converts back with the factors below.
"""

from __future__ import annotations

from dataclasses import dataclass

#: Physical dimension of a DOF kind -> SI unit string of the coordinate and of its rate.
UNITS = {"length": ("m", "m/s"), "angle": ("rad", "rad/s")}


@dataclass(frozen=True)
class Scales:
    """Reference scales: a quantity q in SI equals q_nd * scale."""

    length_m: float
    time_s: float
    mass_kg: float

    @property
    def velocity(self) -> float:
        return self.length_m / self.time_s

    @property
    def force(self) -> float:
        return self.mass_kg * self.length_m / self.time_s**2

    @property
    def energy(self) -> float:
        return self.mass_kg * self.length_m**2 / self.time_s**2

    @property
    def stiffness(self) -> float:
        return self.mass_kg / self.time_s**2

    @property
    def inertia(self) -> float:
        return self.mass_kg * self.length_m**2

    def coordinate(self, kind: str) -> float:
        """Scale of a generalised coordinate of the given kind ('length' or 'angle')."""
        return self.length_m if kind == "length" else 1.0

    def rate(self, kind: str) -> float:
        """Scale of the time derivative of a coordinate of the given kind."""
        return self.coordinate(kind) / self.time_s

    def generalised_force(self, kind: str) -> float:
        """Force for a length DOF (N), torque for an angle DOF (N m)."""
        return self.energy / self.coordinate(kind)
