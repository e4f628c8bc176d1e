"""Energies of the mass-lattice laws in SI, for energy colouring and well finding.

``law_energy_j(law, values, z)`` is E(z − offset) of a law config, with every numeric field
given per element (``values[name]``, after variations) and ``z`` the elongation (bond) or the
displacement (on site) in metres, broadcast over leading axes: the models' compiled law
(docs/physics.md §2), not a copy of it. ``barriers`` finds the barriers of an on-site landscape
numerically.
"""

from __future__ import annotations

import numpy as np

from flexmm.models import laws as lw
from flexmm.models.mass_params import law_rows
from flexmm.units import Scales

#: SI as the unit system: law_rows then gives rows in J and m
_SI = Scales(length_m=1.0, time_s=1.0, mass_kg=1.0)


def law_energy_j(law, values: dict[str, np.ndarray], z) -> np.ndarray:
    """Energy (J) of ``law`` at elongation/displacement ``z`` (m), per element (SI fields).

    ``values`` holds each numeric field per element, (k,) or scalars; ``z`` broadcasts against
    them over leading axes. The law is the models' own (``models.laws.law`` on the rows
    ``models.mass_params.law_rows`` builds), evaluated in SI units.
    """
    z = np.asarray(z, float)
    k = max([np.size(v) for v in values.values()] + [1])
    vals = {name: np.broadcast_to(np.asarray(v, float), (k,)) for name, v in values.items()}
    vals.setdefault("offset_m", np.zeros(k))
    code, rows, tab = law_rows(law, vals, _SI, k)
    zz = np.broadcast_to(z, np.broadcast_shapes(z.shape, (k,)))
    flat = np.ascontiguousarray(zz.reshape(-1, k))
    out = np.empty_like(flat)
    lw.energies(code, flat, rows, np.zeros(1) if tab is None else tab, out)
    return out.reshape(zz.shape)


def barriers(energy, lo: float, hi: float, n: int = 4001) -> np.ndarray:
    """Positions of the local maxima of ``energy(z) -> (n, k)`` on [lo, hi] for k landscapes.

    Returns an (k, m) array padded with +inf (m: the most barriers of any landscape), sorted.
    """
    z = np.linspace(lo, hi, n)
    e = energy(z[:, None])  # (n, k)
    inner = (e[1:-1] > e[:-2]) & (e[1:-1] >= e[2:])
    k = e.shape[1]
    found = [z[1:-1][inner[:, j]] for j in range(k)]
    m = max((f.size for f in found), default=0)
    out = np.full((k, m), np.inf)
    for j, f in enumerate(found):
        out[j, : f.size] = f
    return out


__all__ = ["barriers", "law_energy_j"]
