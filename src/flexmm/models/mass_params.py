"""From SI law configs to nondimensional parameter rows of ``flexmm.models.laws``.

Units inside: length L (the site spacing), mass m (a site), time sqrt(m/k_ref), so a force
unit F = k_ref L and an energy unit E = k_ref L². Every numeric law field arrives as an (n,)
array (one value per element, after variations), so rows are built vectorised.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Callable
from dataclasses import dataclass
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


def _poly(L: float, E: float, *coeffs_si):
    """The POLY law's columns from its energy coefficients c_k (J/m^k, k = 1, 2, ...)."""
    return lw.POLY, [c * L**k / E for k, c in enumerate(coeffs_si, start=1)], None


def _dipole(law, v, L, E):
    p = v["exponent"]
    c = v["coefficient_j_m_p"] if law.coefficient_j_m_p is not None else 1e-7 * v["moment_a_m2"] ** 2
    return lw.DIPOLE, [c / (E * L**p), v["distance_m"] / L, p], None


def _table(law, v, L, E):
    x, f = read_force_table(law)  # column 1: the start, offset by the caller when tables are concatenated
    return lw.TABLE, [0.0, x.size], lw.spline_table(x / L, f / (E / L))


def _table_stiffness(law, spacing_m):
    x, f = read_force_table(law)
    return abs(float(np.interp(0.0, x, np.gradient(f, x)))) or 1.0


def _raney(law, v, L, E):
    c = raney_coefficients(v["d_mm"])  # mJ/mm^k
    return _poly(L, E, *(1e-3 * c[:, k] * 1e3 ** (k + 1) for k in range(c.shape[1])))


@dataclass(frozen=True)
class LawRule:
    """How one law of ``config.mass_chain`` (by its ``law`` name) becomes kernel parameters:
    ``columns(law, vals, L, E) -> (kernel code, [column 1, 2, ...], spline table or None)`` from the
    per-element SI values ``vals`` in the length and energy units L, E; ``stiffness(law, spacing_m)``
    a positive stiffness (N/m) near rest, for the time scale."""

    columns: Callable
    stiffness: Callable = lambda law, spacing_m: 1.0


#: every law, keyed by its config ``law`` name
LAWS: dict[str, LawRule] = {
    "linear": LawRule(lambda law, v, L, E: _poly(L, E, 0.0, 0.5 * v["k_n_per_m"]), lambda law, h: law.k_n_per_m),
    "polynomial": LawRule(lambda law, v, L, E: _poly(L, E, 0.0, v["k1_n_per_m"] / 2, v["k2_n_per_m2"] / 3,
                                                     v["k3_n_per_m3"] / 4), lambda law, h: abs(law.k1_n_per_m) or 1.0),
    "polynomial_energy": LawRule(lambda law, v, L, E: _poly(L, E, *law.coefficients)),
    "raney2016": LawRule(_raney),
    "bistable_cubic": LawRule(lambda law, v, L, E: _poly(
        L, E, 0.0, v["alpha_n_per_m3"] * v["beta"] * v["jump_m"] * v["jump_m"] / 2,
        -v["alpha_n_per_m3"] * (1 + v["beta"]) * v["jump_m"] / 3, v["alpha_n_per_m3"] / 4)),
    "phi4": LawRule(lambda law, v, L, E: _poly(L, E, 0.0, -2 * v["barrier_j"] / v["half_distance_m"]**2, 0.0,
                                               v["barrier_j"] / v["half_distance_m"]**4)),
    "constant_force": LawRule(lambda law, v, L, E: _poly(L, E, -v["force_n"])),
    "sine": LawRule(lambda law, v, L, E: (lw.SINE, [v["amplitude_j"] / E, 2 * math.pi * L / v["period_m"]], None)),
    "hertz": LawRule(lambda law, v, L, E: (lw.HERTZ, [v["stiffness_n_per_m_p"] * L**v["exponent"] / (E / L),
                                                      v["exponent"], v["precompression_m"] / L], None),
                     lambda law, h: law.stiffness_n_per_m_p * law.exponent
                     * (law.precompression_m if law.precompression_m > 0 else h) ** (law.exponent - 1)),
    "toda": LawRule(lambda law, v, L, E: (lw.TODA, [v["a_n"] / (E / L), v["b_per_m"] * L], None),
                    lambda law, h: law.a_n * law.b_per_m),
    "dipole": LawRule(_dipole, lambda law, h: law.exponent * (law.exponent + 1) * law.coefficient
                      / law.distance_m ** (law.exponent + 2)),
    "table": LawRule(_table, _table_stiffness),
}


def rest_stiffness(law, spacing_m: float) -> float:
    """A positive stiffness (N/m) characterising ``law`` near rest, for the time scale."""
    return LAWS[law.law].stiffness(law, spacing_m)


def law_rows(law, vals: dict[str, np.ndarray], sc: Scales, n: int) -> tuple[int, np.ndarray, np.ndarray | None]:
    """Kernel code, (n, N_LAW_PRM) rows and (for tables) the flat spline table of one law.

    ``vals`` maps each numeric field name of ``law`` to its (n,) per-element values (SI).
    """
    rows = np.zeros((n, lw.N_LAW_PRM))
    rows[:, 0] = -vals["offset_m"] / sc.length_m
    code, columns, tab = LAWS[law.law].columns(law, vals, sc.length_m, sc.energy)
    for k, c in enumerate(columns, start=1):
        rows[:, k] = c
    return code, rows, tab
