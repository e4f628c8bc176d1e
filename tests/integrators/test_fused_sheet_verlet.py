"""Velocity Verlet fused with the sheet force (``verlet.sheet_verlet_advance``) gives the
results of ``verlet_advance`` + ``sheet_force`` bit for bit (the dissipation ledger to
rounding: it is summed by blocks), and is chosen only where it applies."""

from __future__ import annotations

import numpy as np
import pytest
from integrator_helpers import assert_same_run, verlet_run

from flexmm.assemble import build_problem
from flexmm.config import scene_from_dict
from flexmm.integrators import INTEGRATORS
from flexmm.integrators.common import ACC_DISSIPATED, ACC_WORK
from flexmm.integrators.parallel import advance_kernel
from flexmm.integrators.verlet import (
    sheet_fusable,
    sheet_verlet_advance,
    verlet_advance,
)
from flexmm.models.hinge import H_HALF_A, H_KL
from flexmm.models.sheet_kernels import (
    GRID_BLOCK,
    sheet_force,
    sheet_reference,
    uniform_hinges,
)

SHEET = {"kind": "rotating_squares_sheet", "n_rows": 7, "n_cols": 9, "a_m": 0.01, "theta0_rad": 0.35,
         "k_long_n_per_m": 1.0e4, "k_shear_n_per_m": 3.3e3, "k_rot_n_m_per_rad": 7.5e-3, "mass_kg": 1.0e-3,
         "inertia_kg_m2": 8.333333333e-9}
SHAKER = {"kind": "shaker", "end": "left", "frequency_hz": 500.0, "amplitude_n": 2.0, "ramp_cycles": 0.5,
          "duration_s": 0.002}
PULL = {"kind": "boundary_displacement", "end": "left", "shape": "gaussian", "amplitude_m": 0.001,
        "duration_s": 5e-4}


def sheet_problem(rows=7, cols=9, excitation=None, damping=None, **lattice):
    lat = dict(SHEET, n_rows=rows, n_cols=cols, **lattice)
    scene = {"name": "t", "lattice": lat, "solver": {"duration_s": 0.01, "integrator": "velocity_verlet"}}
    if excitation is not None:
        lat["left"] = "driven"
        scene["excitation"] = excitation
    if damping is not None:
        scene["damping"] = damping
    return build_problem(scene_from_dict(scene))


def _advance(advance, problem, q0, v0, steps, calls=1):
    return verlet_run(advance, problem, q0, v0, steps, 0.05, calls)


