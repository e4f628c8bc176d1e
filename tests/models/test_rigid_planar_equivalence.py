"""A planar vector soliton in the 2D sheet equals the chain with n_v = 2, s_v = 1 (docs/physics.md §1.2).

Both are launched with the same exact chain soliton and integrated with the same step; speed and
amplitude must agree within 1 %. The sheet keeps its transverse displacement v free: the shear
springs of the horizontal hinges push the units up and down in a checkerboard pattern, which the
chain model leaves out. That effect grows with K_s (≈ 2 % in speed and 15 % in amplitude at K_s = 1),
so the comparison uses a small K_s (0.04) with a light rotational inertia (α² = 0.01), for which
the planar soliton exists (K_s > 2α² + 4K_θ) and is ≈ 3 units wide.
"""

import numpy as np
import pytest

from flexmm.assemble import build_problem
from flexmm.config import scene_from_dict
from flexmm.controller import run_problem
from flexmm.io.run_dataset import open_run
from flexmm.theory.rotating import RotatingChainND, soliton_speed

A_M, KL, M = 0.01, 1e4, 1e-3
KS, KT, ALPHA2 = 0.04, 7e-5, 0.01
AMPLITUDE, N_COLS, DURATION = 0.3, 220, 200.0  # rad, units, time units sqrt(m/k_l)
T = (M / KL) ** 0.5


def run(lattice: dict, path) -> tuple[np.ndarray, np.ndarray]:
    scene = scene_from_dict({
        "name": lattice["kind"], "lattice": lattice,
        "excitation": {"kind": "soliton", "amplitude_rad": AMPLITUDE, "center_site": 30},
        "solver": {"duration_s": DURATION * T, "dt_s": 0.02 * T}, "output": {"n_frames": 201}})
    result = run_problem(build_problem(scene), path)
    ds = open_run(result.path)
    return ds["time"].values / T, ds["theta"].values[:, :N_COLS]


def peak_track(time, theta):
    """Sub-site peak position (parabola through the sampled maximum) and height per frame."""
    pos, amp = [], []
    for row in np.abs(theta):
        k = int(np.clip(np.argmax(row), 1, row.size - 2))
        a, b, c = row[k - 1 : k + 2]
        off = 0.5 * (a - c) / (a - 2 * b + c)
        pos.append(k + off)
        amp.append(b - 0.25 * (a - c) * off)
    sel = (time > 0.25 * DURATION) & (time < 0.95 * DURATION)
    return np.polyfit(time[sel], np.asarray(pos)[sel], 1)[0], float(np.mean(np.asarray(amp)[sel]))


def test_planar_sheet_soliton_equals_chain_nv2_sv1(tmp_path):
    common = {"a_m": A_M, "theta0_rad": 0.0, "k_long_n_per_m": KL, "k_shear_n_per_m": KS * KL,
              "k_rot_n_m_per_rad": KT * KL * A_M**2, "mass_kg": M, "inertia_kg_m2": ALPHA2 * M * A_M**2}
    chain = run({"kind": "rotating_squares_chain", "n_units": N_COLS, "n_lateral": 2, "lateral_stretch": True,
                 **common}, tmp_path / "chain")
    sheet = run({"kind": "rotating_squares_sheet", "n_rows": 2, "n_cols": N_COLS, "bottom": "periodic",
                 "top": "periodic", **common}, tmp_path / "sheet")
    c_chain, a_chain = peak_track(*chain)
    c_sheet, a_sheet = peak_track(*sheet)
    assert c_sheet == pytest.approx(c_chain, rel=0.01)
    assert a_sheet == pytest.approx(a_chain, rel=0.01)
    # and both carry the launched soliton: speed law of docs/physics.md §1.3 (sites per time unit)
    theory = float(soliton_speed(RotatingChainND(0.0, KS, KT, ALPHA2, 2, 1), AMPLITUDE))
    assert c_chain == pytest.approx(theory, rel=0.01)
    assert a_chain == pytest.approx(AMPLITUDE, rel=0.02)
