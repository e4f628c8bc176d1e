"""analyze's theory for rigid networks (analysis.predict.network, docs/physics.md §1.9): pulse speeds
against the long-wave Bloch speed of each medium, and the amplitudes an interface transmits and
reflects against the impedances, on a run at θ0 = 0.2 launched with the displacement alone."""

import math

import pytest

from flexmm.analysis import analyze_run
from flexmm.api import run_scene
from flexmm.config import scene_from_dict

A, PITCH = 0.016, 0.016 * math.cos(0.2)
X0, W = 60 * PITCH, 10 * PITCH
PULSE = f"1e-4 * exp(-((i * {PITCH} - {X0}) / {W})**2)"  # x = i · a_m on networks: the column's position


def scene():
    law = {"k_long_n_per_m": 71690, "k_shear_n_per_m": 14338, "k_rot_n_m_per_rad": 7.038e-4}
    return scene_from_dict({
        "name": "interface_theta", "excitation": {"kind": "none"}, "damping": {},
        "solver": {"duration_s": 0.05}, "output": {"n_frames": 161},
        "lattice": {"kind": "rigid_network", "n_rows": 2, "n_cols": 300, "a_m": A, "theta0_rad": 0.2, **law,
                    "areal_density_kg_m2": 35.3, "bottom": "periodic", "top": "periodic",
                    "unit_sets": {"stiff": {"box_m": [149.5 * PITCH, -1.0, 10.0, 1.0]}},
                    "regions": [{"units": "stiff", **{k: 4 * v for k, v in law.items()}}]},
        # u alone, right-going at the lattice's long-wave speed (44.25 m/s): not the acoustic mode
        "initial": {"fields": [{"field": "u", "value": PULSE, "rate": f"-44.2524 * -2 * (i * {PITCH} - {X0}) / {W}**2 * {PULSE}"}]},
    })


def test_an_interface_at_theta0_is_predicted_from_the_launch_s_acoustic_pulse(tmp_path):
    """Measured: the incident pulse 9.910e-5 m at 45.05 m/s (fitted on into the stiff side),
    transmitted 6.640e-5 m at 88.52 m/s, reflected −3.247e-5 m at 44.34 m/s; predicted 9.898e-5,
    6.598e-5 (2/3 of the forward acoustic pulse), −3.299e-5 (−1/3), speeds 44.25 and 88.50 m/s."""
    run_scene(scene(), run_dir=tmp_path / "run")
    res = analyze_run(tmp_path / "run", field_spec="u")
    rows = {(c.item, c.quantity): c for c in res.comparisons if c.predicted is not None}
    notes = {item: rows[(item, "amplitude")].note.split(":")[0] for item, q in rows if q == "amplitude"}
    assert sorted(notes.values()) == ["incident of the launch's forward acoustic pulse (docs/physics.md §1.9)",
                                      "reflected", "transmitted"]
    for item, what in notes.items():
        speed, amplitude = rows[(item, "speed")], rows[(item, "amplitude")]
        # the incident pulse's speed fit runs on across the interface, where it speeds up
        assert abs(speed.rel_diff) < (2.5e-2 if what.startswith("incident") else 6e-3)
        assert abs(amplitude.rel_diff) < {"reflected": 2.5e-2}.get(what, 1e-2)
    transmitted = next(item for item, what in notes.items() if what == "transmitted")
    assert rows[(transmitted, "speed")].predicted == pytest.approx(2 * 44.2524, rel=1e-4)  # √4 × the lattice's


def test_no_bulk_prediction_for_a_sheet_with_free_rows():
    """A sheet with free top and bottom rows carries a strip's waves, not the bulk medium's: no
    speed row (the theory declines with a reason, which analyze turns into no prediction)."""
    from types import SimpleNamespace

    from flexmm.analysis.context import RunContext
    from flexmm.analysis.predict.network import pulse
    from flexmm.analysis.report.theory_comparison import _safe

    config = {"name": "t", "solver": {"duration_s": 1e-3}, "excitation": {"kind": "impact", "end": "left",
                                                                          "velocity_m_s": 1.0},
              "lattice": {"kind": "rigid_network", "n_rows": 4, "n_cols": 10, "a_m": A, "k_long_n_per_m": 1e4,
                          "k_shear_n_per_m": 3e3, "k_rot_n_m_per_rad": 2e-3, "areal_density_kg_m2": 20.0}}
    ctx = RunContext(model="rigid_network", config=config)
    with pytest.raises(ValueError, match="periodic across its rows"):
        pulse(ctx, SimpleNamespace(field="u"))
    assert _safe(pulse, ctx, SimpleNamespace(field="u")) == []
    periodic = dict(config, lattice=dict(config["lattice"], bottom="periodic", top="periodic"))
    rows = pulse(RunContext(model="rigid_network", config=periodic),
                 SimpleNamespace(field="u", sites=[3, 4, 5], speed_m_s=30.0))
    assert [r.quantity for r in rows] == ["speed"] and rows[0].predicted == pytest.approx(31.6228, rel=1e-4)
