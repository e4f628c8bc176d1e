"""One plan, shown everywhere: every verb prints the plan of ``prepare.resolve`` (issue 36).

``validate``, ``plan``, ``run``, ``compare``, ``bench`` and ``stability`` print the same ``plan:``
lines — lattice and domain, method, step, stable limit, frame times, cost — for every shipped
scene. The verbs that integrate are stopped where their integration starts (their plan lines are
printed before it), and the accuracy pilots are replaced by a quick deterministic choice
(``quick_pilots``), so the test plans and never integrates; ``test_lego_validate_plan_run_agree``
runs the real pilots on the scene of the issue's example.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from flexmm.cli import app

CONFIGS = sorted((Path(__file__).resolve().parents[2] / "configs").glob("*.yaml"))
LEGO = Path(__file__).resolve().parents[2] / "configs" / "lego_vector_soliton.yaml"


class Stop(Exception):
    """Raised where a verb would start integrating: its plan has been printed."""


def _stop(*args, **kwargs):
    raise Stop


@pytest.fixture
def quick_pilots(monkeypatch):
    """``accuracy.choose`` as a deterministic quarter of the method's stable step, fitted to the frames."""
    from flexmm import accuracy as acc
    from flexmm.integrators import INTEGRATORS

    def choose(problem, accuracy, only=None, every=None):
        spec = INTEGRATORS[only or "pefrl"]
        h = problem.dt if problem.omega_max <= 0 else 0.25 * spec.stability_limit / problem.omega_max
        h = acc.divides(min(h, problem.duration / 8), every)
        est = acc.Estimate(accuracy / 2, accuracy / 2, accuracy / 4, problem.duration / 10, "quick", 0.0)
        row = {"integrator": spec.name, "dt": h, "cost": 0.0}
        return acc.Choice(spec.name, h, accuracy / 2, 0.0, problem.duration / 10, [row], estimate=est)

    monkeypatch.setattr(acc, "choose", choose)
    # and no whole-run check of the quick choice (it would integrate the scene three times)
    monkeypatch.setattr(acc, "run_estimate", lambda problem, spec, h, pilot: pilot)
    monkeypatch.setattr(acc, "shorten_for_run", lambda problem, choice, est, accuracy, every: est)


@pytest.fixture
def stopped(monkeypatch):
    """Integration replaced by ``Stop`` in run/compare (the controller), bench and stability (their scans)."""
    import flexmm.api
    from flexmm.diagnostics import stability_scan, workprecision

    monkeypatch.setattr(flexmm.api, "run_problem", _stop)
    monkeypatch.setattr(workprecision, "benchmark", _stop)
    monkeypatch.setattr(stability_scan, "scan", _stop)


def plan_lines(args: list[str]) -> list[str]:
    res = CliRunner().invoke(app, args)
    assert res.exit_code in (0, 1), (args, res.output, res.exception)
    if res.exit_code == 1:
        assert isinstance(res.exception, Stop), (args, res.output, res.exception)
    lines = [ln for ln in res.stdout.splitlines() if ln.startswith("plan: ") and "WARNING" not in ln]
    assert lines, (args, res.output)
    return lines


def _pulse_field(path: Path) -> str:
    from flexmm.config import load_scene
    from flexmm.models import model_fields
    from flexmm.plan.output import AnalysisRequest, default_field

    kind = load_scene(path).lattice.kind
    return "pulse:" + default_field(AnalysisRequest("pulse"), model_fields(kind))


@pytest.mark.parametrize("path", CONFIGS, ids=[p.stem for p in CONFIGS])
def test_every_verb_prints_the_same_plan(path, tmp_path, quick_pilots, stopped):
    cfg = str(path)
    planned = plan_lines(["plan", cfg])
    assert any(ln.startswith("plan: method ") for ln in planned)
    assert any(ln.startswith("plan: frames ") for ln in planned)
    cost = next(ln for ln in planned if ln.startswith("plan: cost: integration ≈ "))
    assert "(calibrated for " in cost, cost  # every shipped model kind and method is in the calibration table
    assert plan_lines(["validate", cfg]) == planned
    assert plan_lines(["run", cfg, "--out", str(tmp_path / "run")]) == planned
    assert plan_lines(["bench", cfg, "--out", str(tmp_path / "bench")]) == planned
    assert plan_lines(["stability", cfg, "--out", str(tmp_path / "stab")]) == planned
    pulse = _pulse_field(path)  # compare runs for an analysis: the plan of `plan --analysis` alike
    assert plan_lines(["compare", cfg, "--fidelity", "auto,full", "--analysis", pulse, "--out", str(tmp_path / "c")]) \
        == plan_lines(["plan", cfg, "--analysis", pulse])


def test_lego_validate_plan_run_agree(tmp_path, stopped):
    """The issue's example: validate said velocity Verlet at 2.51e-5 s, plan and run PEFRL at 1.43e-4 s (on
    the demo's 200-unit chain then; on its 900-unit chain with an absorbing end, PEFRL at 1.25e-4 s)."""
    planned = plan_lines(["plan", str(LEGO)])
    assert plan_lines(["validate", str(LEGO)]) == planned
    assert plan_lines(["run", str(LEGO), "--out", str(tmp_path / "run")]) == planned
    method = next(ln for ln in planned if ln.startswith("plan: method "))
    assert method.startswith("plan: method pefrl, dt 0.000125 s (chosen by the accuracy pilots)"), method


def test_throughput_interpolates_the_calibration_table(monkeypatch):
    """log–log between calibrated sizes, the nearest outside, a geometric mean at one size; an
    uncalibrated method scaled by force evaluations per step, an unknown kind from the median."""
    import math

    from flexmm.plan import cost

    rows = ({"kind": "k", "method": "velocity_verlet", "n_units": 100, "threads": 1, "unit_steps_per_s": 1e6,
             "call_s": 1e-5, "scene": "a"},
            {"kind": "k", "method": "velocity_verlet", "n_units": 10_000, "threads": 1, "unit_steps_per_s": 4e6,
             "call_s": 1e-5, "scene": "a"},
            {"kind": "k", "method": "velocity_verlet", "n_units": 10_000, "threads": 1, "unit_steps_per_s": 16e6,
             "call_s": 1e-5, "scene": "b"})
    monkeypatch.setattr(cost, "calibration", lambda: rows)
    rate, call_s, how = cost.throughput("k", "velocity_verlet", 1000)
    assert math.isclose(rate, math.sqrt(1e6 * 8e6)) and math.isclose(call_s, 1e-5) and "calibrated for k" in how
    assert math.isclose(cost.throughput("k", "velocity_verlet", 10)[0], 1e6)
    assert math.isclose(cost.throughput("k", "velocity_verlet", 10**6)[0], 8e6)
    rate, _, how = cost.throughput("k", "pefrl", 100)  # 4 force evaluations a step against 1
    assert math.isclose(rate, 0.25e6) and "scaled to pefrl" in how
    assert "not calibrated" in cost.throughput("other", "velocity_verlet", 100)[2]
