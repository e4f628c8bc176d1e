"""Ten scenes for the ``solver.accuracy`` acceptance check (tests/plan/test_plan_acceptance.py; not a test module itself).

Each is (name, scene dict, requested accuracy); paths are relative to the repository root.
"""

from __future__ import annotations

from pathlib import Path

from conftest import LEGO_PARAMETERS

from flexmm.config.loader import read_yaml

ROOT = Path(__file__).resolve().parents[2]
LEGO = dict(kind="rotating_squares_chain", **LEGO_PARAMETERS)


def _config(name: str, **solver) -> dict:
    data, _ = read_yaml(ROOT / "configs" / name)
    data["solver"] = {k: v for k, v in {**data["solver"], **solver}.items() if k not in ("dt_fraction", "dt_s")}
    data.pop("output", None)
    return data


def scenes() -> list[tuple[str, dict, float]]:
    soliton = {"name": "lego_soliton", "lattice": {**LEGO, "n_units": 300, "n_lateral": 1},
               "excitation": {"kind": "soliton", "amplitude_rad": 0.4, "center_site": 60},
               "solver": {"duration_s": 0.3}}
    gauss = {"name": "theta0_gaussian", "lattice": {**LEGO, "n_units": 200, "theta0_rad": 0.3, "n_lateral": 2,
                                                    "lateral_stretch": True, "left": "driven"},
             "excitation": {"kind": "boundary_displacement", "shape": "gaussian", "amplitude_m": 1e-3,
                            "duration_s": 2e-3},
             "solver": {"duration_s": 0.05}}
    shaker = {"name": "damped_shaker", "lattice": {**LEGO, "n_units": 150, "left": "driven"},
              "excitation": {"kind": "shaker", "frequency_hz": 200.0, "amplitude_m": 5e-4, "ramp_cycles": 2},
              "damping": {"viscous": {"damping_ratio": 0.02}}, "solver": {"duration_s": 0.1}}
    toda = {"name": "toda_impact", "lattice": {"kind": "mass_chain", "n_units": 150, "spacing_m": 0.01,
                                               "mass_kg": 0.01, "bond": {"law": "toda", "a_n": 1.0, "b_per_m": 100.0}},
            "excitation": {"kind": "impact", "velocity_m_s": 0.5}, "solver": {"duration_s": 1.0}}
    strip = _config("planar_sheet_impact.yaml", duration_s=0.02)
    strip["lattice"].update(n_rows=2, n_cols=150)
    lego = _config("lego_vector_soliton.yaml", duration_s=0.1)
    return [
        ("LEGO launched soliton", soliton, 1e-4),
        ("LEGO launched soliton", soliton, 1e-6),
        ("LEGO impact, first 0.1 s", lego, 1e-4),
        ("θ0 = 0.3 chain, gaussian pulse", gauss, 1e-5),
        ("damped chain, shaker", shaker, 1e-5),
        ("buckled beams rarefaction", _config("c_buckled_beams_rarefaction.yaml", duration_s=0.2), 1e-5),
        ("Raney transition wave", _config("h_raney_transition_wave.yaml", duration_s=2.0), 1e-4),
        ("origami half-sine push", _config("d_origami_rarefaction_overtakes.yaml", duration_s=0.5), 1e-4),
        ("Toda chain impact", toda, 1e-6),
        ("planar sheet strip impact", strip, 1e-4),
    ]
