"""A shaker above the pass band of a linear chain (issue #32, item 6): the response is evanescent,
u_n ∝ (−e^{−κ})^n with cosh κ = mω²/(2k) − 1 (docs/physics.md §2), and ``flexmm analyze`` fits
that decay — down to the level of the transient the ramp leaves ringing in the undamped chain,
not into it (it reported 0.03 per site for a true 1.404) — and shows the linear theory."""

from __future__ import annotations

import math

import pytest

from flexmm.analysis.report.analyze import analyze_run
from flexmm.analysis.report.summary import summary_lines
from flexmm.api import run_scene
from flexmm.config import scene_from_dict

K, M = 1e4, 0.01
KAPPA = 1.404


def test_evanescent_decay_against_the_linear_theory(tmp_path):
    f_max = math.sqrt(K / M) / math.pi
    f = f_max * math.cosh(KAPPA / 2)  # above the band: κ = 2 arccosh(f / f_max)
    sc = scene_from_dict({"name": "evanescent", "lattice": {
        "kind": "mass_chain", "n_units": 80, "spacing_m": 0.01, "mass_kg": M, "left": "driven",
        "bond": {"law": "linear", "k_n_per_m": K}},
        "excitation": {"kind": "shaker", "end": "left", "frequency_hz": f, "amplitude_m": 1e-4, "ramp_cycles": 5},
        "solver": {"duration_s": 0.2}, "output": {"n_frames": 2001}})
    assert run_scene(sc, run_dir=tmp_path / "run", fidelity="full").status == "finished"
    res = analyze_run(tmp_path / "run")
    assert res.driven.decay_per_site == pytest.approx(KAPPA, rel=0.01)
    row = next(c for c in res.comparisons if c.quantity == "decay per site")
    assert row.predicted == pytest.approx(KAPPA, rel=1e-9) and abs(row.rel_diff) < 0.01
    assert "(theory 1.404" in summary_lines(res)[0]