@pytest.mark.parametrize("shape", [(7, 9), (3, 2 * GRID_BLOCK + 5), (2 * GRID_BLOCK // 40 + 3, 40), (1, 12)])
@pytest.mark.parametrize("case", ["free", "graded", "shaker", "shaker+viscous", "pull"])
def test_fused_sheet_verlet_equals_unfused(shape, case) -> None:
    """Several grid blocks (rows longer than a block, blocks of many rows, a single row), with
    an applied force on the left column, damping and a prescribed displacement; hinges that
    share their parameters (read as scalars) and graded ones (read from the table)."""
    excitation = {"free": None, "graded": None, "shaker": SHAKER, "shaker+viscous": SHAKER, "pull": PULL}[case]
    damping = {"viscous": {"damping_ratio": 0.05}} if "viscous" in case else None
    problem = sheet_problem(*shape, excitation=excitation, damping=damping)
    s = problem.system
    uniform = uniform_hinges(s.args.hinge_prm)
    assert uniform[0] == uniform[0]
    if case == "graded":
        s.args.hinge_prm[:, H_KL] *= np.linspace(0.8, 1.2, s.args.hinge_prm.shape[0])
        s.args.hinge_prm[::3, H_HALF_A] *= 1.01
        uniform = uniform_hinges(s.args.hinge_prm)
        assert uniform[0] != uniform[0]
    assert sheet_fusable(s.args, s.q0, s.inv_mass, problem.damp, problem.terms)
    rng = np.random.default_rng(3)
    q0, v0 = 0.02 * rng.standard_normal(s.ndof), 0.02 * rng.standard_normal(s.ndof)
    ref = _advance(verlet_advance, problem, q0, v0, 10, calls=3)  # same calls: a call ends with
    out = _advance(sheet_verlet_advance, problem, q0, v0, 10, calls=3)  # a half kick (rounding)
    assert_same_run(out, ref)
    assert (ref[4][ACC_WORK] != 0.0) == (excitation is not None)  # a prescribed pull works too
    assert (ref[4][ACC_DISSIPATED] != 0.0) == ("viscous" in case)


@pytest.mark.parametrize("shape", [(6, 10), (4, 2 * GRID_BLOCK + 6), (60, 40)])
@pytest.mark.parametrize("edges", [{}, {"left": "periodic", "right": "periodic"},
                                   {"bottom": "periodic", "top": "periodic"}])
def test_grid_sheet_force_matches_reference(shape, edges) -> None:
    """The grid path (with its wraps on periodic edges) against the numpy reference, and against
    the scattered loop on the same hinges listed in another order (no grid layout)."""
    s = sheet_problem(*shape, **edges).system
    q = 0.05 * np.random.default_rng(5).standard_normal(s.ndof)
    f = np.zeros(s.ndof)
    sheet_force(q, s.args, f)
    _, f_ref = sheet_reference(q, s.args)
    np.testing.assert_allclose(f, f_ref, rtol=0, atol=1e-13 * np.max(np.abs(f_ref)))
    perm = np.random.default_rng(6).permutation(s.args.hinge_a.shape[0])
    shuffled = s.args._replace(hinge_a=s.args.hinge_a[perm], hinge_b=s.args.hinge_b[perm],
                               hinge_axis=s.args.hinge_axis[perm], hinge_prm=s.args.hinge_prm[perm])
    g = np.zeros(s.ndof)
    sheet_force(q, shuffled, g)
    np.testing.assert_allclose(g, f, rtol=0, atol=1e-13 * np.max(np.abs(f_ref)))


def test_fused_sheet_kernel_is_picked_only_where_it_applies() -> None:
    spec = INTEGRATORS["velocity_verlet"]

    def pick(p, threads=1):
        return advance_kernel(spec, p.system.args, p.system.inv_mass, p.damp, p.terms, threads)

    assert pick(sheet_problem(excitation=SHAKER))[0] is sheet_verlet_advance
    assert pick(sheet_problem(excitation=SHAKER), 2) == (sheet_verlet_advance, 1)  # no threaded variant
    periodic = sheet_problem(6, 10, left="periodic", right="periodic")
    assert not sheet_fusable(periodic.system.args, periodic.system.q0, periodic.system.inv_mass, periodic.damp,
                             periodic.terms)
    assert pick(periodic)[0] is spec.advance
    dashpot = sheet_problem(damping={"dashpot_n_s_per_m": 1.0})
    assert pick(dashpot)[0] is spec.advance
    assert advance_kernel(INTEGRATORS["pefrl"], dashpot.system.args, dashpot.system.inv_mass, dashpot.damp,
                          dashpot.terms, 1)[0] is INTEGRATORS["pefrl"].advance


@pytest.mark.parametrize("graded", [False, True])
def test_stepper_keeps_the_sheet_tables_and_matches_unfused(graded) -> None:
    """A Stepper builds the fused sheet kernel's tables once (``sheet_prepare``) and keeps them
    over calls; the trajectory is still ``verlet_advance``'s, bit for bit."""
    from flexmm.integrators.stepper import Stepper

    problem = sheet_problem(2 * GRID_BLOCK // 40 + 3, 40, excitation=SHAKER)
    s = problem.system
    if graded:
        s.args.hinge_prm[:, H_KL] *= np.linspace(0.8, 1.2, s.args.hinge_prm.shape[0])
    rng = np.random.default_rng(4)
    q0, v0 = 0.02 * rng.standard_normal(s.ndof), 0.02 * rng.standard_normal(s.ndof)
    s.q0[:], s.v0[:] = q0, v0
    st = Stepper(INTEGRATORS["velocity_verlet"], s, problem.terms, problem.damp, 0.05, threads=1, check_energy=False)
    assert st.kernel.__name__ == "sheet_verlet_advance"
    st.advance(10)
    tables = st.kernel.tables
    for _ in range(2):
        st.advance(10)
    assert st.kernel.tables is tables
    ref = _advance(verlet_advance, problem, q0, v0, 10, calls=3)
    for a, b in zip((st.q, st.v, st.f), ref[:3]):
        np.testing.assert_array_equal(a, b)
