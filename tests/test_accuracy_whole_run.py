"""The error estimate a run reports bounds the true error of what it reports (issue #32, item 3).

The LEGO demo (configs/lego_vector_soliton.yaml) at a reduced size: 100 units (its far end free) for 0.2 s. Its
soliton breathes, so the phase error of its breathing keeps growing after the pilot (a tenth of
the run): the pilot's own step doubling said 3e-5 at the step it chose while the amplitudes were
off by 1.1e-3 against a 4x finer step. The estimate is now made over the whole run when that is
cheap (and otherwise extrapolated with the error's measured growth): it bounds the error measured
against a run at a 4x finer step, of the traced amplitudes and arrival times and of the speed and
amplitude ``flexmm analyze`` reports.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from flexmm import accuracy as acc
from flexmm.analysis.report.analyze import analyze_dataset
from flexmm.analysis.report.summary import principal
from flexmm.api import run_scene
from flexmm.assemble import build_problem
from flexmm.config import load_scene
from flexmm.integrators import INTEGRATORS

DEMO = Path(__file__).resolve().parents[1] / "configs" / "lego_vector_soliton.yaml"
SMALL = ["lattice.n_units=100", "damping.absorbing=null", "solver.duration_s=0.2", "output.n_frames=201"]


def test_demo_estimate_bounds_the_error_against_a_4x_finer_step(tmp_path):
    res = run_scene(load_scene(DEMO, SMALL), run_dir=tmp_path / "run", fidelity="full", in_memory=True)
    attrs = res.dataset.attrs
    assert res.status == "finished", res.reason
    estimate, dt_s = float(attrs["accuracy_estimate"]), float(attrs["dt_s"])
    assert "whole run" in attrs["accuracy_check"] and estimate <= 1e-4
    fine = run_scene(load_scene(DEMO, SMALL + ["solver.accuracy=null", "solver.integrator=pefrl",
                                               f"solver.dt_s={dt_s / 4!r}"]),
                     run_dir=tmp_path / "fine", fidelity="full", in_memory=True)
    # the traced quantities (peak |q - q0| per site, half-peak arrival times) over the whole run
    problem = build_problem(load_scene(DEMO, SMALL + ["solver.accuracy=null", "solver.integrator=pefrl",
                                                      f"solver.dt_s={dt_s!r}"]))
    spec = INTEGRATORS["pefrl"]
    n, n_samples, t_w = acc.window_grid(problem.duration, problem.dt)
    true = acc.quantity_error(acc.trace(problem, spec, n, t_w, n_samples),
                              acc.trace(problem, spec, 4 * n, t_w, n_samples))
    assert 0 < true.total <= estimate
    # and what the analysis reports: the soliton's speed and amplitude
    _, p = principal(analyze_dataset(res.dataset))
    _, pf = principal(analyze_dataset(fine.dataset))
    assert abs(p.speed_m_s / pf.speed_m_s - 1) <= estimate
    assert abs(p.amplitude / pf.amplitude - 1) <= estimate


def test_an_error_growing_at_the_cap_is_measured_over_the_whole_run(monkeypatch):
    """A pilot whose error grew at MAX_GROWTH (or faster: the measured γ is clipped) is no basis for
    an extrapolation, which is then only a lower bound: the whole run is measured up to SATURATED_WORK
    times the usual cost; a slower growth is extrapolated as before."""
    from types import SimpleNamespace

    spec = INTEGRATORS["pefrl"]
    # 1000 steps of 2500 units: a whole-run check costs 7 × 1000 × 4 × 2500 = 7e7 unit force evaluations
    problem = SimpleNamespace(duration=10.0, system=SimpleNamespace(n_sites=2500))
    h = problem.duration / 1000
    assert acc.WHOLE_RUN_WORK < 7e7 <= acc.SATURATED_WORK * acc.WHOLE_RUN_WORK
    monkeypatch.setattr(acc, "_whole_run", lambda problem, spec, h, pilot: "measured")
    pilot = lambda growth: acc.Estimate(1e-6, 1e-6, 1e-7, 1.0, "step doubling on a pilot", 0.0, growth)
    assert acc.run_estimate(problem, spec, h, pilot(acc.MAX_GROWTH)) == "measured"
    slow = acc.run_estimate(problem, spec, h, pilot(1.0))
    assert slow.error == pytest.approx(1e-5) and "extrapolated" in slow.method and "at least" not in slow.method
    problem.system.n_sites = 25000  # beyond even the saturated budget: extrapolated, and said to be a lower bound
    assert "at least" in acc.run_estimate(problem, spec, h, pilot(acc.MAX_GROWTH)).method


def test_a_whole_run_estimate_uses_the_order_the_error_shows(monkeypatch):
    """Traces whose amplitudes are off by C h^1.5 (a non-smooth force's order, not PEFRL's 4): the
    whole-run estimate at h is C h^1.5 within 2 % (Richardson with the method's order said 0.66 of it)."""
    import numpy as np

    t = np.linspace(0.0, 1.0, 201)[:, None, None]
    sites = np.arange(20.0)[None, None, :]
    wave = np.exp(-(((t - 0.02 - 0.04 * sites) / 0.02) ** 2))  # a pulse passing every site
    C, q = 0.3, 1.5

    def fake(problem, spec, n_steps, t_end, n_samples):
        return acc.Trace(wave * (1 + C * (t_end / n_steps) ** q), 1.0 / 200, n_steps)

    monkeypatch.setattr(acc, "trace", fake)
    problem = type("P", (), {"duration": 1.0})()
    h = 1.0 / 400
    est = acc._whole_run(problem, INTEGRATORS["pefrl"], h, acc.Estimate(0, 0, 0, 0.1, "pilot", 0.0))
    exact = acc.quantity_error(fake(None, None, 400, 1.0, 200), acc.Trace(wave, 1.0 / 200, 0))
    assert est.amplitude == pytest.approx(exact.amplitude, rel=0.02) and exact.amplitude == pytest.approx(C * h**q, rel=0.01)
    assert acc.observed_order(4.0, 1.0, 4) == 2.0 and acc.observed_order(64.0, 1.0, 4) == 4
