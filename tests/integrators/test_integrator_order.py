"""Every registered integrator converges at its declared order (docs/physics.md §3; diffrax-style).

On the nonlinear LEGO chain (|θ| up to 0.4 rad), with each kind of external term of
integrators.common: none, viscous damping, dashpots, a harmonic force drive with damping, a
prescribed displacement pulse. The error at t = 10 (about 3 periods of the fastest mode)
against a tight dopri5 reference, for four steps halving from h₀; the slope of log error
against log h must be within 0.2 of the declared order.
"""

from __future__ import annotations

import numpy as np
import pytest
from integrator_helpers import VARIANTS, chain_problem, nonlinear_state

from flexmm.integrators import INTEGRATORS
from flexmm.integrators.runner import integrate

T_END = 10.0
N_UNITS = 16
#: largest step per method (nondimensional, ω_max ≈ 2): asymptotic regime, errors ≫ round-off
H0 = {"velocity_verlet": 0.2, "pefrl": 0.4, "blanes_moan6": 0.7, "rk4": 0.1, "dopri5": 0.1,
      "implicit_midpoint": 0.4}

_references: dict[str, np.ndarray] = {}


def reference(variant: str, q0, v0) -> np.ndarray:
    if variant not in _references:
        problem = chain_problem(N_UNITS, "dopri5", variant)
        tr = integrate(problem, "dopri5", rtol=1e-14, atol=1e-16, t_end=T_END, q0=q0, v0=v0)
        _references[variant] = tr.q[-1]
    return _references[variant]


def test_every_method_has_a_step() -> None:
    assert set(H0) == set(INTEGRATORS)


def _valid(name: str, variant: str) -> bool:
    """Methods that refuse velocity-dependent forces are not run with damping (the solver refuses)."""
    return variant == "undamped" or "damping" not in VARIANTS[variant] or INTEGRATORS[name].velocity_dependent_forces


@pytest.mark.parametrize("name, variant", [(n, v) for v in VARIANTS for n in INTEGRATORS if _valid(n, v)])
def test_observed_order(name: str, variant: str) -> None:
    spec = INTEGRATORS[name]
    problem = chain_problem(N_UNITS, name, variant)
    q0, v0 = nonlinear_state(N_UNITS)
    q_ref = reference(variant, q0, v0)
    hs = H0[name] / 2.0 ** np.arange(4)
    # fixed steps for every method (dopri5 without tolerances steps with h)
    errors = np.array([np.max(np.abs(integrate(problem, name, h=h, t_end=T_END, q0=q0, v0=v0).q[-1] - q_ref))
                       for h in hs])
    slope = np.polyfit(np.log(hs), np.log(errors), 1)[0]
    print(f"{name} {variant}: errors {errors}, observed order {slope:.3f} (declared {spec.order})")
    assert errors[-1] > 2e-13, "errors reached the reference's accuracy: order unmeasurable"
    assert abs(slope - spec.order) < 0.2, (errors, slope)
