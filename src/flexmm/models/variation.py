"""Per-element parameter arrays from a lattice's ``variation`` list: the one engine of every lattice.

The semantics are those of ``flexmm.config.variation`` (docs/scenes.md, Parameter variation):
entries act in order on the current values; sites are located by their column or row (``line``);
a bond belongs to the two sites it joins (``ends``):

- gradient: sites on lines first..last take the ramp, others keep their value; a bond takes the
  mean over its two sites of (the ramp if that site is in range, else the bond's current value);
- interface: the same with the constant ``value`` on the lines ≥ position;
- random: ``default_rng([seed, crc32(target)])`` draws one ε per element in element order;
- defects: listed sites (and ``box``) are set or scaled; a bond target changes the bonds touching them;
- values: one value per element (sites in site order, bonds in the order of ``ends``).

Used by the rotating-squares chain and sheet, the chains, networks and grids of masses, and the
render layer (which reads a run's config); so one YAML entry gives the same values everywhere.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Callable, Mapping
from functools import partial

import numpy as np

from flexmm.config.rigid import HINGE_TARGETS, SITE_TARGETS

#: ``ends(target)``: None for a per-site target, else the (a, b) site pairs of the target's bonds
Ends = Callable[[str], "tuple[np.ndarray, np.ndarray] | None"]


def noise(v, n: int) -> np.ndarray:
    """The ε of a Random entry for ``n`` elements (reproducible from its seed and target)."""
    rng = np.random.default_rng([v.seed, zlib.crc32(v.target.encode())])
    sigma = v.std if v.std is not None else v.relative_std
    if v.distribution == "normal":
        return rng.normal(0.0, sigma, n)
    return rng.uniform(-1.0, 1.0, n) * sigma * math.sqrt(3.0)


def _ramp(v, line: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray]:
    """(new value, selected) per site of a Gradient entry: as np.linspace over first..last."""
    first, last = v.first or 0, size - 1 if v.last is None else v.last
    ramp = np.where(line == last, v.end, (line - first) * ((v.end - v.start) / (last - first)) + v.start)
    return ramp, (line >= first) & (line <= last)


def _on_lines(profile, v, old, col, row, pair):
    """An entry that sets sites by their line; ``profile(v, line, size) -> (new value, selected)``."""
    line = row if v.axis == "y" else col
    new, sel = profile(v, line, int(line.max()) + 1)
    if pair is None:
        return np.where(sel, new, old)
    return 0.5 * (np.where(sel[pair[0]], new[pair[0]], old) + np.where(sel[pair[1]], new[pair[1]], old))


def _values(v, old, col, row, pair):
    if len(v.values) != old.size:
        raise ValueError(f"a variation of kind values lists {len(v.values)} values for {v.target}; the lattice "
                         f"has {old.size} elements of it (one value per {'site' if pair is None else 'bond (hinge)'}"
                         ", in element order)")
    return np.array(v.values, float)


def _defects(v, old, col, row, pair):
    hit = np.zeros(col.size, bool)  # the sites the entry lists, plus its box
    hit[np.asarray(v.sites, np.int64)] = True
    if v.box is not None:
        i0, i1, j0, j1 = v.box
        hit |= (col >= i0) & (col <= i1) & (row >= j0) & (row <= j1)
    mask = hit if pair is None else hit[pair[0]] | hit[pair[1]]
    out = old.copy()
    out[mask] = v.value if v.value is not None else old[mask] * v.factor
    return out


#: entry kind -> ``rule(entry, old, col, row, pair)``: the values of one target after the entry
RULES = {
    "gradient": partial(_on_lines, _ramp),
    "interface": partial(_on_lines, lambda v, line, size: (np.full(line.shape, float(v.value)), line >= v.position)),
    "random": lambda v, old, col, row, pair: (old + noise(v, old.size) if v.std is not None
                                              else old * (1.0 + noise(v, old.size))),
    "values": _values,
    "defects": _defects,
}


def vary(v, old: np.ndarray, col: np.ndarray, row: np.ndarray, pair) -> np.ndarray:
    """The values of one target after one entry; ``pair`` = (a, b) of a bond target, else None."""
    return RULES[v.kind](v, old, col, row, pair)


def apply_variations(values: dict[str, np.ndarray], variations, col: np.ndarray, row: np.ndarray,
                     ends: Ends) -> None:
    """Apply a variation list in order to ``values`` (target -> per-element array, SI), in place.

    ``col``, ``row``: each site's column and row (a chain or network: its index and 0).
    """
    for v in variations:
        values[v.target] = vary(v, np.asarray(values[v.target], float), col, row, ends(v.target))


def site_lines(n_sites: int, grid_shape: tuple[int, int] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(column, row) of every site: i, j of site i + nx·j on an (nx, ny) grid; else the index, 0."""
    idx = np.arange(n_sites)
    if grid_shape is None:
        return idx, np.zeros_like(idx)
    return idx % grid_shape[0], idx // grid_shape[0]


def mass_values(cfg, n_sites: int, bonds: np.ndarray, bonds2: np.ndarray,
                grid_shape: tuple[int, int] | None = None) -> dict[str, np.ndarray]:
    """Every variation target of a lattice of masses per element (SI), after its variations.

    Per site: mass, initial displacement, friction and on-site law fields; per bond of ``bonds``
    (B, 2) the ``bond.*`` fields, per bond of ``bonds2`` the ``bond2.*`` fields.
    """
    pairs = {"bond": (bonds[:, 0], bonds[:, 1]), "bond2": (bonds2[:, 0], bonds2[:, 1])}
    vals = {"mass_kg": np.full(n_sites, cfg.mass_kg),
            "initial_displacement_m": np.full(n_sites, cfg.initial_displacement_m)}
    if cfg.friction is not None:
        vals["friction.force_n"] = np.full(n_sites, cfg.friction.force_n)
    for prefix, law in [("bond", cfg.bond), ("bond2", cfg.bond2)] + [(f"onsite.{k}", law)
                                                                     for k, law in enumerate(cfg.onsite)]:
        if law is not None:
            size = len(pairs[prefix][0]) if prefix in pairs else n_sites
            vals |= {f"{prefix}.{name}": np.full(size, value) for name, value in law
                     if isinstance(value, float)}
    col, row = site_lines(n_sites, grid_shape)
    apply_variations(vals, cfg.variation, col, row, lambda target: pairs.get(target.split(".")[0]))
    return vals


def parameter_arrays(base: Mapping[str, float], variations, col: np.ndarray, row: np.ndarray,
                     ha: np.ndarray, hb: np.ndarray) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Per-unit (N,) and per-hinge (H,) arrays of a rigid-unit lattice's targets, in SI.

    ``base`` maps each target to its uniform value; ``col``, ``row`` are the units' column and
    row; ``ha``, ``hb`` the hinges' unit pairs.
    """
    values = {k: np.full(col.size, float(base[k])) for k in SITE_TARGETS}
    values |= {k: np.full(ha.size, float(base[k])) for k in HINGE_TARGETS}
    apply_variations(values, variations, col, row, lambda t: (ha, hb) if t in HINGE_TARGETS else None)
    return {k: values[k] for k in SITE_TARGETS}, {k: values[k] for k in HINGE_TARGETS}
