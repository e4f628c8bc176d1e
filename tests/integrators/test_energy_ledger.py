"""Runaways fail: the energy ledger (E − E0 − W + D) of every run is checked at its frames.

W is accumulated by the integrators along the run, including the work of prescribed
displacements (−f·v on the driven DOF); these tests close the ledger from the kernels' own
energies, so a missing or wrong work term shows up as an imbalance.
"""

from __future__ import annotations

import pytest

from flexmm.assemble import build_problem
from flexmm.config import load_scene
from flexmm.controller import schedule
from flexmm.integrators.stepper import make_stepper


def _worst_imbalance(scene, integrator: str, frames: int = 21) -> tuple[float, object, object]:
    p = build_problem(scene)
    from flexmm.accuracy import stable_step
    from flexmm.integrators import INTEGRATORS

    h = 0.1 * stable_step(p, INTEGRATORS[integrator])
    st = make_stepper(p, integrator, h=h)
    worst = [0.0]

    def frame(s) -> None:
        e = sum(s.energies())  # of the free DOFs: a prescribed DOF's ½ m v² is not the system's
        worst[0] = max(worst[0], s.guard.imbalance(e, s.ledger.work, s.ledger.dissipated))

    out = st.run(schedule(p.duration, h, frames, None).chunks, frame)
    return worst[0], out, st


@pytest.mark.parametrize("integrator", ["velocity_verlet", "pefrl", "rk4"])
def test_prescribed_displacement_work_closes_the_ledger(integrator) -> None:
    # a half-sine boundary displacement pushes into a softening chain and returns: all the energy
    # in the chain came from the prescribed displacement's work
    scene = load_scene("configs/d_origami_rarefaction_overtakes.yaml",
                       ["lattice.n_units=30", "solver.duration_s=0.3", "solver.accuracy=null"])
    worst, out, st = _worst_imbalance(scene, integrator)
    assert out.ok
    assert st.ledger.work > 0
    # without the prescribed work it is 1 (E grows, W = 0)
    assert worst < 1e-2


def test_damped_driven_run_balances_and_finishes() -> None:
    # Raney chain: bistable elements, damping, driven end: both W and D non-zero
    scene = load_scene("configs/h_raney_transition_wave.yaml", ["solver.accuracy=null"])
    worst, out, st = _worst_imbalance(scene, "velocity_verlet")
    assert out.ok, out.reason
    assert st.ledger.dissipated > 0 and st.ledger.work > 0
    assert worst < 1e-2


def test_a_1e6_m_s_impact_fails_with_the_reason(tmp_path) -> None:
    from flexmm.api import run_scene

    scene = load_scene("configs/b_lego_amplitude_gap.yaml",
                       ["excitation.velocity_m_s=1e6", "lattice.n_units=40", "solver.duration_s=0.02",
                        "output.n_frames=21", "solver.accuracy=null"])
    res = run_scene(scene, run_dir=tmp_path / "r")
    assert res.status == "failed"
    assert "energy not conserved" in res.reason and "dt =" in res.reason and "stable limit" in res.reason
    # the same scene struck at 1 m/s is resolved by the same step and finishes
    ok = run_scene(load_scene("configs/b_lego_amplitude_gap.yaml",
                              ["lattice.n_units=40", "solver.duration_s=0.02", "output.n_frames=21",
                               "solver.accuracy=null"]), run_dir=tmp_path / "ok")
    assert ok.ok, ok.reason


def _guard():
    import numpy as np

    from flexmm.integrators.runaway import RunawayGuard

    class System:
        mass = v0 = np.zeros(3)
        n_sites = 3

    class Terms:
        drv_prm = np.zeros((0, 4))

    return RunawayGuard(System, Terms, e0=0.0, drift_tol=0.05)


def test_an_imbalance_must_persist_before_a_run_fails() -> None:
    """The first steps of a drive give O(1) relative imbalances on a tiny budget (the work of a
    drive starting like t² sampled by a few steps); a run fails only when the imbalance lasts."""
    from flexmm.integrators.runaway import PERSIST_CHECKS, RUNAWAY_LAG_STEPS

    g = _guard()
    assert g.unbalanced(1.085e-14, 1e-14, 0.0, step=5) is None  # 8.5 % at the first frame
    assert g.unbalanced(1.0e-10, 1.001e-10, 0.0, step=10) is None  # balanced again: forgotten
    assert g.unbalanced(2.0, 1.0, 0.0, step=20) is None  # a real drift starts ...
    assert g.unbalanced(2.0, 1.0, 0.0, step=20 + RUNAWAY_LAG_STEPS // 2) is None
    assert g.unbalanced(2.0, 1.0, 0.0, step=20 + RUNAWAY_LAG_STEPS - 1) is None
    why = g.unbalanced(2.0, 1.0, 0.0, step=20 + RUNAWAY_LAG_STEPS)  # ... and lasts
    assert why is not None and "imbalance of 1 of the energy budget" in why  # |2 − 0 − 1| / (0 + 1 + 0)
    g = _guard()  # frequent checks: PERSIST_CHECKS in a row within RUNAWAY_LAG_STEPS are not enough
    assert all(g.unbalanced(2.0, 1.0, 0.0, step=k) is None for k in range(1, PERSIST_CHECKS + 3))
    assert g.unbalanced(2.0, 1.0, 0.0, step=1 + RUNAWAY_LAG_STEPS) is not None
    g = _guard()  # two checks far apart: not PERSIST_CHECKS
    assert g.unbalanced(2.0, 1.0, 0.0, step=1) is None and g.unbalanced(2.0, 1.0, 0.0, step=500) is None
    assert g.unbalanced(2.0, 1.0, 0.0, step=900) is not None
    assert _guard().unbalanced(2.0, 1.0, 0.0) is not None  # without a step count: at once
