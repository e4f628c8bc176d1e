"""The initial state of a mass lattice: the energy minimum nearest the config's initial displacement.

The models fold this state into their element shifts, so the dataset's ``u`` is measured from it;
datasets store it as ``u_rest``. For a dataset written before that, to tell which well a site
sits in, the render relaxes the lattice again from the config alone, like ``flexmm.models.mass_chain.relax``: a trust-region Newton–CG search
with short first steps (0.01 spacing), so a guess inside a well relaxes within it. Fixed and
driven ends are held where they start. Gradients are central differences of the element laws.
"""

from __future__ import annotations

import warnings

import numpy as np

from flexmm.linalg import central_difference
from flexmm.models.mass_topology import build_topology
from flexmm.render.laws import law_energy_j


def _numeric(law) -> list[str]:
    return [k for k, v in law if isinstance(v, float) and not isinstance(v, bool)]


def held_sites(p) -> np.ndarray:
    """Sites of the chain's (grid's) fixed or driven ends (a network's ends are lists of branches,
    never held)."""
    lat = p.lattice
    ends = build_topology(lat).ends
    out = [s for end, sites in ends.items() if getattr(lat, end) in ("fixed", "driven") for s in sites]
    return np.asarray(sorted(set(out)), np.int64)


class _Energy:
    """Total energy (J) of absolute site coordinates x (m) and its gradient (N)."""

    def __init__(self, p):
        self.p = p
        lat = p.lattice
        self.bond_terms = [(law, bonds, {k: p.values[f"{prefix}.{k}"] for k in _numeric(law)})
                           for prefix, law, bonds in (("bond", lat.bond, p.bonds), ("bond2", lat.bond2, p.bonds2))
                           if law is not None and len(bonds)]
        self.h = 1e-6 * p.spacing_m

    def energy(self, x) -> float:
        """Total energy (J) of bonds and on-site terms."""
        e = 0.0
        for law, sites, vals in self.p.onsite_terms:
            e += float(np.sum(law_energy_j(law, vals, x[sites])))
        for law, bonds, vals in self.bond_terms:
            e += float(np.sum(law_energy_j(law, vals, x[bonds[:, 1]] - x[bonds[:, 0]])))
        return e

    def _slope(self, law, vals, z):
        return (law_energy_j(law, vals, z + self.h) - law_energy_j(law, vals, z - self.h)) / (2 * self.h)

    def gradient(self, x) -> np.ndarray:
        """∂E/∂x (N) by central differences of each element's law."""
        g = np.zeros_like(x)
        for law, sites, vals in self.p.onsite_terms:
            np.add.at(g, sites, self._slope(law, vals, x[sites]))
        for law, bonds, vals in self.bond_terms:
            f = self._slope(law, vals, x[bonds[:, 1]] - x[bonds[:, 0]])
            np.add.at(g, bonds[:, 1], f)
            np.add.at(g, bonds[:, 0], -f)
        return g


def relaxed_initial(p) -> np.ndarray:
    """Initial site coordinates (m): the config's initial displacement, relaxed if ``relax``."""
    x0 = p.values["initial_displacement_m"].astype(float).copy()
    if not p.lattice.relax:
        return x0
    from scipy.optimize import minimize

    held = np.zeros(p.n_sites, bool)
    held[held_sites(p)] = True
    free = np.flatnonzero(~held)
    if free.size == 0:
        return x0
    model = _Energy(p)
    a = p.spacing_m
    work = x0.copy()
    scale = max(abs(model.energy(x0)), 1e-30)  # J: keeps the objective of order one

    def full(y):
        work[free] = y * a
        return work

    def fun(y):
        return model.energy(full(y)) / scale

    def jac(y):
        return model.gradient(full(y))[free] * a / scale

    def hessp(y, v):
        return central_difference(jac, y, v)

    with warnings.catch_warnings(), np.errstate(all="ignore"):
        warnings.simplefilter("ignore", RuntimeWarning)
        res = minimize(fun, x0[free] / a, jac=jac, hessp=hessp, method="trust-ncg",
                       options={"initial_trust_radius": 0.01, "max_trust_radius": 1.0, "gtol": 1e-10,
                                "maxiter": 5000})
    out = x0.copy()
    out[free] = res.x * a
    return out


__all__ = ["held_sites", "relaxed_initial"]
