"""From SI law configs to nondimensional parameter rows of ``flexmm.models.laws``.

Units inside: length L (the site spacing), mass m (a site), time sqrt(m/k_ref), so a force
unit F = k_ref L and an energy unit E = k_ref L². Every numeric law field arrives as an (n,)
array (one value per element, after variations), so rows are built vectorised.
"""

from __future__ import annotations

import csv
import math
from functools import lru_cache
from importlib.resources import files

import numpy as np

from flexmm.models import laws as lw
from flexmm.units import Scales


@lru_cache(maxsize=1)
def raney_table() -> np.ndarray:
    """The bundled Raney 2016 table: rows (d_mm, C0..C8), ψ in mJ for x in mm."""
    text = files("flexmm.data").joinpath("raney2016_bistable_energy_coeffs.csv").read_text()
    rows = [[float(v) for v in line.split(",")] for line in text.splitlines()
            if line and not line.startswith(("#", "d_mm"))]
    return np.array(rows)


def raney_coefficients(d_mm) -> np.ndarray:
    """(n, 8) coefficients C_1..C_8 (mJ/mm^k) for constraint widths ``d_mm`` (n,), linear in d."""
    t = raney_table()
    d = np.atleast_1d(np.asarray(d_mm, float))
    if d.min() < t[0, 0] - 1e-9 or d.max() > t[-1, 0] + 1e-9:
        raise ValueError(f"d_mm outside the Raney 2016 table ({t[0, 0]} ... {t[-1, 0]})")
    return np.stack([np.interp(d, t[:, 0], t[:, k]) for k in range(2, t.shape[1])], axis=1)


def read_force_table(law) -> tuple[np.ndarray, np.ndarray]:
    """(displacement m, force N) of a tabulated law, from its inline lists or CSV file."""
    if law.csv is None:
        return np.asarray(law.displacement_m, float), np.asarray(law.force_n, float)
    xs, fs = [], []
    with open(law.csv, newline="") as fh:
        for rec in csv.reader(line for line in fh if not line.lstrip().startswith("#")):
            try:
                x, f = float(rec[0]), float(rec[1])
            except (ValueError, IndexError):
                continue  # header
            xs.append(x)
            fs.append(f)
    return np.array(xs), np.array(fs)


def rest_stiffness(law, spacing_m: float) -> float:
    """A positive stiffness (N/m) characterising ``law`` near rest, for the time scale."""
    kind = law.law
    if kind == "linear":
        return law.k_n_per_m
    if kind == "polynomial":
        return abs(law.k1_n_per_m) or 1.0
    if kind == "hertz":
        d0 = law.precompression_m
        return law.stiffness_n_per_m_p * law.exponent * (d0 if d0 > 0 else spacing_m) ** (law.exponent - 1)
    if kind == "toda":
        return law.a_n * law.b_per_m
    if kind == "dipole":
        p = law.exponent
        return p * (p + 1) * law.coefficient / law.distance_m ** (p + 2)
    if kind == "table":
        x, f = read_force_table(law)
        return abs(float(np.interp(0.0, x, np.gradient(f, x)))) or 1.0
    return 1.0


def law_rows(law, vals: dict[str, np.ndarray], sc: Scales, n: int) -> tuple[int, np.ndarray, np.ndarray | None]:
    """Kernel code, (n, N_LAW_PRM) rows and (for tables) the flat spline table of one law.

    ``vals`` maps each numeric field name of ``law`` to its (n,) per-element values (SI).
    """
    L, E = sc.length_m, sc.energy
    F = E / L
    rows = np.zeros((n, lw.N_LAW_PRM))
    rows[:, 0] = -vals["offset_m"] / L
    kind = law.law

    def poly(*coeffs_si):  # c_k in J/m^k for k = 1, 2, ...
        for k, c in enumerate(coeffs_si, start=1):
            rows[:, k] = c * L**k / E
        return lw.POLY, rows, None

    if kind == "linear":
        return poly(0.0, 0.5 * vals["k_n_per_m"])
    if kind == "polynomial":
        return poly(0.0, vals["k1_n_per_m"] / 2, vals["k2_n_per_m2"] / 3, vals["k3_n_per_m3"] / 4)
    if kind == "polynomial_energy":
        return poly(*law.coefficients)
    if kind == "raney2016":
        c = raney_coefficients(vals["d_mm"])  # mJ/mm^k
        return poly(*(1e-3 * c[:, k] * 1e3 ** (k + 1) for k in range(c.shape[1])))
    if kind == "bistable_cubic":
        a, b, j = vals["alpha_n_per_m3"], vals["beta"], vals["jump_m"]
        return poly(0.0, a * b * j * j / 2, -a * (1 + b) * j / 3, a / 4)
    if kind == "phi4":
        h, w = vals["barrier_j"], vals["half_distance_m"]
        return poly(0.0, -2 * h / w**2, 0.0, h / w**4)
    if kind == "constant_force":
        return poly(-vals["force_n"])
    if kind == "sine":
        rows[:, 1] = vals["amplitude_j"] / E
        rows[:, 2] = 2 * math.pi * L / vals["period_m"]
        return lw.SINE, rows, None
    if kind == "hertz":
        p = vals["exponent"]
        rows[:, 1] = vals["stiffness_n_per_m_p"] * L**p / F
        rows[:, 2] = p
        rows[:, 3] = vals["precompression_m"] / L
        return lw.HERTZ, rows, None
    if kind == "toda":
        rows[:, 1] = vals["a_n"] / F
        rows[:, 2] = vals["b_per_m"] * L
        return lw.TODA, rows, None
    if kind == "dipole":
        p = vals["exponent"]
        if law.coefficient_j_m_p is not None:
            c = vals["coefficient_j_m_p"]
        else:
            c = 1e-7 * vals["moment_a_m2"] ** 2
        rows[:, 1] = c / (E * L**p)
        rows[:, 2] = vals["distance_m"] / L
        rows[:, 3] = p
        return lw.DIPOLE, rows, None
    if kind == "table":
        x, f = read_force_table(law)
        tab = lw.spline_table(x / L, f / F)
        rows[:, 1] = 0.0  # start, offset by the caller when tables are concatenated
        rows[:, 2] = x.size
        return lw.TABLE, rows, tab
    raise ValueError(f"unknown law {kind!r}")
