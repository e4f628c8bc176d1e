"""Second-order methods keep their order on longer runs and at small steps (README, work–precision).

The order test (test_integrator_order) runs to t = 10 at hω ≥ 0.05. Here the nonlinear 16-unit
chain runs to t = 60 at hω = 0.08 … 0.01, where the implicit midpoint rule's local error is
~(hω)²/6 ≈ 2e-5 of a step's change: a Newton tolerance that does not shrink with the step floors
the error (a fixed relative 3e-3 accepts the explicit predictor at the smallest steps and the
observed order falls to 0.5; 1e-2 makes it negative), while the accuracy-scaled tolerance of
``integrators.implicit`` keeps order 2 with one Newton–Krylov solve per step. Velocity Verlet,
explicit, is the control.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from integrator_helpers import chain_problem, nonlinear_state

from flexmm.integrators.runner import integrate

T_END = 60.0
N_UNITS = 16


@pytest.fixture(scope="module")
def long_reference():
    problem = chain_problem(N_UNITS, "dopri5")
    q0, v0 = nonlinear_state(N_UNITS)
    tr = integrate(problem, "dopri5", rtol=1e-14, atol=1e-16, t_end=T_END, q0=q0, v0=v0)
    return q0, v0, tr.q[-1]


@pytest.mark.parametrize("name", ["implicit_midpoint", "velocity_verlet"])
def test_second_order_methods_keep_their_order_at_small_steps(name, long_reference) -> None:
    q0, v0, q_ref = long_reference
    problem = chain_problem(N_UNITS, name)
    hs = 0.08 / problem.omega_max / 2.0 ** np.arange(4)
    runs = [integrate(problem, name, h=h, t_end=T_END, q0=q0, v0=v0) for h in hs]
    errors = np.array([np.max(np.abs(tr.q[-1] - q_ref)) for tr in runs])
    slope = np.polyfit(np.log(hs), np.log(errors), 1)[0]
    print(f"{name}: hω {hs * problem.omega_max}, errors {errors}, observed order {slope:.3f}, "
          f"counters at the smallest step {runs[-1].counters}")
    assert errors[-1] > 1e-11  # far above the reference's accuracy
    assert abs(slope - 2.0) < 0.2
    if name == "implicit_midpoint":  # one Newton–Krylov solve per step, then the converged check
        assert all(tr.counters["rejected_or_newton"] <= 2 * tr.counters["steps"] for tr in runs)


@pytest.mark.slow
def test_verlet_on_the_soliton_bench_saturates_then_converges_at_order_2() -> None:
    """README "Reading the charts": on the LEGO soliton bench the final-state error of Verlet
    hardly falls while its phase error on the fastest radiation exceeds ~1 rad (hω_max ≳ 0.08 over
    T ≈ 2000) and falls at order 2 below that."""
    from pathlib import Path

    from flexmm.assemble import build_problem
    from flexmm.config import load_scene
    from flexmm.diagnostics.workprecision import lattice_dofs

    root = Path(__file__).resolve().parents[2]
    problem = build_problem(load_scene(root / "benchmarks" / "configs" / "lego_soliton.yaml"))
    dofs = lattice_dofs(problem.system)
    q_ref = integrate(problem, "dopri5", rtol=1e-12, atol=1e-14).q[-1, dofs]
    w = problem.omega_max

    def error(h_omega: float) -> float:
        return float(np.max(np.abs(integrate(problem, "velocity_verlet", h=h_omega / w).q[-1, dofs] - q_ref)))

    crossover = math.sqrt(24.0 / (w * problem.duration))  # phase error 1 rad at ω_max
    saturated = [error(x) for x in (1.8, 0.6, 0.2)]  # (hω)² falls 81×
    small = np.array([0.05, 0.02])
    converging = [error(x) for x in small]
    slope = math.log(converging[0] / converging[1]) / math.log(small[0] / small[1])
    print(f"crossover hω_max {crossover:.3f}; errors {saturated} (saturated), {converging} (order {slope:.3f})")
    assert 0.05 < crossover < 0.2
    assert max(saturated) / min(saturated) < 10.0
    assert abs(slope - 2.0) < 0.2
