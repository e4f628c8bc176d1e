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
