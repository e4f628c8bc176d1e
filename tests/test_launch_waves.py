"""Launched waves with their theory (docs/physics.md §2): the FPU-β (mKdV) sech solitary wave and
the sine-Gordon kink; expected values from the closed-form laws written out here."""

from __future__ import annotations

import math

import pytest
import yaml

from flexmm.analysis import report
from flexmm.api import run_scene
from flexmm.config import ConfigError, load_scene, scene_from_dict

FPU = {"kind": "mass_chain", "n_units": 300, "spacing_m": 0.01, "mass_kg": 0.01,
       "bond": {"law": "polynomial", "k1_n_per_m": 100.0, "k3_n_per_m3": 4.0e6}}


@pytest.mark.parametrize("strain, direction", [(0.05, 1), (-0.05, -1)])
def test_launched_fpu_beta_pulse_runs_at_the_mkdv_speed_with_its_width(tmp_path, strain, direction):
    """D = Dm sech(n/W), W = sqrt(k1/(6 k3))/|Dm| = 4.08 sites, v = c0 sqrt(1 + k3 Dm²/(2 k1)):
    v − c0 (0.25 % of c0) within 6 % (the discrete wave differs at O(1/W²) = 0.06), W within 1 %,
    either polarity, and the analysis row."""
    k1, k3, a, m = 100.0, 4.0e6, 0.01, 0.01
    sc = scene_from_dict({
        "name": "fpu", "solver": {"duration_s": 1.5}, "lattice": FPU,
        "initial": {"launch": [{"kind": "fpu_beta_pulse", "strain": strain, "direction": direction,
                                "center_site": 40 if direction > 0 else 259}]}})
    res = report.analyze_run(run_scene(sc, run_dir=tmp_path / "fpu").path)
    (p,) = res.pulses
    c0, Dm = a * math.sqrt(k1 / m), strain * a
    v = c0 * math.sqrt(1 + k3 * Dm**2 / (2 * k1))
    assert p.direction == direction and p.amplitude == pytest.approx(strain, rel=0.01)
    assert (abs(p.speed_m_s) - c0) / (v - c0) == pytest.approx(1.0, abs=0.06)
    assert p.width_sech_m == pytest.approx(math.sqrt(k1 / (6 * k3)) / abs(Dm) * a, rel=0.01)
    (row,) = [r for r in res.comparisons if r.quantity == "speed"]
    assert "FPU-β" in row.note and abs(row.rel_diff) < 1e-4


def test_fpu_beta_launch_on_a_bond_with_k2_is_an_error(tmp_path):
    f = tmp_path / "k2.yaml"
    f.write_text(yaml.safe_dump({
        "name": "k2", "solver": {"duration_s": 0.1},
        "lattice": {**FPU, "bond": {**FPU["bond"], "k2_n_per_m2": 10.0}},
        "initial": {"launch": [{"kind": "fpu_beta_pulse", "strain": 0.05, "center_site": 40}]}}, sort_keys=False))
    sc = load_scene(f)
    with pytest.raises(Exception, match="k2 = 0"):
        run_scene(sc, run_dir=tmp_path / "k2")
