"""Per-element variation of parameters: gradients, seeded random scatter, defects.

Values live in a dict ``target -> (n_elements,) float array`` (SI, as in the config); each
variation rewrites one entry in place, in the order given.
"""

from __future__ import annotations

import numpy as np


def apply_variation(values: dict[str, np.ndarray], var, grid_shape=None) -> None:
    """Apply one Gradient, RandomVariation or Defects config to ``values[var.target]``."""
    a = values[var.target]
    n = a.size
    if var.kind == "gradient":
        first = 0 if var.first is None else var.first
        last = n - 1 if var.last is None else var.last
        if not 0 <= first <= last < n:
            raise ValueError(f"gradient of {var.target!r}: need 0 <= first <= last < {n}")
        a[first : last + 1] = np.linspace(var.start, var.end, last - first + 1)
    elif var.kind == "random":
        rng = np.random.default_rng(var.seed)
        if var.distribution == "normal":
            eps = rng.normal(0.0, var.relative_std, n)
        else:
            eps = rng.uniform(-1.0, 1.0, n) * var.relative_std * np.sqrt(3.0)
        a *= 1.0 + eps
    else:
        idx = _defect_sites(var, n, grid_shape)
        if var.value is not None:
            a[idx] = var.value
        else:
            a[idx] *= var.factor


def _defect_sites(var, n: int, grid_shape) -> np.ndarray:
    """Element indices a Defects variation touches (its sites plus its grid box)."""
    idx = list(var.sites)
    if var.box is not None:
        if grid_shape is None or var.target.startswith(("bond.", "bond2.")):
            raise ValueError(f"variation of {var.target!r}: 'box' needs a grid and a per-site target")
        nx, _ = grid_shape
        i0, i1, j0, j1 = var.box
        idx += [i + nx * j for j in range(j0, j1 + 1) for i in range(i0, i1 + 1)]
    idx = np.unique(np.asarray(idx, np.int64))
    if idx.size and idx.max() >= n:
        raise ValueError(f"variation of {var.target!r}: element {idx.max()} outside 0..{n - 1}")
    return idx
