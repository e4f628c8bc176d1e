"""Objectives of ``flexmm design``: smooth functions of a run's records with exact gradients.

Each term measures one thing in a region (a list of sites, or an end of the lattice):

- ``peak_force``: the force transmitted to the region, F(t) = Σ_{i∈R} f_i(t) over the DOFs of
  one field (internal forces cancel, so this is the force the rest of the structure and the
  drives exert on R; on a fixed end unit it is the reaction of the support), its peak over time
  smoothed as the p-norm (mean_k |F_k|^p)^{1/p} (``sharpness`` p; ∞ would be the true peak);
- ``energy``: the kinetic energy of the region (all its DOFs), averaged over the run;
- ``peak_energy``: its p-norm peak over time;
- ``arrival_time``: the kinetic-energy-weighted mean time Σ t E_R(t) / Σ E_R(t) in the region;
- ``energy_share``: the region's mean kinetic energy over that of a ``reference`` region (e.g. a
  target patch against the whole band of columns it sits in: raising it concentrates the energy
  that passes there instead of only transmitting more of it).

A weighted sum of terms is minimised; a term with ``goal: maximize`` enters with a minus sign,
and each term is divided by its value at the start so weights compare like with like. Values
are reported in SI.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np
from pydantic import Field, model_validator

from flexmm.config.base import Positive, Strict
from flexmm.design.gradient import Raw, Records


class Region(Strict):
    """Sites of the lattice: listed, an end's units, or a box of a grid's columns and rows."""

    sites: list[int] | None = Field(None, min_length=1)
    end: Literal["left", "right", "bottom", "top"] | None = None
    box: tuple[int, int, int, int] | None = Field(
        None, description="[first column, last column, first row, last row] (inclusive; a chain has row 0)")

    @model_validator(mode="after")
    def _one(self):
        if sum(x is not None for x in (self.sites, self.end, self.box)) != 1:
            raise ValueError("give exactly one of sites, end or box")
        if self.box is not None and not (0 <= self.box[0] <= self.box[1] and 0 <= self.box[2] <= self.box[3]):
            raise ValueError(f"box {list(self.box)}: need 0 <= first <= last for the columns and the rows")
        return self


class Term(Strict):
    """One objective term (see the module docstring)."""

    kind: Literal["peak_force", "energy", "peak_energy", "arrival_time", "energy_share"]
    region: Region
    reference: Region | None = Field(None, description="energy_share: the region whose energy is the denominator")
    field: str | None = Field(None, description="peak_force: the field whose forces are summed "
                                                 "(default the longitudinal one)")
    goal: Literal["minimize", "maximize"] = "minimize"
    weight: Positive = 1.0
    sharpness: float = Field(8.0, ge=2.0, le=64.0, description="p of the p-norm peak")

    @model_validator(mode="after")
    def _reference(self):
        if TERMS[self.kind].shares != (self.reference is not None):
            raise ValueError("kind energy_share needs a reference region (and only energy_share takes one)")
        return self


@dataclass
class BoundTerm:
    """A term resolved on a built system: which records it reads and how to convert to SI."""

    spec: Term
    cols: np.ndarray  # columns of the records (observed DOFs) it reads
    dofs: np.ndarray  # their DOF indices
    to_si: float
    norm: float = 1.0
    ref_cols: np.ndarray | None = None  # energy_share: the reference region's record columns
    ref_dofs: np.ndarray | None = None

    @property
    def sign(self) -> float:
        return -1.0 if self.spec.goal == "maximize" else 1.0

    @property
    def reads_forces(self) -> bool:
        """It reads the forces on its region (else the kinetic energy)."""
        return TERMS[self.spec.kind].forces

    def value(self, rec: Records, raw: Raw, times: np.ndarray) -> tuple:
        """(value in model units, dJ/dq, dJ/dv, dJ/df on the term's record columns — all of them for
        energy_share —, dJ/dminv (ndof,))."""
        kind = TERMS[self.spec.kind]
        if kind.shares:
            return self._share(rec, raw)
        nk = rec.q.shape[0]
        dq = np.zeros((nk, self.cols.size))
        dv = np.zeros_like(dq)
        df = np.zeros_like(dq)
        dminv = np.zeros(raw.minv.size)
        if kind.forces:
            val, dF = _pnorm(rec.f[:, self.cols].sum(axis=1), self.spec.sharpness)
            df[:] = dF[:, None]
            return val, dq, dv, df, dminv
        mass, v, E = kinetic(rec, raw, self.cols, self.dofs)
        val, dE = kind.of_energy(E, self.spec.sharpness, times)
        dv[:] = dE[:, None] * mass * v
        dminv[self.dofs] = _dminv(dE, mass, v)
        return val, dq, dv, df, dminv

    def _share(self, rec: Records, raw: Raw) -> tuple:
        """Ē_R / Ē_ref over the columns of both regions (a DOF in both counts in both)."""
        nk, width = rec.q.shape
        zeros = np.zeros((nk, width))
        dv = np.zeros((nk, width))
        dminv = np.zeros(raw.minv.size)
        m_r, v_r, E_r = kinetic(rec, raw, self.cols, self.dofs)
        m_f, v_f, E_f = kinetic(rec, raw, self.ref_cols, self.ref_dofs)
        top, bottom = E_r.mean(), E_f.mean()
        if bottom == 0.0:
            return 0.0, zeros, dv, zeros, dminv
        val = top / bottom
        d_top, d_bottom = np.full(nk, 1.0 / (nk * bottom)), np.full(nk, -val / (nk * bottom))
        np.add.at(dv, (slice(None), self.cols), d_top[:, None] * m_r * v_r)
        np.add.at(dv, (slice(None), self.ref_cols), d_bottom[:, None] * m_f * v_f)
        np.add.at(dminv, self.dofs, _dminv(d_top, m_r, v_r))
        np.add.at(dminv, self.ref_dofs, _dminv(d_bottom, m_f, v_f))
        return float(val), zeros, dv, zeros.copy(), dminv


def kinetic(rec: Records, raw: Raw, cols: np.ndarray, dofs: np.ndarray) -> tuple:
    """(masses, velocities, kinetic energy over time) of some record columns; held DOFs carry no KE here."""
    minv = raw.minv[dofs]
    mass = np.where(minv > 0, 1.0 / np.where(minv > 0, minv, 1.0), 0.0)
    v = rec.v[:, cols]
    return mass, v, 0.5 * (v * v * mass).sum(axis=1)


def _dminv(dE: np.ndarray, mass: np.ndarray, v: np.ndarray) -> np.ndarray:
    """d(Σ_k dE_k E_k)/d m⁻¹ per DOF, m = 1/m⁻¹ (zero on held DOFs)."""
    dmass = 0.5 * (dE[:, None] * v * v).sum(axis=0)
    return np.where(mass > 0, -dmass * mass * mass, 0.0)


def _pnorm(x: np.ndarray, p: float) -> tuple[float, np.ndarray]:
    """(mean |x|^p)^{1/p} and its gradient."""
    a = np.abs(x)
    top = a.max()
    if top == 0:
        return 0.0, np.zeros_like(x)
    s = a / top
    mean = np.mean(s**p)
    val = top * mean ** (1.0 / p)
    grad = mean ** (1.0 / p - 1.0) * s ** (p - 1.0) * np.sign(x) / x.size
    return float(val), grad


def _arrival(E: np.ndarray, p: float, times: np.ndarray) -> tuple[float, np.ndarray]:
    """Σ t E / Σ E and its gradient."""
    total = E.sum()
    val = float((times * E).sum() / total)
    return val, (times - val) / total


@dataclass(frozen=True)
class TermKind:
    """What a term kind measures: its SI ``units`` and ``scale`` (the ``Scales`` attribute that
    converts it; None: the field's generalised force), whether it reads the forces on its region
    (``forces``) or shares out the energy of a reference region (``shares``), else ``of_energy(E,
    p, times) -> (value, dvalue/dE)`` from the region's kinetic energy over time."""

    units: str
    scale: str | None = "energy"
    forces: bool = False
    shares: bool = False
    of_energy: Callable | None = None


#: every term kind (the module docstring)
TERMS = {
    "peak_force": TermKind("N", None, forces=True),
    "energy": TermKind("J", of_energy=lambda E, p, times: (E.mean(), np.full(E.size, 1.0 / E.size))),
    "peak_energy": TermKind("J", of_energy=lambda E, p, times: _pnorm(E, p)),
    "arrival_time": TermKind("s", "time_s", of_energy=_arrival),
    "energy_share": TermKind("1", None, shares=True),
}
UNITS = {name: term.units for name, term in TERMS.items()}


def bind_terms(terms: list[Term], system) -> tuple[list[BoundTerm], np.ndarray]:
    """Resolve the terms on a system: (bound terms, the observed DOFs they need)."""
    from flexmm.errors import FlexmmError

    sc = system.scales
    bound, dofs_all = [], []
    for t in terms:
        sites = _sites(t.region, system)
        ref = None
        if TERMS[t.kind].forces:
            field = t.field or system.longitudinal_field
            if field not in [f.name for f in system.fields]:
                raise FlexmmError(f"objective field {field!r}: the model's fields are {[f.name for f in system.fields]}")
            dofs = [system.dof(field, s) for s in sites]
            to_si = sc.generalised_force(system.fields[system.field_index(field)].kind)
        else:
            dofs = [system.dof(f.name, s) for f in system.fields for s in sites]
            scale = TERMS[t.kind].scale
            to_si = 1.0 if scale is None else getattr(sc, scale)
            if t.reference is not None:
                ref = np.asarray([system.dof(f.name, s) for f in system.fields for s in _sites(t.reference, system)],
                                 np.int64)
                dofs_all += ref.tolist()
        bound.append((t, np.asarray(dofs, np.int64), to_si, ref))
        dofs_all += dofs
    obs = np.unique(np.asarray(dofs_all, np.int64))
    out = [BoundTerm(t, np.searchsorted(obs, d), d, to_si, ref_cols=None if r is None else np.searchsorted(obs, r),
                     ref_dofs=r) for t, d, to_si, r in bound]
    return out, obs


def _sites(region: Region, system) -> list[int]:
    from flexmm.errors import FlexmmError

    if region.end is not None:
        if region.end not in system.ends:
            raise FlexmmError(f"objective region end {region.end!r}: this lattice's ends are {', '.join(system.ends)}")
        return list(system.ends[region.end])
    if region.box is not None:
        c0, c1, r0, r1 = region.box
        col, row = system.site_grid()
        sites = np.flatnonzero((col >= c0) & (col <= c1) & (row >= r0) & (row <= r1)).tolist()
        if not sites:
            raise FlexmmError(f"objective region box {list(region.box)} holds no site (columns 0..{col.max()}, "
                              f"rows 0..{row.max()})")
        return sites
    bad = [s for s in region.sites if not 0 <= s < system.n_sites]
    if bad:
        raise FlexmmError(f"objective region sites {bad} outside 0..{system.n_sites - 1}")
    return list(region.sites)


class Objective:
    """Σ sign·weight·term/|term(start)| over bound terms; callable as a ``gradient`` objective."""

    def __init__(self, terms: list[BoundTerm], times: np.ndarray):
        self.terms = terms
        self.times = times
        self.last: list[float] = []

    def normalise(self, rec: Records, raw: Raw) -> None:
        for t in self.terms:
            v = t.value(rec, raw, self.times)[0]
            t.norm = abs(v) if v != 0 else 1.0

    def __call__(self, rec: Records, raw: Raw):
        total = 0.0
        dq = np.zeros_like(rec.q)
        dv = np.zeros_like(rec.v)
        df = np.zeros_like(rec.f)
        explicit = raw.zeros()
        self.last = []
        for t in self.terms:
            val, tq, tv, tf, tm = t.value(rec, raw, self.times)
            self.last.append(val * t.to_si)
            c = t.sign * t.spec.weight / t.norm
            total += c * val
            cols = slice(None) if TERMS[t.spec.kind].shares else t.cols  # a share spans both regions
            dq[:, cols] += c * tq
            dv[:, cols] += c * tv
            df[:, cols] += c * tf
            explicit.minv += c * tm
        return total, dq, dv, df, explicit
