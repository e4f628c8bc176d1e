"""Per-unit and per-hinge parameter arrays of the rigid-unit lattices from ``variation`` configs.

Units carry θ0, mass and inertia; hinges carry k_l, k_s, k_θ (``flexmm.config.rigid``). Each
variation in the list acts in order on the current values:

- gradient: linear ramp in the column (axis x) or row (axis y) index, a hinge takes the mean of
  its two units;
- interface: units with index ≥ position take the new value, a hinge across takes the mean;
- random: adds N(0, std) or multiplies by 1 + N(0, relative_std), independently per element;
- defects: sets (or scales) the value on listed units, or on every hinge touching them.
"""

from __future__ import annotations

import numpy as np

from flexmm.config.rigid import HINGE_TARGETS, SITE_TARGETS


def _ramp(v, idx: np.ndarray, size: int) -> np.ndarray:
    """Gradient values at unit indices ``idx``: start at ``first``, end at ``last``, flat outside."""
    first = v.first or 0
    last = size - 1 if v.last is None else v.last
    return v.start + (v.end - v.start) * np.clip((idx - first) / (last - first), 0.0, 1.0)


def _apply(v, values: np.ndarray, idx_units: tuple[np.ndarray, ...], size: int, key: int, touches) -> np.ndarray:
    """One variation on one array; ``idx_units``: unit indices along the axis (1 array for units,
    2 for hinges, whose value is the mean over their two units)."""
    if v.kind == "gradient":
        return sum(_ramp(v, i, size) for i in idx_units) / len(idx_units)
    if v.kind == "interface":
        w = sum((i >= v.position).astype(float) for i in idx_units) / len(idx_units)
        return values * (1.0 - w) + v.value * w
    if v.kind == "random":
        rng = np.random.default_rng([v.seed, key])
        eps = rng.normal(0.0, v.std if v.std is not None else v.relative_std, values.size)
        return values + eps if v.std is not None else values * (1.0 + eps)
    out = values.copy()
    mask = touches(np.asarray(v.sites))
    out[mask] = v.value if v.value is not None else values[mask] * v.factor
    return out


def parameter_arrays(base: dict[str, float], variations, col: np.ndarray, row: np.ndarray,
                     ha: np.ndarray, hb: np.ndarray) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Per-unit (N,) and per-hinge (H,) arrays of every target, in SI, after the variations.

    ``base`` maps each target to its uniform value; ``col``, ``row`` are the units' indices;
    ``ha``, ``hb`` the hinges' unit pairs.
    """
    n, nh = col.size, ha.size
    sites = {k: np.full(n, float(base[k])) for k in SITE_TARGETS}
    hinges = {k: np.full(nh, float(base[k])) for k in HINGE_TARGETS}
    for key, v in enumerate(variations):
        axis = row if getattr(v, "axis", "x") == "y" else col
        size = int(axis.max()) + 1
        if v.target in SITE_TARGETS:
            sites[v.target] = _apply(v, sites[v.target], (axis,), size, key,
                                     lambda s: np.isin(np.arange(n), s))
        else:
            hinges[v.target] = _apply(v, hinges[v.target], (axis[ha], axis[hb]), size, key,
                                      lambda s: np.isin(ha, s) | np.isin(hb, s))
    return sites, hinges
