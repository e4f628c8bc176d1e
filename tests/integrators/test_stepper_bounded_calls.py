"""A pilot's stepper comes back to Python (where a signal is acted on) within a bound of work."""

from __future__ import annotations

import numpy as np
from integrator_helpers import chain_problem

from flexmm.integrators.stepper import make_stepper


def test_pilot_steppers_come_back_to_python_within_their_work_bound() -> None:
    """``bounded_calls``: no compiled call longer than the bound, the same steps in all, and a
    deterministic split (two bounded runs are the same bits; the bound is work, not wall time)."""
    problem = chain_problem(n_units=50, integrator="pefrl")

    def bounded_run() -> tuple[list[int], np.ndarray]:
        st = make_stepper(problem, threads=1, check_energy=False).bounded_calls(work=50 * 7, min_steps=1)
        calls = []
        call = st._call
        st._call = lambda q, v, f, n, acc: calls.append(n) or call(q, v, f, n, acc)
        out = st.run([30, 5, 0, 16], None, reraise=True)
        assert out.ok and st.steps == 51
        return calls, st.q.copy()

    calls, q = bounded_run()
    assert calls == [7, 7, 7, 7, 2, 5, 0, 7, 7, 2]
    calls2, q2 = bounded_run()
    np.testing.assert_array_equal(q, q2)
    whole = make_stepper(problem, threads=1, check_energy=False)
    whole.run([30, 5, 0, 16])
    np.testing.assert_allclose(q, whole.q, rtol=1e-12, atol=1e-14)  # the same run, up to rounding


def test_bounded_calls_take_at_least_the_minimum_steps_on_a_large_lattice() -> None:
    """A lattice so large that the work bound allows less than ``MIN_CALL_STEPS`` steps per call
    still gets calls of that many (a one-step call ran the fused chain kernel at 40 % of its speed)."""
    from flexmm.integrators.stepper import MIN_CALL_STEPS

    problem = chain_problem(n_units=50, integrator="velocity_verlet")
    st = make_stepper(problem, threads=1, check_energy=False).bounded_calls(work=50 * 2)
    calls = []
    call = st._call
    st._call = lambda q, v, f, n, acc: calls.append(n) or call(q, v, f, n, acc)
    assert st.run([MIN_CALL_STEPS + 10], None, reraise=True).ok
    assert calls == [MIN_CALL_STEPS, 10]
