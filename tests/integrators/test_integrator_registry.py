"""The registry is data: config names, metadata and validation rules agree with it."""

from __future__ import annotations

import math
import typing
from dataclasses import replace

import numpy as np
import pytest
from integrator_helpers import LEGO, chain_problem, nonlinear_state

from flexmm.assemble import SceneError, check_velocity_forces
from flexmm.config import ConfigError, scene_from_dict
from flexmm.config.scene import ADAPTIVE_INTEGRATORS, Solver
from flexmm.integrators import INTEGRATORS, composition, splitting
from flexmm.integrators.parallel import PARALLEL_MIN_SITES, choose_threads


def scene(**solver):
    return {"name": "t", "lattice": dict(LEGO), "solver": {"duration_s": 0.01, **solver}}


def test_config_names_are_the_registry() -> None:
    literal = typing.get_args(Solver.model_fields["integrator"].annotation)
    assert set(literal) == set(INTEGRATORS)
    assert ADAPTIVE_INTEGRATORS == {k for k, v in INTEGRATORS.items() if v.adaptive}


@pytest.mark.parametrize("name", list(INTEGRATORS))
def test_metadata(name) -> None:
    spec = INTEGRATORS[name]
    assert spec.name == name and spec.order >= 2 and spec.description
    assert spec.stability_limit > 0
    assert math.isinf(spec.stability_limit) == spec.implicit
    assert spec.adaptive == (spec.state_size is not None)
    acc = spec.new_acc(10, rtol=1e-6)
    assert acc.shape[0] >= 8 and acc[0] == acc[1] == 0.0


def test_pefrl_coefficients_are_consistent() -> None:
    assert sum(splitting.DRIFTS) == pytest.approx(1.0, abs=1e-15)
    assert sum(splitting.KICKS) == pytest.approx(1.0, abs=1e-15)
    assert splitting.DRIFTS == splitting.DRIFTS[::-1] and splitting.KICKS == splitting.KICKS[::-1]  # symmetric


def test_blanes_moan_coefficients_are_consistent() -> None:
    kicks, drifts = composition.blanes_moan_6()
    assert len(kicks) == 12 and len(drifts) == 11
    assert sum(kicks) == pytest.approx(1.0, abs=1e-14) and sum(drifts) == pytest.approx(1.0, abs=1e-14)
    assert kicks == kicks[::-1] and drifts == drifts[::-1]  # symmetric: time-reversible, even order


def test_every_splitting_runs_one_compiled_loop() -> None:
    """PEFRL and Blanes–Moan bind their coefficients to the one compiled ``splitting_advance``: one
    compilation per model type serves every splitting (a closure per method compiled each anew)."""
    import numba

    from flexmm.integrators.stepper import make_stepper

    problem = chain_problem(8)
    q0, v0 = nonlinear_state(8)
    ends = {}
    for name in ("pefrl", "blanes_moan6"):
        st = make_stepper(problem, name, threads=1, q0=q0, v0=v0)
        assert st.kernel is INTEGRATORS[name].advance
        st.advance(20)
        ends[name] = st.q.copy()
    args_type = numba.typeof(st.args)
    assert len([sig for sig in splitting.splitting_advance.signatures if sig[5] == args_type]) == 1
    assert not np.array_equal(ends["pefrl"], ends["blanes_moan6"])  # each ran its own coefficients


def test_blanes_moan_refuses_velocity_dependent_forces() -> None:
    spec = INTEGRATORS["blanes_moan6"]
    for variant in ("viscous", "dashpot"):
        problem = chain_problem(8, variant=variant)
        with pytest.raises(SceneError, match="depend on velocity"):
            check_velocity_forces(spec, problem.damp, problem.terms, 0.0)
    with pytest.raises(SceneError, match="depend on velocity"):
        from flexmm.assemble import build_problem

        build_problem(scene_from_dict({**scene(integrator="blanes_moan6"),
                                       "damping": {"viscous": {"damping_ratio": 0.05}}}))


def test_tolerances_only_for_adaptive_methods() -> None:
    with pytest.raises(ConfigError, match="solver.rtol applies only to an adaptive integrator"):
        scene_from_dict(scene(integrator="rk4", rtol=1e-6))
    scene_from_dict(scene(integrator="dopri5", rtol=1e-6, atol=1e-9))


def test_unknown_integrator_lists_the_valid_ones() -> None:
    with pytest.raises(ConfigError) as err:
        scene_from_dict(scene(integrator="euler"))
    for name in INTEGRATORS:
        assert name in str(err.value)


def test_velocity_dependent_forces_refused_with_a_reason() -> None:
    """A method declaring forces of q only (an RKN-type scheme) must refuse damping and say why."""
    rkn = replace(INTEGRATORS["pefrl"], name="rkn_test", velocity_dependent_forces=False)
    problem = chain_problem(8, variant="dashpot")
    with pytest.raises(SceneError, match="depend on velocity") as err:
        check_velocity_forces(rkn, problem.damp, problem.terms, 0.0)
    assert "dashpots" in str(err.value) and "Nystrom" in str(err.value)
    check_velocity_forces(rkn, np.zeros_like(problem.damp), chain_problem(8).terms, 0.0)  # undamped: fine


@pytest.mark.parametrize("name", [k for k, v in INTEGRATORS.items() if v.explicit_limit])
def test_dt_above_each_methods_limit_is_refused(name) -> None:
    from flexmm.assemble import build_problem
    from flexmm.stability import UnstableStepError

    ok = build_problem(scene_from_dict(scene(integrator=name)))
    limit_s = ok.stable_dt * ok.system.scales.time_s
    assert ok.stable_dt == pytest.approx(INTEGRATORS[name].stability_limit / ok.omega_max)
    with pytest.raises(UnstableStepError, match=f"stable limit of {name}"):
        build_problem(scene_from_dict(scene(integrator=name, dt_s=1.05 * limit_s)))
    forced = build_problem(scene_from_dict(scene(integrator=name, dt_s=1.05 * limit_s, allow_unstable=True)))
    assert any("WARNING" in n for n in forced.notes)


def test_implicit_and_adaptive_steps() -> None:
    from flexmm.assemble import build_problem

    base = build_problem(scene_from_dict(scene()))
    big = 10 * base.stable_dt * base.system.scales.time_s
    imp = build_problem(scene_from_dict(scene(integrator="implicit_midpoint", dt_s=big)))
    assert math.isinf(imp.stable_dt) and imp.dt == pytest.approx(10 * base.stable_dt)
    auto = build_problem(scene_from_dict(scene(integrator="implicit_midpoint")))
    assert auto.dt == pytest.approx(base.dt)  # dt_fraction × 2/ω_max
    ada = build_problem(scene_from_dict(scene(integrator="dopri5", dt_s=big)))  # dt_s = largest step
    assert ada.dt == pytest.approx(10 * base.stable_dt)


def test_thread_choice() -> None:
    assert choose_threads(1000) == 1
    assert choose_threads(PARALLEL_MIN_SITES) >= 1
    assert choose_threads(10, requested=1) == 1
