"""The built system: plain arrays plus compiled kernels, made from a config by a model builder.

State layout is field-major and flat: ``q[f * n_sites + i]`` is field ``f`` of site ``i``;
models may append extra DOFs after the lattice (a striker mass, for instance).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from flexmm.units import Scales


@dataclass(frozen=True)
class FieldSpec:
    """One generalised coordinate per site: its name, kind ('length'/'angle') and long name."""

    name: str
    kind: str
    long_name: str


@dataclass
class System:
    """A model ready to integrate (nondimensional).

    Attributes
    ----------
    fields : per-site coordinates, in state order.
    n_sites : number of lattice sites.
    mass : (ndof,) generalised masses (inertia for angle DOFs), used for kinetic energy.
    inv_mass : (ndof,) inverse masses; 0 for fixed or prescribed DOFs.
    force : compiled ``force(q, args, out)`` writing -dE/dq into ``out`` (ndof,).
    energy : compiled ``energy(q, args) -> float`` potential energy.
    args : tuple of arrays the kernels read (connectivity, per-element parameters, scratch).
    q0, v0 : (ndof,) initial state.
    site_coords : name -> (n_sites,) rest coordinates in SI, for the dataset.
    extra_dofs : name -> (index, kind) of DOFs beyond the lattice (e.g. the striker).
    """

    model: str
    fields: tuple[FieldSpec, ...]
    n_sites: int
    scales: Scales
    mass: np.ndarray
    inv_mass: np.ndarray
    force: Callable[..., None]
    energy: Callable[..., float]
    args: tuple
    q0: np.ndarray
    v0: np.ndarray
    spacing_m: float
    site_coords: dict[str, np.ndarray] = field(default_factory=dict)
    extra_dofs: dict[str, tuple[int, str]] = field(default_factory=dict)
    reference: Callable[..., tuple[float, np.ndarray]] | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def ndof(self) -> int:
        return self.mass.shape[0]

    def field_index(self, name: str) -> int:
        for k, f in enumerate(self.fields):
            if f.name == name:
                return k
        valid = ", ".join(f.name for f in self.fields)
        raise KeyError(f"model {self.model!r} has no field {name!r} (valid: {valid})")

    def dof(self, field_name: str, site: int) -> int:
        """Flat index of ``field_name`` at ``site``."""
        return self.field_index(field_name) * self.n_sites + site

    def dof_kind(self, index: int) -> str:
        """'length' or 'angle' for a flat DOF index."""
        if index < len(self.fields) * self.n_sites:
            return self.fields[index // self.n_sites].kind
        for idx, kind in self.extra_dofs.values():
            if idx == index:
                return kind
        raise IndexError(index)

    def kinetic_energy(self, v: np.ndarray) -> float:
        return 0.5 * float(np.dot(self.mass, v * v))
