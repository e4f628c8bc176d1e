"""Predeformed equilibria: the Newton polish of ``models.predeform`` and exact gradients through them.

Oracles: the residual force of the polished equilibrium (round-off, not FIRE's tolerance), the
dense Hessian's spectrum (where it is indefinite the polish must keep FIRE's state), Richardson
extrapolated central differences of the scene builder for the implicit-function derivative of
the equilibrium (``design.equilibrium``), and central differences of whole runs for the chained
gradient (``--check-gradient``) w.r.t. k_θ, the end loads and the applied strain.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest
import yaml
from conftest import LEGO_CHAIN

from flexmm.config import ConfigError, scene_from_dict
from flexmm.design.kernels import model_tangent
from flexmm.design.optimize import check_gradient, load_design
from flexmm.design.variables import Design, Variable, _unflat
from flexmm.linalg import dense_matrix, force_hessian
from flexmm.models import MODELS
from flexmm.models.predeform import hessian

SHEET = {"kind": "rotating_squares_sheet", "a_m": 0.01, "k_long_n_per_m": 1e4, "k_shear_n_per_m": 3e3,
         "k_rot_n_m_per_rad": 2e-4, "areal_density_kg_m2": 20.0, "theta0_rad": 0.1}
LOADS = {"loads": [{"end": "left", "force_n": 0.2}, {"end": "right", "force_n": 0.2}], "theta_guess_rad": 0.1}
LATTICES = {
    # past buckling (F_c = 4 k_θ/a ≈ 0.18 N), both ends free: a free translation along x
    "chain-loaded": dict(LEGO_CHAIN, n_units=10, theta0_rad=0.05, predeform=LOADS),
    "chain-strained": dict(LEGO_CHAIN, n_units=10, theta0_rad=0.05, predeform={"strain_x": -0.01,
                                                                              "theta_guess_rad": 0.1}),
    # x held by the strain, y free: a free translation along y
    "sheet-strained": dict(SHEET, n_rows=3, n_cols=4, predeform={"strain_x": -0.02}),
    "sheet-loaded": dict(SHEET, n_rows=3, n_cols=4, left="fixed",
                         predeform={"loads": [{"end": "right", "force_n": 0.5}]}),
}


def _build(lattice: dict, newton: bool = True):
    lattice = copy.deepcopy(lattice)
    lattice["predeform"]["newton"] = newton
    scene = scene_from_dict({"name": "t", "lattice": lattice, "solver": {"duration_s": 1e-3}})
    return MODELS[lattice["kind"]].build(scene.lattice)


def _residual(system) -> float:
    f = np.empty(system.ndof)
    system.force(system.q0, system.args, f)
    return float(np.abs(f[system.predeformation.free]).max())


@pytest.mark.parametrize("name", list(LATTICES))
def test_newton_polish_reaches_round_off_at_fires_equilibrium(name):
    fire, polished = _build(LATTICES[name], newton=False), _build(LATTICES[name])
    pf, pp = fire.predeformation, polished.predeformation
    assert pf.newton_steps == 0 and pp.newton_steps > 0
    assert pf.residual > 1e-13  # FIRE stops below its tolerance (1e-10), far above round-off
    assert _residual(polished) == pp.residual < 1e-14
    moved = np.abs(polished.q0 - fire.q0).max()
    assert 0.0 < moved < 1e-4  # the same equilibrium, FIRE's error removed
    assert pp.energy <= pf.energy + 1e-12 * abs(pf.energy)
    n = polished.n_sites
    free_axis = {"chain-loaded": 0, "sheet-strained": 1}.get(name)  # the field nothing holds
    if free_axis is not None:  # FIRE conserves its mean (zero here); the polish restores it
        assert abs(polished.q0[free_axis * n : (free_axis + 1) * n].sum()) < 1e-13


@pytest.mark.parametrize("name", ["chain-loaded", "sheet-strained"])
def test_coloured_hessian_equals_the_dense_one(name):
    """The sparse Hessian from nine colourings of the units equals the one assembled column by
    column (both central differences of the force along unit vectors or their sums)."""
    system = _build(LATTICES[name])
    free = system.predeformation.free
    dense = dense_matrix(force_hessian(system.force, system.args, system.q0), system.ndof, free)
    coloured = hessian(system, system.q0, free).toarray()
    assert np.abs(coloured - dense).max() < 1e-8 * np.abs(dense).max()


def test_polish_keeps_fires_state_where_the_hessian_is_indefinite():
    """A free sheet under balanced compressive end loads may rotate as a whole (the dead loads do
    work on a rotation): its Hessian has a negative eigenvalue, and the polish must keep FIRE's
    state bit for bit."""
    lattice = dict(SHEET, n_rows=4, n_cols=6, predeform=LOADS | {"theta_guess_rad": 0.0})
    fire, polished = _build(lattice, newton=False), _build(lattice)
    free = polished.predeformation.free
    K = dense_matrix(force_hessian(polished.force, polished.args, polished.q0), polished.ndof, free)
    assert np.linalg.eigvalsh(K)[0] < -1e-6
    assert polished.predeformation.newton_steps == 0
    assert np.array_equal(polished.q0, fire.q0)


@pytest.mark.parametrize("name, variables", [
    ("chain-loaded", [{"name": "k_rot", "target": "k_rot_n_m_per_rad", "initial": 7.038e-4},
                      {"name": "load", "path": "lattice.predeform.loads.*.force_n", "initial": 0.2}]),
    ("chain-strained", [{"name": "k_rot", "target": "k_rot_n_m_per_rad", "initial": 7.038e-4},
                        {"name": "strain", "path": "lattice.predeform.strain_x", "initial": -0.01}]),
    ("sheet-strained", [{"name": "k_rot", "target": "k_rot_n_m_per_rad", "initial": 2e-4},
                        {"name": "strain", "path": "lattice.predeform.strain_x", "initial": -0.02}]),
    ("sheet-loaded", [{"name": "theta0", "target": "theta0_rad", "profile": "linear", "initial": [0.08, 0.12]},
                      {"name": "load", "path": "lattice.predeform.loads.0.force_n", "initial": 0.5}]),
])
def test_equilibrium_derivative_matches_extrapolated_builder_differences(name, variables):
    """The Jacobian rows of q0 (implicit function theorem) against Richardson-extrapolated
    central differences of the builder (steps 2e-4 and 1e-4 relative: truncation O(h⁴)), and
    the linearised equilibrium (∂F/∂q) δq + (∂F/∂p) δp = 0 on the free DOFs to rounding (the
    builder's plain differences leave ~1e-8 of the parameter term there)."""
    scene = {"name": "t", "lattice": LATTICES[name], "solver": {"duration_s": 1e-3}}
    des = Design(scene, [Variable(**v) for v in variables])
    x0 = des.x0
    system = des.build(x0)[0]
    free = system.predeformation.free
    J = des.jacobian_matrix(x0).toarray()
    for k in range(x0.size):
        col = _unflat(J[:, k], des.template)
        exact = col.q0
        held, r = np.where(np.isin(np.arange(exact.size), free), 0.0, exact), np.empty(exact.size)
        model_tangent(system.q0, system.args, held, col.t1, col.t2, r)  # the parameters' and held DOFs' part
        scale = np.abs(r[free]).max()
        model_tangent(system.q0, system.args, exact, col.t1, col.t2, r)
        assert np.abs(r[free]).max() < 1e-11 * scale, des.labels[k]

        def diff(rel, k=k):
            h = rel * abs(x0[k])
            xp, xm = x0.copy(), x0.copy()
            xp[k] += h
            xm[k] -= h
            return (des.raw(xp).q0 - des.raw(xm).q0) / (2 * h)

        richardson = (4 * diff(1e-4) - diff(2e-4)) / 3
        assert np.abs(exact).max() > 0
        assert np.abs(richardson - exact).max() < 1e-7 * np.abs(exact).max(), des.labels[k]


def _spec(tmp_path, lattice: dict, excitation: dict, variables: list, duration: float) -> str:
    spec = {"name": "equilibrium", "scene": {"name": "s", "lattice": lattice, "excitation": excitation,
                                              "solver": {"duration_s": duration}},
            "variables": variables, "objective": [{"kind": "energy", "region": {"end": "right"}}]}
    path = tmp_path / "spec.yaml"
    path.write_text(yaml.safe_dump(spec, sort_keys=False))
    return str(path)


@pytest.mark.parametrize("name, excitation, variables, duration", [
    ("chain-strained", {"kind": "boundary_force", "end": "left", "shape": "half_sine", "amplitude_n_m": 1e-4,
                        "duration_s": 0.003},
     [{"name": "strain", "path": "lattice.predeform.strain_x", "initial": -0.01, "bounds": [-0.05, 0.0]}], 0.008),
    ("sheet-strained", {"kind": "kicks", "kicks": [{"sites": [5], "angular_velocity_rad_s": 20.0}]},
     [{"name": "k_rot", "target": "k_rot_n_m_per_rad", "initial": 2e-4, "bounds": [1e-5, 1e-3]},
      {"name": "strain", "path": "lattice.predeform.strain_x", "initial": -0.02, "bounds": [-0.1, 0.0]}], 0.01),
])
def test_whole_run_gradient_through_a_strained_equilibrium(tmp_path, name, excitation, variables, duration):
    """Adjoint of the run chained with the equilibrium's exact derivative, against central
    differences of whole runs (each rebuilding and relaxing the lattice). The loaded chain's
    k_θ and end loads: ``test_gradient_models.test_check_gradient_cli_on_each_model``."""
    labels, _, _, err = check_gradient(load_design(_spec(tmp_path, LATTICES[name], excitation, variables, duration)))
    assert np.all(err <= 1e-6), dict(zip(labels, err))


@pytest.mark.parametrize("path, detail", [
    ("lattice.predeform.loads.2.force_n", "not an element of a list of 2"),
    ("lattice.predeform.loads.0", "a list element is not a scalar"),
])
def test_bad_list_paths_name_the_variable(tmp_path, path, detail):
    spec = _spec(tmp_path, LATTICES["chain-loaded"], {"kind": "none"},
                 [{"name": "load", "path": path, "initial": 0.2}], 0.001)
    with pytest.raises(ConfigError, match=rf"variables\[0\]\.path: .*{detail}"):
        load_design(spec)
