"""Problems shared by the integrator tests: small LEGO chains, a nonlinear state, a drive."""

from __future__ import annotations

import numpy as np
from conftest import LEGO_CHAIN

from flexmm.assemble import build_problem
from flexmm.config import scene_from_dict

LEGO = {
    **LEGO_CHAIN, "n_units": 24, "theta0_rad": 0.0, "left": "free", "right": "free",
}

#: damping/drive variants: everything integrators.common supports, one at a time and together
VARIANTS = {
    "undamped": {},
    "viscous": {"damping": {"viscous": {"damping_ratio": 0.05}}},
    "dashpot": {"damping": {"dashpot_n_s_per_m": 5.0}},
    "drive+damping": {
        "damping": {"viscous": {"damping_ratio": 0.02}, "dashpot_n_s_per_m": 2.0},
        "excitation": {"kind": "shaker", "end": "left", "frequency_hz": 600.0, "amplitude_n": 20.0,
                       "ramp_cycles": 1.0},
    },
    "prescribed": {
        "excitation": {"kind": "boundary_displacement", "end": "left", "shape": "gaussian",
                       "amplitude_m": 0.002, "duration_s": 5e-4},
    },
}


#: more variants, for the fused Verlet kernels (not in VARIANTS: the order tests stay as they are)
FUSED_VARIANTS = {
    "shaker+viscous": {
        "damping": {"viscous": {"damping_ratio": 0.02}},
        "excitation": {"kind": "shaker", "end": "left", "frequency_hz": 600.0, "amplitude_n": 20.0,
                       "ramp_cycles": 1.0},
    },
}


def chain_problem(n_units: int = 24, integrator: str = "velocity_verlet", variant: str = "undamped", **lattice):
    lat = dict(LEGO, n_units=n_units, **lattice)
    extra = VARIANTS[variant] if variant in VARIANTS else FUSED_VARIANTS[variant]
    if "excitation" in extra:
        lat["left"] = "driven"
    scene = {"name": "t", "lattice": lat, "solver": {"duration_s": 0.01, "integrator": integrator}, **extra}
    return build_problem(scene_from_dict(scene))


def nonlinear_state(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Large rotations (|θ| up to 0.4 rad) with some strain: far from the linear regime."""
    x = np.arange(n)
    q = np.concatenate([0.05 * np.sin(2 * np.pi * x / n), 0.4 * np.exp(-(((x - n / 2) / 3) ** 2))])
    v = np.concatenate([0.02 * np.cos(2 * np.pi * x / n), 0.1 * np.exp(-(((x - n / 3) / 3) ** 2))])
    return q, v


def total_energy(problem, q, v) -> float:
    s = problem.system
    return float(s.energy(q, s.args) + s.kinetic_energy(v))


def verlet_run(advance, problem, q0, v0, steps: int, h: float, calls: int = 1):
    """(q, v, f, t, ledger) after ``calls`` calls of a velocity Verlet advance kernel of ``steps``
    steps each from (q0, v0) at t = 0 (the stepper's init first)."""
    from flexmm.integrators import INTEGRATORS

    spec = INTEGRATORS["velocity_verlet"]
    s, terms = problem.system, problem.terms
    q, v, f, acc = q0.copy(), v0.copy(), np.zeros(s.ndof), spec.new_acc(s.ndof)
    spec.init(s.args, q, v, 0.0, f, terms)
    t = 0.0
    for _ in range(calls):
        t = advance(s.args, q, v, f, s.inv_mass, problem.damp, terms, t, h, steps, acc)
    return q, v, f, t, acc


def assert_same_run(out, ref) -> None:
    """Two ``verlet_run`` results agree: state, force and time bit for bit, the ledger's applied
    work and counters exactly, its dissipation to rounding (a fused kernel sums it by blocks)."""
    import pytest

    from flexmm.integrators.common import ACC_DISSIPATED, ACC_WORK

    for a, b in zip(out[:3], ref[:3]):
        np.testing.assert_array_equal(a, b)
    assert out[3] == ref[3]
    acc, acc_ref = out[4], ref[4]
    assert acc[ACC_WORK] == acc_ref[ACC_WORK]
    assert acc[ACC_DISSIPATED] == pytest.approx(acc_ref[ACC_DISSIPATED], rel=1e-13, abs=0)
    np.testing.assert_array_equal(acc[ACC_WORK + 1 :], acc_ref[ACC_WORK + 1 :])  # counters
