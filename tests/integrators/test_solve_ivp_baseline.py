"""The solve_ivp baseline integrates the same equations as flexmm (drives, damping, dashpots)."""

from __future__ import annotations

import numpy as np
from integrator_helpers import chain_problem

from flexmm.diagnostics import baseline
from flexmm.integrators.runner import integrate


def test_rhs_is_the_acceleration_of_the_model() -> None:
    problem = chain_problem(12, variant="drive+damping")
    s = problem.system
    rng = np.random.default_rng(1)
    q, v = 0.05 * rng.standard_normal(s.ndof), 0.05 * rng.standard_normal(s.ndof)
    rhs, count = baseline.make_rhs(problem)
    dy = rhs(0.7, np.concatenate([q, v]))
    # independent evaluation: numpy reference force, on-site damping, dashpots, applied force
    _, f = s.reference(q, s.args)
    t = problem.terms
    dv = v[t.dash_ij[:, 1]] - v[t.dash_ij[:, 0]]
    np.add.at(f, t.dash_ij[:, 0], t.dash_c * dv)
    np.add.at(f, t.dash_ij[:, 1], -t.dash_c * dv)
    from flexmm.integrators.common import waveform

    for d, dof in enumerate(t.drv_dof):
        f[dof] += waveform(t.drv_shape[d], t.drv_prm[d], 0.7)[0]
    np.testing.assert_allclose(dy[: s.ndof], v)
    np.testing.assert_allclose(dy[s.ndof :], s.inv_mass * (f - problem.damp * v), rtol=1e-12, atol=1e-14)
    assert count[0] == 1


def test_solve_ivp_agrees_with_our_reference() -> None:
    """DOP853 at rtol 1e-11 and our dopri5 at rtol 1e-12 give the same frames (to ~1e-9)."""
    problem = chain_problem(16, variant="drive+damping")
    ours = integrate(problem, "dopri5", rtol=1e-12, atol=1e-14, t_end=40.0, n_frames=21)
    theirs = baseline.run(problem, "DOP853", 1e-11, 1e-13, ours.t)
    print(f"max |ours − DOP853| over frames {np.max(np.abs(ours.q - theirs.q)):.3g}, "
          f"max |q| {np.max(np.abs(ours.q)):.3g}")
    assert theirs.status == "finished"
    np.testing.assert_allclose(theirs.q, ours.q, rtol=0, atol=1e-9)
