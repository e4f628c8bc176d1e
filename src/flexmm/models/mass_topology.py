"""Sites and bonds of chains, networks of chains (junctions) and square grids of masses.

A topology is plain arrays: nearest-neighbour bonds ``(B, 2)`` oriented (i → j, elongation
x_j − x_i), second-neighbour bonds ``(B2, 2)``, named end site lists and rest coordinates.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from flexmm.config.lattice import MODELS


@dataclass
class Topology:
    """Connectivity of a lattice of scalar sites."""

    n_sites: int
    bonds: np.ndarray
    bonds2: np.ndarray
    ends: dict[str, list[int]]
    coords: dict[str, np.ndarray]
    groups: dict[str, list[int]] = field(default_factory=dict)
    grid_shape: tuple[int, int] | None = None


def second_neighbours(n_sites: int, bonds: np.ndarray) -> np.ndarray:
    """Pairs (i, k) for every path i → j → k of two oriented bonds (a chain gives (i, i + 2))."""
    incoming: list[list[int]] = [[] for _ in range(n_sites)]
    outgoing: list[list[int]] = [[] for _ in range(n_sites)]
    for i, j in bonds:
        outgoing[i].append(int(j))
        incoming[j].append(int(i))
    pairs = [(i, k) for j in range(n_sites) for i in incoming[j] for k in outgoing[j]]
    return np.array(pairs, np.int64).reshape(-1, 2)


def chain(cfg) -> Topology:
    """n sites in a row; ends 'left' = [0], 'right' = [n − 1]. A ring (``left: periodic``): the
    bonds (n − 1, 0) and second-neighbour bonds (n − 2, 0), (n − 1, 1) close it (elongation
    u_0 − u_{n−1}: site 0 sits one spacing beyond site n − 1)."""
    n, spacing_m, periodic = cfg.n_units, cfg.spacing_m, cfg.left == "periodic"
    i = np.arange(n if periodic else n - 1, dtype=np.int64)
    bonds = np.stack([i, (i + 1) % n], axis=1)
    j = np.arange(n if periodic else max(n - 2, 0), dtype=np.int64)
    return Topology(n, bonds, np.stack([j, (j + 2) % n], axis=1), {"left": [0], "right": [n - 1]},
                    {"x": np.arange(n) * spacing_m})


def network(cfg) -> Topology:
    """Branches numbered in order, then junctions; bonds follow each branch's direction.

    Coordinate 'x' is the distance along the branch from its start (junctions: 0);
    ``groups`` maps each branch and junction name to its sites.
    """
    start = 0
    groups: dict[str, list[int]] = {}
    for b in cfg.branches:
        groups[b.name] = list(range(start, start + b.n_units))
        start += b.n_units
    for j in cfg.junctions:
        groups[j.name] = [start]
        start += 1
    bonds = []
    x = np.zeros(start)
    for b in cfg.branches:
        s = groups[b.name]
        x[s] = (np.arange(len(s)) + (1 if b.start else 0)) * cfg.spacing_m
        path = ([groups[b.start][0]] if b.start else []) + s + ([groups[b.end][0]] if b.end else [])
        bonds += list(zip(path[:-1], path[1:]))
    bonds = np.array(bonds, np.int64).reshape(-1, 2)
    ends = {"left": [groups[n][0] for n in cfg.left], "right": [groups[n][-1] for n in cfg.right]}
    return Topology(start, bonds, second_neighbours(start, bonds), ends, {"x": x}, groups)


def grid(cfg) -> Topology:
    """Site i + nx·j; horizontal bonds first, then vertical; bonds2 are the two diagonals."""
    nx, ny, spacing_m = cfg.nx, cfg.ny, cfg.spacing_m
    idx = np.arange(nx * ny, dtype=np.int64).reshape(ny, nx)
    h = np.stack([idx[:, :-1].ravel(), idx[:, 1:].ravel()], axis=1)
    v = np.stack([idx[:-1, :].ravel(), idx[1:, :].ravel()], axis=1)
    d1 = np.stack([idx[:-1, :-1].ravel(), idx[1:, 1:].ravel()], axis=1)
    d2 = np.stack([idx[:-1, 1:].ravel(), idx[1:, :-1].ravel()], axis=1)
    ii, jj = np.meshgrid(np.arange(nx), np.arange(ny))
    return Topology(
        nx * ny, np.concatenate([h, v]), np.concatenate([d1, d2]),
        {"left": idx[:, 0].tolist(), "right": idx[:, -1].tolist()},
        {"x": ii.ravel() * spacing_m, "y": jj.ravel() * spacing_m},
        grid_shape=(nx, ny),
    )


def build_topology(cfg) -> Topology:
    """The topology of a lattice of masses (its kind's ``topology`` hook, ``config.lattice.MODELS``)."""
    return MODELS[cfg.kind].hook("topology")(cfg)
