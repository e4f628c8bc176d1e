"""Per-element parameter variation: one schema for every lattice (docs/scenes.md, Parameter variation).

A lattice's ``variation`` is a list applied in order; each entry rewrites the per-element values of
one ``target`` (a per-site or a per-bond parameter; the lattice says which). Elements are located by
the *lines* of their sites: the column (``axis: x``) or row (``axis: y``) of a site on a 2D lattice,
its index on a chain or network (one row). A bond (a hinge of the rigid-unit lattices) belongs to
the two sites it joins. The engine is ``flexmm.models.variation``; this module holds the schema and
the checks against the lattice's size, so a bad entry is a config error at its file:line.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Annotated, Literal, Union

from pydantic import Field, model_validator

from flexmm.config.base import Finite, NonNegative, Strict, exactly_one

Axis = Literal["x", "y"]


class Gradient(Strict):
    """Linear ramp over the lines ``first``..``last`` (default: all), ``start`` at first, ``end`` at last.

    Outside first..last the values stay as they were (no clamping), so gradients compose into
    piecewise-linear profiles. A bond takes the mean over its two sites of the ramp (a site in
    range) or of its current value (a site outside).
    """

    kind: Literal["gradient"]
    target: str
    start: Finite
    end: Finite
    axis: Axis = "x"
    first: int | None = Field(None, ge=0, description="first line of the ramp (default 0)")
    last: int | None = Field(None, ge=0, description="last line of the ramp (default the last line)")


class Interface(Strict):
    """Two lattices joined at line ``position``: sites on lines ≥ position take ``value``.

    A bond across the interface takes the mean of ``value`` and its current value.
    """

    kind: Literal["interface"]
    target: str
    position: int = Field(ge=1, description="first column (axis x) or row (axis y) of the second lattice")
    value: Finite
    axis: Axis = "x"


class Random(Strict):
    """Independent noise on every element, reproducible from ``seed``.

    ``std`` adds σε (in the target's unit), ``relative_std`` multiplies by 1 + σε; ε is standard
    normal, or uniform on ±√3 (the same variance). The generator is seeded by (``seed``, a CRC-32
    of ``target``) and draws one ε per element in element order: the noise of an entry does not
    depend on the other entries, and two targets with the same seed get independent noise.
    """

    kind: Literal["random"]
    target: str
    std: NonNegative | None = None
    relative_std: NonNegative | None = None
    distribution: Literal["normal", "uniform"] = "normal"
    seed: int = Field(0, ge=0)

    @model_validator(mode="after")
    def _one(self):
        return exactly_one(self, "std", "relative_std")


class Defects(Strict):
    """Set ``target`` to ``value`` (or multiply it by ``factor``) on the listed sites.

    ``sites`` are site indices; ``box`` = [i0, i1, j0, j1] (inclusive) adds the sites of columns
    i0..i1 and rows j0..j1. A bond target changes every bond touching a listed site (once).
    """

    kind: Literal["defects"]
    target: str
    sites: list[Annotated[int, Field(ge=0)]] = Field(default_factory=list)
    box: list[Annotated[int, Field(ge=0)]] | None = Field(None, min_length=4, max_length=4)
    value: Finite | None = None
    factor: Finite | None = None

    @model_validator(mode="after")
    def _what(self):
        exactly_one(self, "value", "factor")
        if not self.sites and self.box is None:
            raise ValueError("give sites or box")
        return self


class Values(Strict):
    """Every element of ``target`` takes its own value: ``values`` lists one per element, in element
    order (a per-site target: site order; a bond or hinge target: the lattice's bond order,
    docs/scenes.md). Written by ``flexmm design`` for a per-element design (profile each)."""

    kind: Literal["values"]
    target: str
    values: list[Finite] = Field(min_length=1, description="one value per element of the target, in element order")


Variation = Annotated[Union[Gradient, Interface, Random, Defects, Values], Field(discriminator="kind")]


def _at(i: int, v, *names: str) -> str:
    """``variation.i.name = value`` of entry ``i``'s first given field among ``names`` (the loader
    points at its line), else ``variation.i``."""
    given = [n for n in names if n in v.model_fields_set]
    return f"variation.{i}.{given[0]} = {getattr(v, given[0])}" if given else f"variation.{i}"


def check_variations(variation: Sequence, *, n_cols: int, n_rows: int, site_targets: Sequence[str],
                     bond_targets: Sequence[str]) -> None:
    """Check a lattice's variation list against its size and targets; ValueError naming the entry.

    ``n_cols`` × ``n_rows`` lines (a chain or network: its sites × 1); sites are numbered
    row · n_cols + col.
    """
    valid = list(site_targets) + list(bond_targets)
    n_sites = n_cols * n_rows
    for i, v in enumerate(variation):
        if v.target not in valid:
            raise ValueError(f"{_at(i, v, 'target')}: not a parameter of this lattice; valid: {', '.join(valid)}")
        size, lines = (n_rows, "rows") if getattr(v, "axis", "x") == "y" else (n_cols, "columns")
        if size == 1 and v.kind != "values":
            raise ValueError(f"{_at(i, v, 'axis')}: the lattice has a single row (use axis x)")
        if v.kind == "gradient":
            first, last = v.first or 0, size - 1 if v.last is None else v.last
            if not first < last < size:
                raise ValueError(f"{_at(i, v, 'last', 'first', 'axis')}: a gradient needs first < last < {size} "
                                 f"(the lattice has {size} {lines}), got first {first}, last {last}")
        elif v.kind == "interface" and v.position >= size:
            raise ValueError(f"{_at(i, v, 'position')}: an interface needs 1 ≤ position ≤ {size - 1} "
                             f"(the lattice has {size} {lines})")
        elif v.kind == "values" and v.target in site_targets and len(v.values) != n_sites:
            raise ValueError(f"variation.{i}.values: {len(v.values)} values; {v.target} is per site and the "
                             f"lattice has {n_sites} sites (one value each, in site order)")
        elif v.kind == "defects":
            bad = [s for s in v.sites if s >= n_sites]
            if bad:
                raise ValueError(f"{_at(i, v, 'sites')}: sites {bad} outside 0..{n_sites - 1}")
            if v.box is not None:
                i0, i1, j0, j1 = v.box
                if not (i0 <= i1 < n_cols and j0 <= j1 < n_rows):
                    raise ValueError(f"{_at(i, v, 'box')}: a box [i0, i1, j0, j1] needs i0 ≤ i1 < {n_cols} "
                                     f"and j0 ≤ j1 < {n_rows}")
