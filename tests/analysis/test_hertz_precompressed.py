"""A precompressed Hertz chain is compared with the precompressed solitary-wave law, not the sonic vacuum.

The chain is held by a static load F0 on its free ends (overlap δ0 = (F0/A)^(2/3) at rest) and
struck by a bead. On the old code its pulse was compared with the uncompressed law
V = (2/√5) c ξm^(1/4) at the dynamic strain alone (here 465 m/s against a measured 598 m/s).
"""

from __future__ import annotations

import math

import pytest

from flexmm.config import scene_from_dict
from flexmm.theory.chains import nesterenko_precompressed_speed, nesterenko_speed

A, D, M, F0 = 4.88e9, 0.00476, 4.5e-4, 2.0  # steel beads (configs/hertz_granular_impact.yaml), 2 N


def scene(**lattice) -> dict:
    return {"name": "hertz_precompressed",
            "lattice": {"kind": "mass_chain", "n_units": 120, "spacing_m": D, "mass_kg": M,
                        "bond": {"law": "hertz", "stiffness_n_per_m_p": A, "exponent": 1.5},
                        "static_load_n": F0, **lattice},
            "excitation": {"kind": "impact", "end": "left", "velocity_m_s": 0.3,
                           "striker": {"mass_kg": M, "contact_stiffness_n_per_m": A, "exponent": 1.5}},
            "solver": {"duration_s": 6e-4}, "output": {"n_frames": 241}}


def law(xi0: float, xim: float) -> float:
    """Nesterenko's precompressed law in its textbook form, with the sound speed c0 of the compressed chain."""
    c0 = math.sqrt(1.5 * A * D**2.5 / M * math.sqrt(xi0))
    r = xim / xi0
    return c0 / (r - 1) * math.sqrt(4 / 15 * (3 + 2 * r**2.5 - 5 * r))


def test_the_precompressed_law_meets_its_limits() -> None:
    c2 = A * D**2.5 / M
    xi0 = 1e-4
    # weak wave: the sound speed of the compressed chain; strong wave: the sonic-vacuum law
    assert nesterenko_precompressed_speed(A, M, D, xi0, xi0 * (1 + 1e-6)) == pytest.approx(
        math.sqrt(1.5 * c2 * math.sqrt(xi0)), rel=1e-6)
    assert nesterenko_precompressed_speed(A, M, D, 1e-12, 1e-4) == pytest.approx(nesterenko_speed(A, M, D, 1e-4),
                                                                                 rel=1e-5)
    for r in (1.0005, 1.01, 3.0, 30.0):  # both branches of the implementation agree with the textbook form
        assert nesterenko_precompressed_speed(A, M, D, xi0, r * xi0) == pytest.approx(law(xi0, r * xi0), rel=2e-6)


def test_a_precompressed_chain_is_compared_with_the_precompressed_law(tmp_path) -> None:
    from flexmm.analysis.report.analyze import analyze_run
    from flexmm.api import run_scene

    res = run_scene(scene_from_dict(scene()), run_dir=tmp_path / "r", fidelity="auto")
    assert res.ok, res.reason
    out = analyze_run(res.path, kind="pulse")
    row = next(c for c in out.comparisons if c.item == "pulse 0" and c.quantity == "speed")
    lead = out.pulses[0]
    xi0 = (F0 / A) ** (2 / 3) / D  # the static load's overlap, from the contact law
    xim = xi0 - lead.amplitude  # the pulse's strain is measured from the rest state
    assert xim / xi0 > 2  # a solitary wave well above the sound of the compressed chain
    assert row.predicted == pytest.approx(law(xi0, xim), rel=2e-3)  # δ0 read from the run's rest state
    assert abs(row.rel_diff) < 0.01  # measured 597.7 m/s against 596.4 m/s
    assert nesterenko_speed(A, M, D, -lead.amplitude) < 0.8 * row.measured  # the sonic vacuum's law is far off


def test_no_theory_without_a_law_for_the_chain(tmp_path) -> None:
    # a precompressed contact of exponent 2 has no solitary-wave law here: no prediction is printed
    from flexmm.analysis.report.analyze import analyze_run
    from flexmm.api import run_scene

    sc = scene(bond={"law": "hertz", "stiffness_n_per_m_p": A * 1e3, "exponent": 2.0})
    res = run_scene(scene_from_dict(sc), run_dir=tmp_path / "r", fidelity="auto")
    assert res.ok, res.reason
    rows = [c for c in analyze_run(res.path, kind="pulse").comparisons if c.quantity == "speed"]
    assert rows and all(c.predicted is None for c in rows)
