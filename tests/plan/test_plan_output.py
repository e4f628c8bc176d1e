"""What to save for a requested analysis (flexmm.plan.output)."""

from __future__ import annotations

import pytest

from flexmm.config import ConfigError, scene_from_dict
from flexmm.plan.output import AnalysisRequest, output_plan, parse_analysis

FIELDS = ("u", "theta")


def scene(output=None):
    data = {"name": "o", "lattice": {"kind": "rotating_squares_chain", "n_units": 20, "a_m": 0.016,
                                     "k_long_n_per_m": 1.0, "k_shear_n_per_m": 0.1, "k_rot_n_m_per_rad": 1e-6,
                                     "mass_kg": 1.0, "inertia_kg_m2": 1e-5},
            "solver": {"duration_s": 1.0}}
    if output is not None:
        data["output"] = output
    return scene_from_dict(data)


def test_parse():
    assert parse_analysis("pulse") == AnalysisRequest("pulse")
    assert parse_analysis("front:u") == AnalysisRequest("front", "u")
    assert parse_analysis("none") is None and parse_analysis(None) is None
    assert parse_analysis("pulse:velocity:u") == AnalysisRequest("pulse", "velocity:u")
    with pytest.raises(ConfigError) as exc:
        parse_analysis("spectrum")
    assert str(exc.value) == ("--analysis spectrum: kind: got 'spectrum' (str); expected: input should be "
                              "'pulse', 'front' or 'energy'")
    with pytest.raises(ConfigError, match=r"--analysis pulse:a b: field: got 'a b' \(str\); expected: a field name"):
        parse_analysis("pulse:a b")


def test_pulse_keeps_its_field_and_cadence():
    upd, notes = output_plan(scene(), AnalysisRequest("pulse"), FIELDS, passage_s=0.02, width_sites=20)
    assert upd["fields"] == ["theta"] and upd["velocities"] is False
    assert upd["n_frames"] == 501  # 10 frames per 0.02 s passage over 1 s
    assert upd["site_stride"] == 2
    assert "needs only" in notes[0]


def test_strain_needs_displacement_and_user_choices_stay():
    sc = scene({"fields": ["u", "theta"], "n_frames": 1000})
    upd, _ = output_plan(sc, AnalysisRequest("pulse", "strain"), FIELDS, passage_s=0.05)
    assert "fields" not in upd and "n_frames" not in upd and upd["velocities"] is False
    upd, _ = output_plan(scene(), AnalysisRequest("pulse", "velocity:u"), FIELDS)
    assert upd == {"fields": ["u"]}


def test_no_request_changes_nothing():
    upd, notes = output_plan(scene(), None, FIELDS)
    assert upd == {} and "as declared" in notes[0]
