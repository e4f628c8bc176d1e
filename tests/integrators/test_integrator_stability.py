"""Stability limits on the linear chain: measured blow-up step vs predicted (PHYSICS.md §3).

The LEGO chain at amplitude 1e-7 (random state: every mode present) is linear to ~1e-7.
Raising dt until the run blows up (energy × 1e4 within t = 400, ~130 periods of the fastest
mode) and bisecting gives the measured limit; the prediction is stability_limit/ω_max with
ω_max from Lanczos on the matrix-free Hessian. Every fixed-step explicit method must land
within 10 % (they land within 2 %: the amplification grows fast past the limit).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from integrator_helpers import chain_problem

from flexmm.integrators import INTEGRATORS
from flexmm.integrators.runner import integrate
from flexmm.stability_scan import linear_chain_state, measure_limit

T_END = 400.0
EXPLICIT = [k for k, v in INTEGRATORS.items() if v.explicit_limit]


@pytest.fixture(scope="module")
def linear_chain():
    problem = chain_problem(32)
    return problem, *linear_chain_state(problem)


@pytest.mark.parametrize("name", EXPLICIT)
def test_measured_limit_matches_prediction(name, linear_chain) -> None:
    problem, q0, v0 = linear_chain
    predicted = INTEGRATORS[name].stability_limit / problem.omega_max
    measured, trials = measure_limit(problem, INTEGRATORS[name], predicted, T_END, q0=q0, v0=v0)
    print(f"{name}: predicted {predicted:.5f}, measured {measured:.5f}, ratio {measured / predicted:.4f} "
          f"({len(trials)} runs)")
    assert abs(measured / predicted - 1.0) < 0.10


def test_adaptive_tableau_limit_and_error_control(linear_chain) -> None:
    """dopri5's fixed-step map is (weakly) unstable past hω = 0.997 — growth < 1e-4 per step up to
    hω ≈ 1.2, so runs blow up later; with error control no step size blows up."""
    problem, q0, v0 = linear_chain
    spec = INTEGRATORS["dopri5"]
    predicted = spec.stability_limit / problem.omega_max
    measured, _ = measure_limit(problem, spec, predicted, T_END, q0=q0, v0=v0)
    print(f"dopri5 fixed steps: predicted {predicted:.5f}, measured {measured:.5f}")
    assert 1.0 <= measured / predicted < 2.0
    tr = integrate(problem, "dopri5", rtol=1e-6, atol=1e-12, max_step=10 * predicted, t_end=T_END,
                   n_frames=5, q0=q0, v0=v0)
    assert tr.ok


def test_implicit_midpoint_has_no_step_limit(linear_chain) -> None:
    problem, q0, v0 = linear_chain
    h = 20 * 2.0 / problem.omega_max  # 20 x the Verlet limit
    tr = integrate(problem, "implicit_midpoint", h=h, t_end=T_END, n_frames=5, q0=q0, v0=v0)
    assert tr.ok and tr.counters["failed"] == 0
    assert math.isinf(INTEGRATORS["implicit_midpoint"].stability_limit)


@pytest.mark.slow
@pytest.mark.parametrize("name", EXPLICIT + ["dopri5"])
def test_registry_limit_is_the_methods_own(name) -> None:
    """stability_limit equals the harmonic-oscillator limit of the compiled method (to 1e-3)."""
    from flexmm.stability import harmonic_limit

    assert harmonic_limit(INTEGRATORS[name]) == pytest.approx(INTEGRATORS[name].stability_limit, rel=1e-3)
