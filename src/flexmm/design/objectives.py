"""Objectives of ``flexmm design``: smooth functions of a run's records with exact gradients.

Each term measures one thing in a region (a list of sites, or an end of the lattice):

- ``peak_force``: the force transmitted to the region, F(t) = Σ_{i∈R} f_i(t) over the DOFs of
  one field (internal forces cancel, so this is the force the rest of the structure and the
  drives exert on R; on a fixed end unit it is the reaction of the support), its peak over time
  smoothed as the p-norm (mean_k |F_k|^p)^{1/p} (``sharpness`` p; ∞ would be the true peak);
- ``energy``: the kinetic energy of the region (all its DOFs), averaged over the run;
- ``peak_energy``: its p-norm peak over time;
- ``arrival_time``: the kinetic-energy-weighted mean time Σ t E_R(t) / Σ E_R(t) in the region.

A weighted sum of terms is minimised; a term with ``goal: maximize`` enters with a minus sign,
and each term is divided by its value at the start so weights compare like with like. Values
are reported in SI.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from pydantic import Field, model_validator

from flexmm.config.base import Positive, Strict
from flexmm.design.gradient import Raw, Records


class Region(Strict):
    """Sites of the lattice: listed, or an end's units."""

    sites: list[int] | None = Field(None, min_length=1)
    end: Literal["left", "right", "bottom", "top"] | None = None

    @model_validator(mode="after")
    def _one(self):
        if (self.sites is None) == (self.end is None):
            raise ValueError("give exactly one of sites or end")
        return self


class Term(Strict):
    """One objective term (see the module docstring)."""

    kind: Literal["peak_force", "energy", "peak_energy", "arrival_time"]
    region: Region
    field: str | None = Field(None, description="peak_force: the field whose forces are summed "
                                                 "(default the longitudinal one)")
    goal: Literal["minimize", "maximize"] = "minimize"
    weight: Positive = 1.0
    sharpness: float = Field(8.0, ge=2.0, le=64.0, description="p of the p-norm peak")


UNITS = {"peak_force": "N", "energy": "J", "peak_energy": "J", "arrival_time": "s"}


@dataclass
class BoundTerm:
    """A term resolved on a built system: which records it reads and how to convert to SI."""

    spec: Term
    cols: np.ndarray  # columns of the records (observed DOFs) it reads
    dofs: np.ndarray  # their DOF indices
    to_si: float
    norm: float = 1.0

    @property
    def sign(self) -> float:
        return -1.0 if self.spec.goal == "maximize" else 1.0

    def value(self, rec: Records, raw: Raw, times: np.ndarray) -> tuple:
        """(value in model units, dJ/dq, dJ/dv, dJ/df on the record columns, dJ/dminv (ndof,))."""
        kind, p = self.spec.kind, self.spec.sharpness
        nk = rec.q.shape[0]
        dq = np.zeros((nk, self.cols.size))
        dv = np.zeros_like(dq)
        df = np.zeros_like(dq)
        dminv = np.zeros(raw.minv.size)
        if kind == "peak_force":
            F = rec.f[:, self.cols].sum(axis=1)
            val, dF = _pnorm(F, p)
            df[:] = dF[:, None]
            return val, dq, dv, df, dminv
        minv = raw.minv[self.dofs]
        mass = np.where(minv > 0, 1.0 / np.where(minv > 0, minv, 1.0), 0.0)  # held DOFs carry no KE here
        v = rec.v[:, self.cols]
        E = 0.5 * (v * v * mass).sum(axis=1)
        if kind == "energy":
            val, dE = E.mean(), np.full(nk, 1.0 / nk)
        elif kind == "peak_energy":
            val, dE = _pnorm(E, p)
        else:
            total = E.sum()
            val = float((times * E).sum() / total)
            dE = (times - val) / total
        dv[:] = dE[:, None] * mass * v
        dmass = 0.5 * (dE[:, None] * v * v).sum(axis=0)
        dminv[self.dofs] = np.where(minv > 0, -dmass * mass * mass, 0.0)  # m = 1/m⁻¹
        return val, dq, dv, df, dminv


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


def bind_terms(terms: list[Term], system) -> tuple[list[BoundTerm], np.ndarray]:
    """Resolve the terms on a system: (bound terms, the observed DOFs they need)."""
    from flexmm.errors import FlexmmError

    sc = system.scales
    bound, dofs_all = [], []
    for t in terms:
        if t.region.end is not None:
            if t.region.end not in system.ends:
                raise FlexmmError(f"objective region end {t.region.end!r}: this lattice's ends are "
                                  f"{', '.join(system.ends)}")
            sites = list(system.ends[t.region.end])
        else:
            sites = t.region.sites
            bad = [s for s in sites if not 0 <= s < system.n_sites]
            if bad:
                raise FlexmmError(f"objective region sites {bad} outside 0..{system.n_sites - 1}")
        if t.kind == "peak_force":
            field = t.field or system.longitudinal_field
            if field not in [f.name for f in system.fields]:
                raise FlexmmError(f"objective field {field!r}: the model's fields are {[f.name for f in system.fields]}")
            dofs = [system.dof(field, s) for s in sites]
            to_si = sc.generalised_force(system.fields[system.field_index(field)].kind)
        else:
            dofs = [system.dof(f.name, s) for f in system.fields for s in sites]
            to_si = sc.time_s if t.kind == "arrival_time" else sc.energy
        bound.append((t, np.asarray(dofs, np.int64), to_si))
        dofs_all += dofs
    obs = np.unique(np.asarray(dofs_all, np.int64))
    out = [BoundTerm(t, np.searchsorted(obs, d), d, to_si) for t, d, to_si in bound]
    return out, obs


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
            dq[:, t.cols] += c * tq
            dv[:, t.cols] += c * tv
            df[:, t.cols] += c * tf
            explicit.minv += c * tm
        return total, dq, dv, df, explicit
