"""``flexmm run`` prints analyze's measurement of what the scene is about (one measurement path).

The printed line must be the feature ``flexmm analyze`` picks (``analysis.report.summary.principal``),
measured on the same field: strain for chains of masses, not the displacement u; the soliton,
not a small precursor; a front for a multistable chain. No scipy warning may leak.
"""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from flexmm.analysis import field_view, measure_pulses
from flexmm.analysis.report import analyze as report
from flexmm.analysis.context import RunContext
from flexmm.analysis.report.summary import principal, summary_lines
from synthetic import SynthPulse, pulse_dataset
from flexmm.cli import app

CONFIGS = Path(__file__).resolve().parents[2] / "configs"
TODA = {"name": "toda_impact",
        "lattice": {"kind": "mass_chain", "n_units": 150, "spacing_m": 0.01, "mass_kg": 0.01,
                    "bond": {"law": "toda", "a_n": 1.0, "b_per_m": 100.0}},
        "excitation": {"kind": "impact", "velocity_m_s": 0.5}, "solver": {"duration_s": 1.0}}


def _run(tmp_path: Path, cfg: dict, name: str) -> tuple[str, Path]:
    f = tmp_path / f"{name}.yaml"
    f.write_text(yaml.safe_dump(cfg))
    out = tmp_path / name
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        r = CliRunner().invoke(app, ["run", str(f), "--out", str(out)])
    assert r.exit_code == 0, r.output
    leaked = [str(w.message) for w in caught if "peaks have" in str(w.message)]
    assert not leaked, leaked
    assert "peaks have" not in r.output
    return r.output, out


def _speed(line: str) -> float:
    return float(re.search(r"speed ([0-9.eE+-]+) ±", line).group(1))


def test_toda_impact_summary_is_the_strain_soliton_of_analyze(tmp_path):
    text, out = _run(tmp_path, TODA, "toda")
    line = next(ln for ln in text.splitlines() if ln.startswith("pulse"))
    assert " in strain " in line and "compressive" in line  # not the displacement u
    res = report.analyze_run(out)
    item, p = principal(res)
    assert line == summary_lines(res)[0]
    assert _speed(line) == pytest.approx(p.speed_m_s, rel=1e-4)
    speed = next(c for c in res.comparisons if c.item == item and c.quantity == "speed")
    # the impact leaves a Toda soliton: its speed at the measured strain peak (docs/physics.md §2)
    assert speed.rel_diff is not None and abs(speed.rel_diff) < 0.015


def test_raney_transition_wave_summary_is_the_front_speed(tmp_path):
    cfg = yaml.safe_load((CONFIGS / "h_raney_transition_wave.yaml").read_text())
    cfg["solver"]["duration_s"] = 2.0
    cfg["output"]["n_frames"] = 201
    text, out = _run(tmp_path, cfg, "raney")
    line = next(ln for ln in text.splitlines() if ln.startswith("front"))
    assert " in u " in line and "moving)" in line
    # docs/scenes.md: 1.4502 m/s, steady along the chain
    assert _speed(line) == pytest.approx(1.4502, abs=2e-4)


def test_principal_pulse_is_the_largest_not_the_first():
    """A small fast precursor ahead of a large slow pulse: the large one is the headline."""
    ds = pulse_dataset([SynthPulse(0.15, 3.0, 2.0, 40.0), SynthPulse(0.4, 1.0, 4.0, 10.0)],
                       n_sites=400, duration_s=100.0, n_frames=401)
    view = field_view(ds, "theta")
    res = report.RunAnalysis(Path("synthetic"), "pulse", RunContext("synthetic", {}, ds), view,
                             pulses=measure_pulses(view))
    assert len(res.pulses) == 2
    _, p = principal(res)
    assert p.amplitude == pytest.approx(0.4, rel=0.02) and p.speed_m_s == pytest.approx(1.0, rel=5e-3)
    assert np.isfinite(p.width_sech_m)
