"""Stability limits on the linear chain: measured blow-up step vs predicted (docs/physics.md §3).

The LEGO chain's fastest mode alone, at amplitude 1e-6 (linear dynamics), is run for 1/g steps
at each trial step; a trial is unstable if it blows up or its fitted amplitude growth exceeds
g = 1e-5 per step (``stability_scan``). Raising dt and bisecting gives the measured limit; the
prediction is stability_limit/ω_max (first hω with |R| > 1). Every fixed-step explicit method,
and dopri5 at fixed steps, must land within 10 %: Verlet, PEFRL, Blanes–Moan and RK4 within
0.5 % (their growth jumps past the limit; Blanes–Moan's first unstable band, 3e-4 wide, is
caught by the scan's probe just above the prediction), dopri5 at the limit the threshold
implies, +1.8 % (ln|R(iy)| only reaches 1e-5 at y = 1.0156; see ``test_growth_rate_is_the_tableau_s``).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from integrator_helpers import chain_problem

from flexmm.integrators import INTEGRATORS, dopri5
from flexmm.integrators.runner import integrate
from flexmm.diagnostics.stability_scan import GROWTH_THRESHOLD, measure_limit, mode_state, trial

FIXED_STEP = [k for k, v in INTEGRATORS.items() if v.explicit_limit] + ["dopri5"]


@pytest.fixture(scope="module")
def linear_chain():
    problem = chain_problem(8)
    return problem, *mode_state(problem)


def dp5_amplification(y: float) -> float:
    """|R(iy)| of the Dormand–Prince 5th-order solution, R(z) = 1 + z bᵀ(I − zA)⁻¹1, from the tableau."""
    a, b = dopri5.A, dopri5.B
    return float(abs(1.0 + 1j * y * b @ np.linalg.solve(np.eye(7) - 1j * y * a, np.ones(7))))


#: measured in the default run: one of each kind of method (second-order, fourth-order splitting,
#: Runge–Kutta); the others (each a long bisection of runs) are ``slow``
MEASURED_BY_DEFAULT = ("velocity_verlet", "pefrl", "rk4")


@pytest.mark.parametrize("name", [n if n in MEASURED_BY_DEFAULT else pytest.param(n, marks=pytest.mark.slow)
                                  for n in FIXED_STEP])
def test_measured_limit_matches_prediction(name, linear_chain) -> None:
    problem, q0, v0 = linear_chain
    predicted = INTEGRATORS[name].stability_limit / problem.omega_max
    measured, trials = measure_limit(problem, INTEGRATORS[name], predicted, growth_threshold=GROWTH_THRESHOLD,
                                     q0=q0, v0=v0)
    print(f"{name}: predicted {predicted:.5f}, measured {measured:.5f}, ratio {measured / predicted:.4f} "
          f"({len(trials)} runs)")
    assert abs(measured / predicted - 1.0) < 0.10
    assert measured / predicted > 0.99  # a stable step is never reported unstable


def test_predicted_dopri5_limit_is_the_tableau_s() -> None:
    """The registry's 0.9972 is where |R(iy)| of the tableau first exceeds 1."""
    lim = INTEGRATORS["dopri5"].stability_limit
    ys = np.linspace(0.05, lim - 1e-3, 200)
    assert max(dp5_amplification(y) for y in ys) <= 1.0
    assert dp5_amplification(lim + 1e-3) > 1.0


@pytest.mark.parametrize("ratio", [0.95, 1.05])
def test_growth_rate_is_the_tableau_s(ratio, linear_chain) -> None:
    """The scan's fitted growth per step equals ln|R(ihω_max)| of the tableau (weak growth is seen)."""
    problem, q0, v0 = linear_chain
    h = ratio * INTEGRATORS["dopri5"].stability_limit / problem.omega_max
    stable, g = trial(problem, INTEGRATORS["dopri5"], h, growth_threshold=GROWTH_THRESHOLD, q0=q0, v0=v0)
    expected = math.log(dp5_amplification(h * problem.omega_max))
    print(f"h/h* = {ratio}: fitted growth {g:.4e} per step, ln|R| {expected:.4e}")
    assert g == pytest.approx(expected, rel=0.02)
    assert stable == (expected <= GROWTH_THRESHOLD)


def test_error_control_keeps_dopri5_stable(linear_chain) -> None:
    problem, q0, v0 = linear_chain
    predicted = INTEGRATORS["dopri5"].stability_limit / problem.omega_max
    tr = integrate(problem, "dopri5", rtol=1e-6, atol=1e-12, max_step=10 * predicted, t_end=400.0,
                   n_frames=5, q0=q0, v0=v0)
    assert tr.ok


def test_implicit_midpoint_has_no_step_limit(linear_chain) -> None:
    problem, q0, v0 = linear_chain
    h = 20 * 2.0 / problem.omega_max  # 20 x the Verlet limit
    stable, g = trial(problem, INTEGRATORS["implicit_midpoint"], h, growth_threshold=1e-3, q0=q0, v0=v0)
    assert stable and abs(g) < 1e-6  # the midpoint rule conserves the quadratic energy
    assert math.isinf(INTEGRATORS["implicit_midpoint"].stability_limit)


@pytest.mark.slow
def test_overflow_alone_sees_dopri5_late() -> None:
    """Why the growth criterion: waiting for energy × 1e4 within t = 400 puts dopri5 ~1.77× late."""
    problem = chain_problem(32)
    q0, v0 = mode_state(problem)
    predicted = INTEGRATORS["dopri5"].stability_limit / problem.omega_max
    measured, _ = measure_limit(problem, INTEGRATORS["dopri5"], predicted, 400.0, q0=q0, v0=v0)
    assert measured / predicted > 1.3


@pytest.mark.slow
def test_threshold_limit_is_the_tableau_s() -> None:
    """harmonic_limit with a growth threshold g finds the first y with ln|R(iy)| > g (dopri5: 1.0156)."""
    from scipy.optimize import brentq

    from flexmm.stability import harmonic_limit

    g = GROWTH_THRESHOLD
    expected = brentq(lambda y: math.log(dp5_amplification(y)) - g, 1.0, 1.2, xtol=1e-9)
    assert harmonic_limit(INTEGRATORS["dopri5"], growth_per_step=g, hi=1.5) == pytest.approx(expected, rel=1e-4)


@pytest.mark.slow
@pytest.mark.parametrize("name", FIXED_STEP)
def test_registry_limit_is_the_methods_own(name) -> None:
    """stability_limit equals the harmonic-oscillator limit of the compiled method (to 1e-3)."""
    from flexmm.stability import harmonic_limit

    assert harmonic_limit(INTEGRATORS[name]) == pytest.approx(INTEGRATORS[name].stability_limit, rel=1e-3)
