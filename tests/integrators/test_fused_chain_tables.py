"""The fused chain Verlet's prepared tables: blocks where only the site columns vary run the
variant with scalar hinges and factors, and a Stepper keeps its tables from call to call (built
again when h changes); either way the trajectory is the unfused stepper's, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest
from integrator_helpers import assert_same_run, chain_problem, verlet_run

from flexmm.integrators import INTEGRATORS
from flexmm.integrators.common import apply_prescribed
from flexmm.integrators.stepper import Stepper
from flexmm.integrators.verlet import verlet_advance
from flexmm.integrators.verlet_chain import (
    RANGE_MIN,
    chain_verlet_advance_prepared,
    prepare,
)
from flexmm.models.hinge import BLOCK, S_KG, S_KR, S_THETA0


def _grade_sites(s) -> None:
    """Lateral torsion graded along the chain, a lateral-stretch patch and a rest-angle defect:
    only site columns vary (hinges and masses uniform)."""
    s.args[3][:, S_KR] *= np.linspace(1.5, 0.5, s.n_sites)
    s.args[3][BLOCK + 10 : BLOCK + 400, S_KG] *= 1.2
    s.args[3][2 * BLOCK + 7, S_THETA0] += 0.01


@pytest.mark.parametrize("variant", ["undamped", "shaker+viscous"])
def test_site_graded_blocks_run_with_scalar_hinges_and_match_unfused(variant) -> None:
    problem = chain_problem(2 * RANGE_MIN + 321, variant=variant, theta0_rad=0.2, n_lateral=2,
                            lateral_stretch=True, right="fixed")
    s = problem.system
    _grade_sites(s)
    tables = prepare(s.args, s.inv_mass, problem.damp, 0.1)
    uniform, hinges_uniform = tables[5], tables[6]
    assert not uniform[1:-1].any() and hinges_uniform[1:-1].all()  # the scalar-hinge variant
    rng = np.random.default_rng(11)
    q0, v0 = 0.05 * rng.standard_normal(s.ndof), 0.05 * rng.standard_normal(s.ndof)
    ref = verlet_run(verlet_advance, problem, q0, v0, 40, 0.1)
    out = verlet_run(lambda *call: chain_verlet_advance_prepared(tables, *call), problem, q0, v0, 40, 0.1)
    assert_same_run(out, ref)


def test_stepper_keeps_its_tables_and_rebuilds_them_when_h_changes() -> None:
    problem = chain_problem(RANGE_MIN + 77, variant="shaker+viscous", theta0_rad=0.2, n_lateral=2)
    s = problem.system
    _grade_sites(s)
    spec = INTEGRATORS["velocity_verlet"]
    st = Stepper(spec, s, problem.terms, problem.damp, 0.1, threads=1, check_energy=False)
    st.advance(5)
    tables = st.kernel.tables
    assert tables is not None
    st.advance(5)
    assert st.kernel.tables is tables  # kept
    st.h = 0.05
    st.advance(6)
    assert st.kernel.tables is not tables  # h changed: rebuilt
    q, v, f, acc = s.q0.copy(), s.v0.copy(), np.zeros(s.ndof), spec.new_acc(s.ndof)
    apply_prescribed(q, v, 0.0, *problem.terms.drives)
    spec.init(s.args, q, v, 0.0, f, problem.terms)
    t = 0.0
    for h, n in ((0.1, 5), (0.1, 5), (0.05, 6)):
        t = verlet_advance(s.args, q, v, f, s.inv_mass, problem.damp, problem.terms, t, h, n, acc)
    for a, b in ((st.q, q), (st.v, v), (st.f, f)):
        np.testing.assert_array_equal(a, b)
    assert st.t == t
