"""The implicit midpoint rule's differentiated run (``design.midpoint``): the engine's rule with its
Newton iteration run to rounding, and the refusal of steps it cannot solve. Its adjoint against
central differences (a chain, a sheet, mass chains; damping, drives, dashpots, friction, the
striker), tangents, checkpointing, order of convergence, design and fit: test_gradient_splitting.
"""

from __future__ import annotations

import numpy as np
import pytest

from flexmm.design import midpoint
from flexmm.design.gradient import GradientError, trajectory_of
from flexmm.integrators.common import total_force
from flexmm.integrators.implicit import _residual
from flexmm.integrators.stepper import make_stepper

from .test_gradient import _objective, _problem

MIDPOINT = "implicit_midpoint"


@pytest.mark.parametrize("name", ["chain-displacement-damped",
                                  pytest.param("mass-friction-dashpots", marks=pytest.mark.slow),
                                  pytest.param("sheet-tilted-pulse-damped", marks=pytest.mark.slow)])
def test_forward_sweep_is_the_engines_rule_solved_to_rounding(name):
    """The differentiated run is the Stepper's implicit-midpoint run up to the engine's adaptive
    Newton tolerance (it differs by ~1e-7 relative here), its steps solve the engine's midpoint
    equation R(V) = 0 to rounding (V = (v + v')/2, held DOFs (q' − q)/h), and the recorded
    force is the total force at the recorded state."""
    problem = _problem(name)
    traj, raw = trajectory_of(problem, nsteps=120, stride=1, integrator=MIDPOINT)
    rec, _ = traj.run(raw)
    stepper = make_stepper(problem, MIDPOINT, h=traj.h)
    f = np.empty_like(stepper.q)
    for j in (40, 80, 120):
        stepper.advance(40)
        for got, want in ((rec.q[j], stepper.q), (rec.v[j], stepper.v)):
            np.testing.assert_allclose(got, want, rtol=0, atol=1e-6 * np.abs(want).max())
        total_force(stepper.args, stepper.q, stepper.v, stepper.t, f, stepper.terms)
        np.testing.assert_allclose(rec.f[j], f, rtol=0, atol=1e-6 * np.abs(f).max())
    args, terms = traj.bind(raw)[:2]
    free = raw.minv > 0
    h = traj.h
    Q, F, R = (np.empty_like(raw.q0) for _ in range(3))
    worst = 0.0
    for k in range(traj.nsteps):
        V = np.where(free, 0.5 * (rec.v[k] + rec.v[k + 1]), (rec.q[k + 1] - rec.q[k]) / h)
        _residual(args, terms, raw.minv, raw.damp, rec.q[k], rec.v[k], V, traj.times[k] + 0.5 * h, h, Q, F, R)
        size = max(np.abs((V - rec.v[k])[free] / raw.minv[free]).max(), 0.5 * h * np.abs(F[free]).max())
        worst = max(worst, np.abs(R).max() / size)
    assert worst < 1e-11, worst  # 1e-13 solved; V rebuilt from v' = 2V − v loses ~1e-12 relative


def test_a_step_newton_cannot_solve_is_refused(monkeypatch):
    """A step the engine would split into substeps is refused with a GradientError naming the
    step, not differentiated as if it were one step (here every step fails: a tolerance no
    residual meets, NaN)."""
    traj, raw = trajectory_of(_problem("chain-force-shaker"), nsteps=20, stride=5, integrator=MIDPOINT)
    monkeypatch.setattr(midpoint, "NEWTON_RTOL", float("nan"))
    objective = _objective((traj.n_samples, traj.obs.size))
    with pytest.raises(GradientError, match="did not converge at step 0.*substeps"):
        traj.gradient(raw, objective)
    with pytest.raises(GradientError, match="did not converge at step 0"):
        traj.sensitivities(raw, [raw.zeros()])
