"""Long runs without damping: symplectic methods keep the energy bounded with no drift; the
others drift, but no more than their accuracy allows (docs/physics.md §3, JAX-MD-style invariants).

The nonlinear 16-unit LEGO chain of the order test. A symplectic method conserves a modified
energy, so E − E0 oscillates with amplitude O((hω)^p) and its mean does not move: the mean
over the last tenth of the run stays within a fifth of the oscillation of the mean over the
first tenth, and the oscillation does not grow. (At hω close to the stability limit a
4-stage splitting such as PEFRL shows a slow drift of the mean; the test uses hω = 0.45,
where its energy error is already ~1e-7 E. The 11-stage Blanes–Moan method drifts slowly above
hω ≈ 0.9 on this strongly nonlinear state, by ~1e-6 E over 20 000 steps; the test uses 0.75.
The implicit midpoint rule runs 100 000 steps: over 50 000 the window means of this chaotic
state still fluctuate by up to 0.4 of the swing whatever the Newton tolerance, 1e-12 … 1e-10.)
"""

from __future__ import annotations

import numpy as np
import pytest
from integrator_helpers import chain_problem, nonlinear_state, total_energy

from flexmm.integrators import INTEGRATORS
from flexmm.integrators.stepper import make_stepper

N_UNITS = 16
#: (h ω_max, steps) per symplectic method (long enough for the initial pulse to spread)
SYMPLECTIC_RUNS = {"velocity_verlet": (0.6, 100_000), "pefrl": (0.45, 25_000), "blanes_moan6": (0.75, 20_000),
                   "implicit_midpoint": (0.6, 100_000)}


def energy_history(problem, name, h, nsteps, every):
    q0, v0 = nonlinear_state(N_UNITS)
    st = make_stepper(problem, name, h=h, q0=q0, v0=v0, threads=1, check_energy=False)
    out = []
    st.run([every] * (nsteps // every), lambda s: out.append(total_energy(problem, s.q, s.v)))
    return np.array(out) - total_energy(problem, q0, v0), total_energy(problem, q0, v0)


def test_symplectic_entries_are_tested() -> None:
    assert set(SYMPLECTIC_RUNS) == {k for k, v in INTEGRATORS.items() if v.symplectic}


@pytest.mark.parametrize("name", list(SYMPLECTIC_RUNS))
def test_symplectic_energy_bounded_without_drift(name: str) -> None:
    problem = chain_problem(N_UNITS, name)
    h_omega, nsteps = SYMPLECTIC_RUNS[name]
    h = h_omega / problem.omega_max
    err, e0 = energy_history(problem, name, h, nsteps, 10)
    tenth = err.size // 10
    # the localised initial pulse spreads during the first half (the state-dependent offset
    # between E and the modified energy relaxes); compare windows of the second half
    first, last = np.max(np.abs(err[:tenth])), np.max(np.abs(err[-tenth:]))
    early = np.max(np.abs(err[: 5 * tenth]))
    swing = np.max(np.abs(err[err.size // 2 :] - err[err.size // 2 :].mean()))
    drift = abs(err[-tenth:].mean() - err[5 * tenth : 6 * tenth].mean())
    order = INTEGRATORS[name].order
    print(f"{name}: {nsteps} steps, hω = {h_omega}: max|E−E0|/E0 first tenth {first / e0:.3g}, "
          f"last tenth {last / e0:.3g}; second half: swing {swing / e0:.3g}, drift of the mean {drift / e0:.3g}")
    assert first < h_omega**order * e0  # O((hω)^p) energy error, constant 1 (loose)
    # no growth: the last tenth against the whole first half (a single early tenth is too short a
    # sample on this chaotic state: its maximum alone varies 2× when the state changes by 1e-9)
    assert last < 1.5 * early
    # no secular drift (measured 0.00–0.22 of the swing for relative perturbations 0, 1e-9, 1e-7
    # of the initial state; a drift over these runs would be many swings)
    assert drift < 0.3 * swing


@pytest.mark.parametrize("name", [k for k, v in INTEGRATORS.items() if not v.symplectic])
def test_non_symplectic_energy_drift_is_within_accuracy(name: str) -> None:
    """RK4 (fixed step) and dopri5 (adaptive) dissipate energy slowly: bounded by their accuracy."""
    from flexmm.integrators.runner import integrate

    problem = chain_problem(N_UNITS, name)
    q0, v0 = nonlinear_state(N_UNITS)
    e0 = total_energy(problem, q0, v0)
    t_end = 2000.0  # ~600 periods of the fastest mode
    if INTEGRATORS[name].adaptive:
        tr = integrate(problem, name, rtol=1e-8, atol=1e-10, t_end=t_end, n_frames=51, q0=q0, v0=v0)
        bound = 1e-5  # a local error ≤ rtol per step keeps the energy error ≲ rtol × steps / 10
    else:
        # RK4 damps a mode of frequency ω by |R(ihω)|² ≈ 1 − (hω)⁶/72 per step: the energy loss
        # would be at most that of the fastest mode
        # if all the energy sat in it; the chaotic state's nonlinear terms add their own O(h⁴)
        # error (measured 0.66–1.22 of that linear bound for relative perturbations 0 … 1e-5 of
        # the initial state), so the test allows twice it
        h_omega = 0.2
        tr = integrate(problem, name, h=h_omega / problem.omega_max, t_end=t_end, n_frames=51, q0=q0, v0=v0)
        bound = 2.0 * h_omega**6 / 72 * t_end * problem.omega_max / h_omega
    err = np.array([total_energy(problem, q, v) for q, v in zip(tr.q, tr.v)]) - e0
    print(f"{name}: |E−E0|/E0 at the end {abs(err[-1]) / e0:.3g}, max {np.abs(err).max() / e0:.3g}, bound {bound:.3g}")
    assert tr.ok
    assert np.abs(err).max() < bound * e0
    assert abs(err[-1]) > 1e-3 * bound * e0  # the bound is not vacuous
