"""Formation transients (analysis.measure.transients): a lobe that forms and dies out, or turns into the
steady pulse, is reported with its formation distance and time and never compared with theory."""

from __future__ import annotations

import json

import pytest
from conftest import DEMO_AS_LEGO_SCENE_SETS

from flexmm.analysis import field_view, measure_pulses
from flexmm.analysis.report.analyze import analyze_run
from flexmm.analysis.report.summary import principal, summary_lines
from synthetic import SynthPulse, pulse_dataset
from flexmm.analysis.measure.transients import mark_transients

END_S = 30.0  # the lobe fades out around this time, and the steady pulse fades in


def _impact_like(lobe_sign: int = 1, *, noise: float = 0.002, seed: int = 0):
    """A lobe (0.35, positive unless told) from x = 10 that dies out at t = END_S, handing over to a
    steady pulse (−0.5) that appears where it died and runs to the end of the chain at speed 1."""
    lobe = SynthPulse(0.35 * lobe_sign, 1.0, 3.0, 10.0, ends_s=END_S, fade_s=1.5)
    steady = SynthPulse(-0.5, 1.0, 3.0, 10.0, starts_s=END_S, fade_s=1.5)
    return pulse_dataset([lobe, steady], n_sites=200, duration_s=180.0, n_frames=721, noise=noise, seed=seed)


def _mark(ds):
    view = field_view(ds, "theta")
    pulses = measure_pulses(view)
    return mark_transients(pulses, [], view.spacing_m, float(view.time[-1]), (float(view.x.min()), float(view.x.max())))


def test_lobe_that_dies_is_a_transient_with_its_distance_and_time():
    pulses = _mark(_impact_like(1))
    lobes = [p for p in pulses if p.transient]
    steady = [p for p in pulses if not p.transient]
    assert len(lobes) == 1 and len(steady) == 1
    (lobe,), (main,) = lobes, steady
    assert lobe.amplitude == pytest.approx(0.35, rel=0.02) and main.amplitude == pytest.approx(-0.5, rel=0.02)
    # the lobe lives from t = 0 to about END_S at speed 1: it travels about END_S sites (its peak is
    # tracked while above a quarter of the largest peak, within the fade of 1.5 s at each end)
    assert lobe.formation_time_s == pytest.approx(END_S, abs=4.0)
    assert lobe.formation_distance_m == pytest.approx(lobe.formation_time_s, rel=0.05, abs=1.0)
    assert lobe.continues_as == main.index  # it turns into the steady pulse
    assert main.continues_as == -1 and main.speed_m_s == pytest.approx(1.0, rel=0.01)


def test_lobe_of_the_same_sign_is_the_formation_of_the_steady_pulse():
    """The same hand-over with a lobe of the steady pulse's sign is one track: one pulse, steady
    after the lobe's life (formation distance ≈ END_S + the fade), measured at its steady amplitude."""
    (p,) = _mark(_impact_like(-1))
    assert not p.transient and p.amplitude == pytest.approx(-0.5, rel=0.02)
    assert p.formation_distance_m == pytest.approx(END_S, abs=6.0)


def test_a_pulse_that_lives_to_the_end_is_not_a_transient():
    ds = pulse_dataset([SynthPulse(0.5, 1.0, 3.0, 20.0), SynthPulse(-0.3, -1.5, 3.0, 190.0)], noise=0.002)
    assert not any(p.transient for p in _mark(ds))


def test_a_pulse_that_runs_far_and_then_fades_is_not_a_transient():
    """Fading after 110 sites (14 FWHM, more than SHORT_FWHM): a decaying pulse, not a formation lobe."""
    ds = pulse_dataset([SynthPulse(0.5, 1.0, 3.0, 10.0, ends_s=110.0, fade_s=1.5)], n_sites=200,
                       duration_s=180.0, n_frames=721, noise=0.002)
    (p,) = _mark(ds)
    assert not p.transient and p.continues_as == -1 and p.speed_m_s == pytest.approx(1.0, rel=0.01)


def test_transient_is_neither_compared_nor_the_headline(tmp_path):
    """analyze: the transient gets formation rows without a prediction, the JSON flags it, and the
    headline is the steady pulse with one line for the transient."""
    from typer.testing import CliRunner

    from flexmm.cli import app

    (tmp_path / "run").mkdir()
    _impact_like().to_netcdf(tmp_path / "run" / "dataset.nc", engine="h5netcdf")
    res = analyze_run(tmp_path / "run")
    (lobe,) = [p for p in res.pulses if p.transient]
    rows = [c for c in res.comparisons if c.item == f"pulse {lobe.index}"]
    assert {c.quantity for c in rows} >= {"formation distance", "formation time"}
    assert all(c.predicted is None and "formation transient" in c.note for c in rows)
    label, head = principal(res)
    assert not head.transient and label == f"pulse {head.index}"
    lines = summary_lines(res)
    assert lines[0].startswith(f"pulse {head.index} of 2")
    assert any(f"formation transient pulse {lobe.index}" in ln and f"turns into pulse {head.index}" in ln
               for ln in lines)
    out = CliRunner().invoke(app, ["analyze", str(tmp_path / "run"), "--json", str(tmp_path / "a.json")])
    assert out.exit_code == 0, out.output
    pulses = json.loads((tmp_path / "a.json").read_text())["runs"][0]["pulses"]
    assert [p["transient"] for p in pulses] == [p.transient for p in res.pulses]
    assert pulses[lobe.index]["continues_as"] == head.index


def test_impact_lobe_on_the_lego_chain_is_a_transient(tmp_path):
    """The LEGO impact (configs/lego_vector_soliton.yaml on a 200-unit chain with a free far end, first
    0.4 s): the off-centre hit first makes a positive-rotation lobe that dies out within ~40 units,
    where the negative-rotation soliton takes over. The lobe is a transient (formation distance and time, no theory row with a
    prediction); the headline is the soliton."""
    from typer.testing import CliRunner

    from flexmm.cli import app

    free_end = [arg for s in DEMO_AS_LEGO_SCENE_SETS for arg in ("--set", s)]
    out = CliRunner().invoke(app, ["run", "configs/lego_vector_soliton.yaml", "-o", str(tmp_path), "-q", *free_end,
                                   "--set", "solver.duration_s=0.4", "--set", "output.n_frames=401"])
    assert out.exit_code == 0, out.output
    res = analyze_run(tmp_path)
    first = min(res.pulses, key=lambda p: p.track_time_s[0])
    h = res.view.spacing_m
    assert first.transient and first.polarity == 1
    assert 10 * h < first.formation_distance_m < 45 * h and 0.05 < first.formation_time_s < 0.12
    rows = [c for c in res.comparisons if c.item == f"pulse {first.index}"]
    assert rows and all(c.predicted is None for c in rows)
    _, head = principal(res)
    assert not head.transient and head.polarity == -1 and head.direction == 1
    assert any(c.item == f"pulse {head.index}" and c.quantity == "speed" and c.predicted is not None
               for c in res.comparisons)
    assert any(f"formation transient pulse {first.index}" in ln for ln in summary_lines(res))
