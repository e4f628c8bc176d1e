"""Chains, networks and grids of masses from a run's stored config: layout, parameters, energies.

Sites and bonds are the model's (``flexmm.models.mass_topology.build_topology``: chain: sites in a
row; network: branches in order, then junctions, bonds along each branch; grid: site i + nx·j,
horizontal bonds, then vertical); a ring chain is drawn open. The dataset's ``u`` is the displacement from the initial state; a site's drawn
position is its rest point plus u along its branch direction (x for chains and grids).

A network has no 2D coordinates of its own; ``network_layout`` places the junctions on a line
and fans the free branches out from them (inputs to the left, outputs to the right).

The on-site coordinate of a site (for wells and energies) is its initial position plus u; the
initial position is the run's rest state ``u_rest`` as its dataset stores it; for a dataset
written before that, the config's ``initial_displacement_m`` (after variations) relaxed to the
nearest energy minimum, as the model does (``mass_relax.relaxed_initial``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from flexmm.config.lattice import MODELS
from flexmm.models.mass_topology import Topology, build_topology
from flexmm.models.variation import mass_values
from flexmm.render.laws import barriers, law_energy_j
from flexmm.render.mass_relax import relaxed_initial


@dataclass
class MassParams:
    """A mass lattice in SI: rest positions (N, 2), the direction u moves each site (N, 2),
    bonds (B, 2), per-element values (``values``), laws and on-site terms."""

    kind: str
    spacing_m: float
    rest_xy: np.ndarray
    direction: np.ndarray
    bonds: np.ndarray
    bonds2: np.ndarray
    values: dict[str, np.ndarray]
    lattice: object
    onsite_terms: list = field(default_factory=list)  # (law, sites (k,), values {name: (k,)})
    grid_shape: tuple[int, int] | None = None  # (nx, ny)
    beads: bool = False
    #: initial (relaxed) site coordinates (m); u is measured from them
    x0: np.ndarray | None = None

    @property
    def n_sites(self) -> int:
        """Number of sites."""
        return self.rest_xy.shape[0]


def _fan(count: int, spread_deg: float = 50.0) -> np.ndarray:
    """Directions (count, 2) fanned symmetrically about +x."""
    if count <= 1:
        return np.array([[1.0, 0.0]] * count)
    ang = np.radians(np.linspace(spread_deg / 2, -spread_deg / 2, count))
    return np.stack([np.cos(ang), np.sin(ang)], 1)


def network_layout(lat, topo: Topology) -> tuple[np.ndarray, np.ndarray]:
    """(rest_xy (N, 2), direction (N, 2)) of a mass network (its topology ``topo``), in metres.

    Junctions sit on the x axis in order of first appearance, (n + 1) spacings apart along the
    branches that join them; branches with a free start fan in from the left of their end
    junction, branches with a free end fan out to the right of their start junction, and
    branches without junctions are stacked below.
    """
    a = lat.spacing_m
    groups, n = topo.groups, topo.n_sites
    xy, dirs = np.zeros((n, 2)), np.tile([1.0, 0.0], (n, 1))
    jpos: dict[str, np.ndarray] = {}
    for b in lat.branches:  # place junctions along junction-to-junction branches
        for name in (b.start, b.end):
            if name is not None and name not in jpos:
                other = b.end if name == b.start else b.start
                base = jpos.get(other)
                if base is None:
                    jpos[name] = np.array([max((p[0] for p in jpos.values()), default=-a) + a, 0.0])
                else:
                    sign = 1.0 if name == b.end else -1.0
                    jpos[name] = base + sign * np.array([(b.n_units + 1) * a, 0.0])
    fan_in = {j: [b for b in lat.branches if b.end == j and b.start is None] for j in jpos}
    fan_out = {j: [b for b in lat.branches if b.start == j and b.end is None] for j in jpos}
    row = 0
    for b in lat.branches:
        s = np.asarray(groups[b.name])
        x = (np.arange(s.size) + (1 if b.start else 0)) * a
        if b.start and b.end:
            d = jpos[b.end] - jpos[b.start]
            length = np.hypot(*d)
            u = d / length if length > 0 else np.array([1.0, 0.0])
            origin, x = jpos[b.start], x * (length / ((s.size + 1) * a) if length > 0 else 1.0)
        elif b.end:
            u = _fan(len(fan_in[b.end]))[fan_in[b.end].index(b)]
            origin = jpos[b.end] - s.size * a * u
        elif b.start:
            u = _fan(len(fan_out[b.start]))[fan_out[b.start].index(b)]
            origin = jpos[b.start]
        else:
            row += 1
            u, origin = np.array([1.0, 0.0]), np.array([0.0, -3.0 * a * row])
        xy[s] = origin + x[:, None] * u
        dirs[s] = u
    for j in lat.junctions:
        xy[groups[j.name][0]] = jpos.get(j.name, np.zeros(2))
    return xy, dirs


def _numeric(law) -> list[tuple[str, float]]:
    return [(k, v) for k, v in law if isinstance(v, float) and not isinstance(v, bool)]


def mass_params(lat, rest: tuple[np.ndarray, np.ndarray] | None = None) -> MassParams:
    """The MassParams of a mass_chain, mass_network or mass_grid config.

    ``rest``: (saved sites, their stored rest positions ``u_rest`` in m) of the run; the initial
    positions of the other sites are then NaN. Without it they are relaxed from the config.
    """
    a = lat.spacing_m
    ring = getattr(lat, "left", None) == "periodic"  # drawn open, without its closing bonds
    topo = build_topology(lat.model_copy(update={"left": "free", "right": "free"}) if ring else lat)
    n, bonds, bonds2, grid_shape, groups = topo.n_sites, topo.bonds, topo.bonds2, topo.grid_shape, topo.groups
    vals = mass_values(lat, n, bonds, bonds2, grid_shape)
    if MODELS[lat.kind].branched:
        xy, dirs = network_layout(lat, topo)
    else:
        xy = np.stack([topo.coords["x"], topo.coords.get("y", np.zeros(n))], 1)
        dirs = np.tile([1.0, 0.0], (n, 1))
    for j in getattr(lat, "junctions", []):
        if j.mass_kg is not None:
            vals["mass_kg"][groups[j.name][0]] = j.mass_kg
    replaced = [groups[j.name][0] for j in getattr(lat, "junctions", []) if j.onsite is not None]
    sites = np.setdiff1d(np.arange(n), replaced)
    terms = [(law, sites, {name: vals[f"onsite.{k}.{name}"][sites] for name, _ in _numeric(law)})
             for k, law in enumerate(lat.onsite)]
    for j in getattr(lat, "junctions", []):
        for law in j.onsite or []:
            terms.append((law, np.array([groups[j.name][0]]), {nm: np.array([v]) for nm, v in _numeric(law)}))
    p = MassParams(lat.kind, a, xy, dirs, bonds, bonds2, vals, lat, terms, grid_shape, beads=lat.bond.law == "hertz")
    if rest is None:
        p.x0 = relaxed_initial(p)
    else:
        p.x0 = np.full(n, np.nan)
        ok = rest[0] < n  # a dataset of another lattice: MassStructure says so
        p.x0[rest[0][ok]] = rest[1][ok]
    return p


def _bond_values(p: MassParams, prefix: str, law) -> dict[str, np.ndarray]:
    return {name: p.values[f"{prefix}.{name}"] for name, _ in _numeric(law)}


def site_energy_j(p: MassParams, u: np.ndarray, u_dot: np.ndarray | None) -> np.ndarray:
    """Energy per site (J): kinetic, on-site terms and half of each bond it belongs to.

    ``u`` (and ``u_dot``) per site in metres (m/s); loads (static_load_n) and friction are not
    stored energy and are left out.
    """
    x0 = p.x0
    e = np.zeros(p.n_sites) if u_dot is None else 0.5 * p.values["mass_kg"] * u_dot**2
    pos = x0 + u
    for law, sites, vals in p.onsite_terms:
        e[sites] += law_energy_j(law, vals, pos[sites])
    lat = p.lattice
    for prefix, law, bonds in (("bond", lat.bond, p.bonds), ("bond2", lat.bond2, p.bonds2)):
        if law is None or not len(bonds):
            continue
        eb = law_energy_j(law, _bond_values(p, prefix, law), pos[bonds[:, 1]] - pos[bonds[:, 0]])
        e += 0.5 * (np.bincount(bonds[:, 0], eb, p.n_sites) + np.bincount(bonds[:, 1], eb, p.n_sites))
    return e


def onsite_barriers(p: MassParams, lo: float, hi: float) -> np.ndarray | None:
    """(N, m) barrier positions (m, +inf padded) of every site's on-site landscape on [lo, hi];
    None if no site has a barrier there (no multistable on-site term)."""
    if not p.onsite_terms:
        return None
    key = np.zeros((p.n_sites, 0))
    cols = []
    for t, (law, sites, vals) in enumerate(p.onsite_terms):
        for name in sorted(vals):
            col = np.full(p.n_sites, np.nan)
            col[sites] = vals[name]
            cols.append(col)
        mark = np.zeros(p.n_sites)
        mark[sites] = t + 1
        cols.append(mark)
    key = np.stack(cols, 1) if cols else key
    rows, inverse = np.unique(np.nan_to_num(key, nan=-1e300), axis=0, return_inverse=True)
    reps = np.array([np.flatnonzero(inverse.ravel() == r)[0] for r in range(rows.shape[0])])

    def energy(z):  # (g, 1) -> (g, k): the landscape of each representative site
        out = np.zeros((z.shape[0], reps.size))
        for law, sites, vals in p.onsite_terms:
            where = {int(s): i for i, s in enumerate(sites)}
            for r, site in enumerate(reps):
                if int(site) in where:
                    i = where[int(site)]
                    out[:, r] += law_energy_j(law, {k: v[i] for k, v in vals.items()}, z[:, 0])
        return out

    b = barriers(energy, lo, hi)
    if b.shape[1] == 0:
        return None
    return b[inverse.ravel()]


def well_index(pos: np.ndarray, site_barriers: np.ndarray) -> np.ndarray:
    """Well of each site: the number of its barriers below its on-site coordinate."""
    return np.sum(pos[:, None] > site_barriers, axis=1).astype(float)


__all__ = ["MassParams", "mass_params", "network_layout", "onsite_barriers", "site_energy_j", "well_index"]
