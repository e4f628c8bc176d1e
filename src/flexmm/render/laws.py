"""Energies of the mass-lattice laws in SI (numpy), for energy colouring and well finding.

The same laws as ``flexmm.models.laws`` (docs/physics.md §2), written from the config's fields:
``law_energy_j(law, values, z)`` is E(z − offset) for a law config, with every numeric field
given per element (``values[name]``, after variations) and ``z`` the elongation (bond) or the
displacement (on site) in metres, broadcast over leading axes. ``barriers`` finds the barriers of an
on-site landscape numerically. ``tests/render/test_energy.py`` compares the energies with the models.
"""

from __future__ import annotations

import csv
from functools import lru_cache
from importlib.resources import files

import numpy as np

#: smallest dipole gap as a fraction of d (the law is singular at contact), as in the models
DIPOLE_MIN_GAP = 1e-3


@lru_cache(maxsize=1)
def raney_table() -> np.ndarray:
    """Rows (d_mm, C0..C8) of the bundled Raney 2016 energy table (ψ in mJ for x in mm)."""
    text = files("flexmm.data").joinpath("raney2016_bistable_energy_coeffs.csv").read_text()
    return np.array([[float(v) for v in line.split(",")] for line in text.splitlines()
                     if line and not line.startswith(("#", "d_mm"))])


def force_table(law) -> tuple[np.ndarray, np.ndarray]:
    """(displacement m, force N) of a tabulated law: inline lists or its CSV file."""
    if law.csv is None:
        return np.asarray(law.displacement_m, float), np.asarray(law.force_n, float)
    xs, fs = [], []
    with open(law.csv, newline="") as fh:
        for rec in csv.reader(line for line in fh if not line.lstrip().startswith("#")):
            try:
                xs.append(float(rec[0]))
                fs.append(float(rec[1]))
            except (ValueError, IndexError):
                continue
    return np.array(xs), np.array(fs)


def _table_energy(law, z):
    """∫ force of a C² not-a-knot spline through the table, linear force outside, E(0) = 0."""
    from scipy.interpolate import CubicSpline

    x, f = force_table(law)
    sp = CubicSpline(x, f, bc_type="not-a-knot")
    en = sp.antiderivative()

    def energy(zz):
        zc = np.clip(zz, x[0], x[-1])
        d = zz - zc
        return en(zc) + sp(zc) * d + 0.5 * sp(zc, 1) * d * d

    return energy(z) - energy(np.zeros(1))[0]


def _poly(z, coeffs):
    """Σ_{k≥1} c_k z^k (Horner), coefficients per element."""
    e = np.zeros_like(z)
    for c in reversed(coeffs):
        e = (e + c) * z
    return e


def law_energy_j(law, values: dict[str, np.ndarray], z) -> np.ndarray:
    """Energy (J) of ``law`` at elongation/displacement ``z`` (m), per element (SI fields)."""
    z = np.asarray(z, float) - values.get("offset_m", 0.0)
    kind = law.law
    v = values
    if kind == "linear":
        return 0.5 * v["k_n_per_m"] * z * z
    if kind == "polynomial":
        return _poly(z, [0.0, v["k1_n_per_m"] / 2, v["k2_n_per_m2"] / 3, v["k3_n_per_m3"] / 4])
    if kind == "polynomial_energy":
        return _poly(z, list(law.coefficients))
    if kind == "raney2016":
        t = raney_table()
        d = np.atleast_1d(np.asarray(v["d_mm"], float))
        c = [np.interp(d, t[:, 0], t[:, k]) for k in range(2, t.shape[1])]  # mJ/mm^k, k = 1..8
        return 1e-3 * _poly(1e3 * z, c)
    if kind == "bistable_cubic":
        a, b, j = v["alpha_n_per_m3"], v["beta"], v["jump_m"]
        return _poly(z, [0.0, a * b * j * j / 2, -a * (1 + b) * j / 3, a / 4])
    if kind == "phi4":
        h, w = v["barrier_j"], v["half_distance_m"]
        return _poly(z, [0.0, -2 * h / w**2, 0.0, h / w**4])
    if kind == "constant_force":
        return -v["force_n"] * z
    if kind == "sine":
        return v["amplitude_j"] * (1.0 - np.cos(2 * np.pi * z / v["period_m"]))
    if kind == "hertz":
        p = v["exponent"]
        delta = np.clip(v["precompression_m"] - z, 0.0, None)
        return v["stiffness_n_per_m_p"] * delta ** (p + 1) / (p + 1)
    if kind == "toda":
        a, b = v["a_n"], v["b_per_m"]
        return a / b * np.expm1(-b * z) + a * z
    if kind == "dipole":
        c = v["coefficient_j_m_p"] if law.coefficient_j_m_p is not None else 1e-7 * v["moment_a_m2"] ** 2
        gap = np.maximum(v["distance_m"] + z, DIPOLE_MIN_GAP * v["distance_m"])
        return c * gap ** (-v["exponent"])
    if kind == "table":
        return _table_energy(law, z)
    raise ValueError(f"unknown law {kind!r}")


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


__all__ = ["barriers", "force_table", "law_energy_j", "raney_table"]
