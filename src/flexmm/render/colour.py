"""What colours the units or bodies: a dataset field, the energy per unit, the well, or nothing.

``make_colouring(spec, source, structure)`` returns a ``Colouring`` whose ``values(frame)`` gives
one number per drawn unit (body); its limits are fixed from a sample of the frames so a movie's
colours mean the same throughout. Fields of a predeformed run are measured from the rest state.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from flexmm.errors import UsageError
from flexmm.render.masses import onsite_barriers, site_energy_j, well_index
from flexmm.render.rigid import unit_energy_j
from flexmm.render.structure import MassStructure, ShapeStructure

SPECIAL = ("energy", "well", "none")
SYMBOLS = {"u": "u", "v": "v", "theta": "θ", "u_dot": "du/dt", "v_dot": "dv/dt", "theta_dot": "dθ/dt"}


@dataclass
class Colouring:
    """Per-unit colour values with fixed limits, a colour map and a colour-bar label."""

    name: str
    label: str
    fields: list[str]
    values: Callable[[dict], np.ndarray] | None
    cmap: str = "coolwarm"
    vmin: float = -1.0
    vmax: float = 1.0
    categories: list[str] | None = None

    def set_limits(self, samples: list[np.ndarray], clim: tuple[float, float] | None) -> None:
        """Limits from ``clim`` or from the sampled values' 99.5th percentile of magnitude: 0 to it
        for the energy, symmetric about 0 for a field."""
        if self.categories is not None or self.values is None:
            return
        if clim is not None:
            self.vmin, self.vmax = clim
            return
        v = np.concatenate([np.ravel(s) for s in samples]) if samples else np.zeros(1)
        v = v[np.isfinite(v)]
        if v.size == 0:
            v = np.zeros(1)
        if self.name == "energy":
            self.vmin, self.vmax = 0.0, float(np.percentile(v, 99.5))
        else:  # a field: symmetric about 0, so its sign (direction, sense of rotation) reads off the colour
            m = float(np.percentile(np.abs(v), 99.5))
            self.vmin, self.vmax = -m, m
        if not self.vmax > self.vmin:
            pad = max(abs(self.vmax), 1e-12)
            self.vmin, self.vmax = self.vmin - pad, self.vmax + pad


def default_colour(source, structure) -> str:
    """theta for rotating units, the well for bistable lattices, else the velocity or u."""
    if isinstance(structure, ShapeStructure):
        return "well" if structure.p is not None and structure.p.joint is not None else "theta"
    if onsite_barriers_present(structure):
        return "well"
    return "u_dot" if "u_dot" in source.fields else "u"


def onsite_barriers_present(structure) -> bool:
    """Whether a mass lattice has an on-site law that can have several wells."""
    return isinstance(structure, MassStructure) and any(
        law.law in ("bistable_cubic", "phi4", "raney2016", "sine", "polynomial_energy", "table")
        for law, _, _ in structure.p.onsite_terms)


def _field(name: str, source) -> Colouring:
    rest = source.rest.get(name)
    units = source.units(name)
    sym = SYMBOLS.get(name, name)
    label = f"{sym} − {sym}_rest" if rest is not None else sym
    label += f" ({units})" if units else ""
    if rest is None:
        return Colouring(name, label, [name], lambda f: f[name])
    return Colouring(name, label, [name], lambda f: f[name] - rest)


def _energy(source, structure) -> Colouring:
    if isinstance(structure, ShapeStructure) and structure.p is None:
        raise UsageError(f"--color energy is not available for {source.model} (colour by a field instead)")
    rates = [r for r in ("u_dot", "v_dot", "theta_dot") if r in source.fields]
    if isinstance(structure, ShapeStructure):
        p = structure.p
        if structure.sites.size != p.n_units or np.any(structure.sites != np.arange(p.n_units)):
            raise UsageError("--color energy needs every unit saved (the run has output.site_stride > 1)")
        names = structure.fields + rates

        def values(f):
            return unit_energy_j(p, f["u"], f.get("v"), f["theta"], {r: f[r] for r in rates})
        note = "" if p.magnets is None else ", magnets not included"
    else:
        p = structure.p
        names = ["u"] + (["u_dot"] if "u_dot" in rates else [])
        full = structure.sites.size == p.n_sites

        if not full:
            raise UsageError("--color energy needs every site saved (the run has output.site_stride > 1)")

        def values(f):
            return site_energy_j(p, f["u"], f.get("u_dot"))
        note = ""
    what = "energy per unit" if isinstance(structure, ShapeStructure) else "energy per site"
    if not rates:
        note += ", potential only: velocities not saved"
    return Colouring("energy", f"{what} (J{note})", names, values, cmap="magma_r")


def _well(source, structure, samples_u: list[np.ndarray] | None) -> Colouring:
    if isinstance(structure, ShapeStructure):
        p = structure.p
        if p is None or p.joint is None:
            raise UsageError("--color well: this lattice has no multistable elements (use a field or energy)")
        _, beta, switch = p.joint
        label = "state of the unit's joints (deployed: θ past the barrier, βψ*/2)"

        def values(f):
            return (f["theta"] / (beta * switch) > 0.5).astype(float)
        return Colouring("well", label, ["theta"], values, cmap="well", vmin=-0.5, vmax=1.5,
                         categories=["folded", "deployed"])
    p = structure.p
    pos = [structure.x0 + u for u in (samples_u or [np.zeros(structure.sites.size)])]
    lo = min(float(np.min(x)) for x in pos)
    hi = max(float(np.max(x)) for x in pos)
    span = max(hi - lo, p.spacing_m)
    b = onsite_barriers(p, lo - 0.5 * span, hi + 0.5 * span)
    if b is None:
        raise UsageError("--color well: no site has a multistable on-site potential in the range it moves over")
    b = b[structure.sites]
    x0 = structure.x0
    n_wells = int(np.max(np.sum(np.isfinite(b), axis=1))) + 1
    cats = [f"well {k + 1}" for k in range(n_wells)]
    return Colouring("well", "well of the on-site potential (1: lowest displacement)", ["u"],
                     lambda f: well_index(x0 + f["u"], b), cmap="well", vmin=-0.5, vmax=n_wells - 0.5,
                     categories=cats)


def make_colouring(spec: str | None, source, structure, samples_u=None) -> Colouring:
    """The Colouring named by ``spec`` (a site field of the dataset, energy, well, none; None: default).

    ``samples_u``: a few frames of u (mass lattices), to find the wells the sites move between.
    """
    name = spec or default_colour(source, structure)
    if spec is None and name == "well" and isinstance(structure, MassStructure):
        try:  # an on-site law that could be multistable, but has a single well where the sites move
            return _well(source, structure, samples_u)
        except UsageError:
            name = "u_dot" if "u_dot" in source.fields else "u"
    if name == "none":
        return Colouring("none", "", [], None)
    if name == "energy":
        return _energy(source, structure)
    if name == "well":
        return _well(source, structure, samples_u)
    if name not in source.fields:
        raise UsageError(f"--color {name!r}: no such field in the run; choose one of "
                         f"{', '.join(source.fields + list(SPECIAL))}")
    return _field(name, source)


__all__ = ["SPECIAL", "Colouring", "default_colour", "make_colouring"]
