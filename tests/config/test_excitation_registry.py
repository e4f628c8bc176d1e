"""The excitation registry (flexmm.config.excitation.EXCITATIONS): one example per kind, and the
config-only hooks the scene checks and the planner use, against values worked out by hand."""

from __future__ import annotations

import math

import pytest
from pydantic import TypeAdapter

from flexmm.config import ConfigError, scene_from_dict
from flexmm.config.excitation import EXCITATIONS, ExcitationConfig

IMPACT = {"kind": "impact", "velocity_m_s": -2.0}
SHAKER = {"kind": "shaker", "end": "right", "frequency_hz": 100.0, "amplitude_m": 1e-4}
PULSE = {"kind": "boundary_displacement", "amplitude_m": -1e-4, "duration_s": 1e-3}
FORCE_PULSE = {"kind": "boundary_force", "end": "right", "amplitude_n": -2.0, "duration_s": 1e-3}

#: kind -> (example, wave sources, imposed velocity (m/s), planar for a row-periodic sheet)
EXAMPLES = {
    "impact": (IMPACT, ["left"], 2.0, True),
    "shaker": (SHAKER, ["right"], 2 * math.pi * 100.0 * 1e-4, True),
    "boundary_displacement": (PULSE, ["left"], math.pi * 1e-4 / 1e-3, True),
    "boundary_force": (FORCE_PULSE, ["right"], 0.0, True),  # a force imposes no velocity
    "soliton": ({"kind": "soliton", "amplitude_rad": 0.3, "center_site": 7}, [7], 0.0, True),
    "solitons": ({"kind": "solitons", "pulses": [{"amplitude_rad": 0.3, "center_site": 7},
                                                 {"amplitude_rad": -0.3, "center_site": 30, "direction": -1}]},
                 [7, 30], 0.0, True),
    "kicks": ({"kind": "kicks", "kicks": [{"end": "right", "velocity_x_m_s": 1.0}, {"sites": [4, 9]}]},
              ["right", 4, 9], 0.0, False),
    "combined": ({"kind": "combined", "parts": [IMPACT, SHAKER]}, None, 0.0, False),
    "none": ({"kind": "none"}, [], 0.0, True),
}


def _exc(data: dict):
    return TypeAdapter(ExcitationConfig).validate_python(data)


def test_every_registered_kind_has_an_example() -> None:
    assert set(EXAMPLES) == set(EXCITATIONS)


@pytest.mark.parametrize("kind", sorted(EXAMPLES))
def test_hooks_of_each_kind(kind: str) -> None:
    data, sources, velocity, planar = EXAMPLES[kind]
    exc = _exc(data)
    assert type(exc) is EXCITATIONS[kind].config
    assert exc.sources() == sources
    assert exc.imposed_velocity_m_s() == pytest.approx(velocity, rel=1e-15)
    assert (exc.planar_issue() is None) == planar


def test_end_hooks_follow_the_end_and_sites() -> None:
    assert _exc({**IMPACT, "end": "top"}).sources() is None  # not an end along x: anywhere
    assert _exc({**IMPACT, "end": "top", "sites": [3]}).sources() is None
    assert _exc({**IMPACT, "sites": [3]}).sources() == [3]
    assert "single units" in _exc({**IMPACT, "sites": [3]}).planar_issue()
    assert "not a wave along x" in _exc({**SHAKER, "end": "bottom"}).planar_issue()
    assert _exc({**SHAKER, "amplitude_m": None, "amplitude_n": 1.0}).imposed_velocity_m_s() == 0.0
    kicks = _exc({"kind": "kicks", "kicks": [{"end": "bottom", "velocity_y_m_s": 1.0}]})
    assert kicks.sources() == ["bottom"] and kicks.planar_issue() is not None
    combined = _exc(EXAMPLES["combined"][0])
    assert [p.kind for p in combined.components()] == ["impact", "shaker"]
    assert [t.end for t in combined.targets()] == ["left", "right"]


def test_combined_accepts_only_combinable_kinds() -> None:
    allowed = {k for k, spec in EXCITATIONS.items() if spec.combinable}
    assert allowed == {"impact", "shaker", "boundary_displacement", "boundary_force", "kicks"}
    with pytest.raises(ValueError):
        _exc({"kind": "combined", "parts": [IMPACT, EXAMPLES["soliton"][0]]})


def _scene(excitation: dict, **lattice) -> dict:
    lat = {"kind": "mass_chain", "n_units": 40, "spacing_m": 0.01, "mass_kg": 0.01,
           "bond": {"law": "linear", "k_n_per_m": 100.0}, **lattice}
    return {"name": "t", "lattice": lat, "excitation": excitation, "solver": {"duration_s": 0.01}}


def test_a_driven_end_needs_an_end_excitation_on_it() -> None:
    scene_from_dict(_scene({"kind": "combined", "parts": [IMPACT, SHAKER]}, right="driven"))
    with pytest.raises(ConfigError, match="no impact, shaker, boundary_displacement or boundary_force acts on the right"):
        scene_from_dict(_scene(IMPACT, right="driven"))
    with pytest.raises(ConfigError, match="outside 0..39"):
        scene_from_dict(_scene(EXAMPLES["solitons"][0] | {"pulses": [{"amplitude_rad": 0.1, "center_site": 40}]}))
    with pytest.raises(ConfigError, match="fixed"):
        scene_from_dict(_scene({"kind": "kicks", "kicks": [{"end": "left", "velocity_x_m_s": 1.0}]}, left="fixed"))
