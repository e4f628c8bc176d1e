"""``flexmm bench`` measures what a run reports (issue 32, item 10): the work–precision chart is the
error of the wave amplitudes and speeds (``accuracy.quantity_error``, as the run's error estimate),
not of the final state, and a scene is refused only when even those are chaotic (a looser reference
reports other amplitudes and speeds)."""

from __future__ import annotations

import pytest
import yaml
from typer.testing import CliRunner

from flexmm.assemble import build_problem
from flexmm.cli import app
from flexmm.config import scene_from_dict
from flexmm.diagnostics import workprecision as wp


def ring(k3: float) -> dict:
    """16 masses on a ring, 3 mm of frozen noise: linear (k3 = 0) or a strongly nonlinear FPU-β ring."""
    return {"name": "ring", "solver": {"duration_s": 1.0}, "output": {"n_frames": 11},
            "lattice": {"kind": "mass_chain", "n_units": 16, "spacing_m": 0.01, "mass_kg": 0.01,
                        "left": "periodic", "right": "periodic",
                        "bond": {"law": "polynomial", "k1_n_per_m": 100.0, "k3_n_per_m3": k3}},
            "initial": {"fields": [{"field": "u", "value": "3e-3 * normal(1)"}]}}


def test_a_regular_scene_has_a_reference_that_a_looser_one_reproduces():
    pb = build_problem(scene_from_dict(ring(0.0)))
    spread, final, _ = wp.reference_spread(pb, wp.reference(pb, 11), 11)
    assert spread < 1e-6 and final < 1e-6  # measured 2e-9 of the field


def test_the_chart_is_the_error_of_the_reported_quantities():
    """Each row's ``quantity_error`` is ``accuracy.quantity_error`` of its frames against the
    reference's (the quantities the run's estimate covers), and it falls at the method's order."""
    from flexmm.accuracy import frames_trace, quantity_error

    pb = build_problem(scene_from_dict(ring(0.0)))
    ref = wp.reference(pb, 11)
    rows = wp.run_flexmm(pb, ref, "velocity_verlet", repeats=1)
    assert len(rows) >= 3 and all(r.quantity_error > 0 for r in rows)
    dt = ref.t[1] - ref.t[0]
    from flexmm.integrators.runner import integrate

    name, value, kw = wp.ladder("velocity_verlet", pb)[0]
    tr = integrate(pb, "velocity_verlet", n_frames=11, **kw)
    direct = quantity_error(frames_trace(pb.system, tr.q, dt), frames_trace(pb.system, ref.q, dt)).total
    assert rows[0].quantity_error == direct
    (a, b) = rows[2], rows[3]  # fractions 0.4 and 0.25 of the stable step: error ∝ h²
    assert a.quantity_error / b.quantity_error == pytest.approx((a.value / b.value) ** 2, rel=0.3)


def test_bench_refuses_a_chaotic_scene_unless_forced(tmp_path):
    f = tmp_path / "chaos.yaml"
    f.write_text(yaml.safe_dump(ring(1e8), sort_keys=False))
    r = CliRunner().invoke(app, ["bench", str(f), "--methods", "velocity_verlet", "--ivp", "", "--repeats", "1",
                                 "--out", str(tmp_path / "b")])
    assert r.exit_code == 2, r.output
    assert "chaotic" in r.output and "--force" in r.output and "Traceback" not in r.output
    assert not (tmp_path / "b" / "workprecision.csv").exists()
