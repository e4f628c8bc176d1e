"""dopri5: its coefficients, its dense output, and that it meets its tolerance (scipy-style).

Oracles: scipy's own Dormand–Prince tables (``RK45.A/B/E`` and its interpolant ``RK45.P``,
independent of flexmm's), the order conditions, and a tight reference run.
"""

from __future__ import annotations

import numpy as np
import pytest
from integrator_helpers import chain_problem, nonlinear_state
from scipy.integrate._ivp.rk import RK45

from flexmm.integrators import dopri5
from flexmm.integrators.runner import integrate

N_UNITS = 16


def test_tableau_matches_scipy_and_order_conditions() -> None:
    np.testing.assert_allclose(dopri5.A[:6, :5], RK45.A, rtol=1e-15, atol=1e-15)
    np.testing.assert_allclose(dopri5.B[:6], RK45.B, rtol=1e-15)
    np.testing.assert_allclose(np.abs(dopri5.E), np.abs(RK45.E), rtol=1e-14)  # scipy: b̂ − b
    np.testing.assert_allclose(dopri5.A.sum(axis=1), dopri5.C, atol=1e-15)  # row sums = nodes
    b, c = dopri5.B, dopri5.C
    for k in range(1, 6):  # quadrature conditions Σ b c^(k−1) = 1/k, k ≤ 5
        assert b @ c ** (k - 1) == pytest.approx(1.0 / k, abs=1e-14)
    assert dopri5.E.sum() == pytest.approx(0.0, abs=1e-15)  # both solutions consistent


def test_dense_output_matches_scipy_interpolant() -> None:
    """One step of y' = λy: flexmm's continuous extension equals scipy's P-matrix form."""
    lam, h, y0 = -0.3 + 1.7j, 0.37, 1.0 + 0.5j
    K = np.zeros(7, complex)
    for i in range(7):
        K[i] = lam * (y0 + h * dopri5.A[i, :i] @ K[:i])
    y1 = y0 + h * dopri5.B @ K
    r = np.array([y0, y1 - y0, h * K[0] - (y1 - y0), 0, h * dopri5.D @ K], complex)
    r[3] = r[1] - h * K[6] - r[2]
    for theta in (0.1, 0.5, 0.9):
        ours = r[0] + theta * (r[1] + (1 - theta) * (r[2] + theta * (r[3] + (1 - theta) * r[4])))
        scipy_form = y0 + h * K @ (RK45.P @ theta ** np.arange(1, 5))
        assert abs(ours - scipy_form) < 1e-14


@pytest.fixture(scope="module")
def chain():
    problem = chain_problem(N_UNITS, "dopri5", "drive+damping")
    q0, v0 = nonlinear_state(N_UNITS)
    ref = integrate(problem, "dopri5", rtol=1e-13, atol=1e-15, t_end=100.0, n_frames=201, q0=q0, v0=v0)
    return problem, q0, v0, ref


def test_meets_its_tolerance(chain) -> None:
    """Error control is local: every accepted step has estimated error ≤ tol (tol = rtol = atol
    on states ≲ 0.4), so the global error over the run is at most ~tol per accepted step —
    checked over 100 time units (~30 periods of the fastest mode, 201 dense-output frames) —
    and it falls in proportion to tol."""
    problem, q0, v0, ref = chain
    errors = []
    for rtol in (1e-5, 1e-7, 1e-9):
        tr = integrate(problem, "dopri5", rtol=rtol, atol=rtol, t_end=100.0, n_frames=201, q0=q0, v0=v0)
        err = np.max(np.abs(tr.q - ref.q))
        steps = tr.counters["steps"]
        print(f"rtol = atol = {rtol:g}: max error over the frames {err:.3g} = {err / rtol:.3g} tol, "
              f"{steps} steps, {tr.counters}")
        assert tr.ok
        assert err < rtol * steps
        errors.append(err)
    assert errors[0] / errors[2] > 1e3  # four decades of tolerance: at least three of error


def test_dense_output_frames(chain) -> None:
    """Frames come from the continuous extension: asking for 100x more frames neither shortens
    the steps nor changes the trajectory, and interpolated frames are as accurate as the steps."""
    problem, q0, v0, ref = chain
    dense = integrate(problem, "dopri5", rtol=1e-9, atol=1e-9, t_end=100.0, n_frames=201, q0=q0, v0=v0)
    coarse = integrate(problem, "dopri5", rtol=1e-9, atol=1e-9, t_end=100.0, n_frames=3, q0=q0, v0=v0)
    assert abs(dense.counters["steps"] - coarse.counters["steps"]) <= 2
    np.testing.assert_allclose(dense.q[::100], coarse.q, rtol=0, atol=1e-12)
    err_frames = np.max(np.abs(dense.q - ref.q))
    err_steps = np.max(np.abs(dense.q[::100] - ref.q[::100]))
    print(f"max error over 201 interpolated frames {err_frames:.3g}; at the 3 coarse frames {err_steps:.3g}")
    assert err_frames < 1e-9 * dense.counters["steps"]
