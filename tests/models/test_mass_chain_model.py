"""Chains, networks and grids of masses: kernels against the numpy reference and −∇E, configs."""

import numpy as np
import pytest

from flexmm.config import ConfigError, scene_from_dict
from flexmm.assemble import build_problem
from flexmm.models import MODELS
from flexmm.models.mass_params import raney_coefficients

BOND = {"law": "polynomial", "k1_n_per_m": 50.0, "k2_n_per_m2": 2e3, "k3_n_per_m3": 1e4}
ONSITE = [{"law": "bistable_cubic", "alpha_n_per_m3": 3e6, "beta": 0.3, "jump_m": 0.004},
          {"law": "sine", "amplitude_j": 1e-4, "period_m": 0.02, "offset_m": 0.001}]
BASE = {"spacing_m": 0.01, "mass_kg": 0.002, "bond": BOND, "onsite": ONSITE}

LATTICES = {
    "mass_chain": {**BASE, "kind": "mass_chain", "n_units": 12,
                   "bond2": {"law": "dipole", "distance_m": 0.02, "moment_a_m2": 0.05}},
    "mass_network": {**BASE, "kind": "mass_network", "junctions": [{"name": "J", "mass_kg": 0.004}],
                     "branches": [{"name": "a", "n_units": 4, "end": "J"},
                                  {"name": "b", "n_units": 3, "end": "J"},
                                  {"name": "out", "n_units": 5, "start": "J"}],
                     "left": ["a", "b"], "right": ["out"],
                     "bond2": {"law": "linear", "k_n_per_m": 5.0}},
    "mass_grid": {**BASE, "kind": "mass_grid", "nx": 4, "ny": 3,
                  "bond": {"law": "toda", "a_n": 0.5, "b_per_m": 100.0}},
}


def scene(lattice, **extra):
    return scene_from_dict({"name": "t", "lattice": lattice, "solver": {"duration_s": 0.01}, **extra})


def system_of(lattice):
    cfg = scene(lattice).lattice
    return MODELS[cfg.kind].build(cfg)


def test_every_mass_model_is_covered():
    assert {k for k in MODELS if k.startswith("mass_")} == set(LATTICES)


@pytest.mark.parametrize("kind", sorted(LATTICES))
def test_mass_chain_compiled_matches_reference_and_gradient(kind):
    s = system_of(LATTICES[kind])
    rng = np.random.default_rng(3)
    q = rng.normal(0.0, 0.05, s.ndof)
    f = np.zeros(s.ndof)
    s.force(q, s.args, f)
    e_ref, f_ref = s.reference(q, s.args)
    assert s.energy(q, s.args) == pytest.approx(e_ref, rel=1e-12, abs=1e-14)
    np.testing.assert_allclose(f, f_ref, rtol=1e-10, atol=1e-12)
    h = 1e-6
    for k in range(s.ndof):
        dq = np.zeros(s.ndof)
        dq[k] = h
        g = (s.energy(q + dq, s.args) - s.energy(q - dq, s.args)) / (2 * h)
        assert -g == pytest.approx(f[k], rel=1e-6, abs=1e-8)


@pytest.mark.parametrize("kind", sorted(LATTICES))
def test_mass_chain_bond_forces_sum_to_zero(kind):
    s = system_of({**LATTICES[kind], "onsite": []})
    q = np.random.default_rng(4).normal(0.0, 0.05, s.ndof)
    f = np.zeros(s.ndof)
    s.force(q, s.args, f)
    assert abs(f.sum()) < 1e-12 * (1 + np.abs(f).max())


def test_mass_chain_relaxed_state_is_an_equilibrium_and_q_is_measured_from_it():
    lat = {**BASE, "kind": "mass_chain", "n_units": 12, "onsite": ONSITE[:1],
           "initial_displacement_m": 0.0035, "static_load_n": 0.01}
    s = system_of(lat)
    f = np.zeros(s.ndof)
    s.force(np.zeros(s.ndof), s.args, f)
    assert np.abs(f).max() < 1e-8
    x0 = s.initial_displacement_m
    assert np.all(np.abs(x0 - 0.004) < 2e-4)  # every site in the lower-energy well at L = 4 mm
    assert x0[0] > x0[5] > x0[-1]  # the static end load compresses the chain


def test_mass_chain_raney_law_reproduces_the_measured_polynomial():
    lat = {"kind": "mass_chain", "n_units": 2, "spacing_m": 0.02, "mass_kg": 0.003, "relax": False,
           "bond": {"law": "linear", "k_n_per_m": 1e-9},
           "onsite": [{"law": "raney2016", "d_mm": 16.0}]}
    s = system_of(lat)
    c = np.array(raney_coefficients(16.0))[0]
    for x_mm in (0.5, 3.0, 7.0):
        q = np.full(2, x_mm * 1e-3 / s.scales.length_m)
        e_si = s.energy(q, s.args) * s.scales.energy
        psi = sum(c[k] * x_mm ** (k + 1) for k in range(8)) * 1e-3  # mJ -> J
        assert e_si == pytest.approx(2 * psi, rel=1e-9)


def test_mass_chain_variation_gradient_defects_random():
    lat = {**LATTICES["mass_chain"], "relax": False, "variation": [
        {"kind": "gradient", "target": "bond.k1_n_per_m", "start": 10.0, "end": 120.0},
        {"kind": "defects", "target": "mass_kg", "sites": [3, 7], "factor": 2.0},
        {"kind": "random", "target": "onsite.0.alpha_n_per_m3", "relative_std": 0.1, "seed": 1},
    ]}
    s = system_of(lat)
    k1 = s.args[3][:11, 2] * 2 * s.scales.energy / s.scales.length_m**2
    ramp = np.linspace(10.0, 120.0, 12)  # over the 12 sites; bond b takes the mean of its sites b, b + 1
    np.testing.assert_allclose(k1, (ramp[:-1] + ramp[1:]) / 2)
    assert s.mass[3] == 2 * s.mass[0] and s.mass[7] == 2 * s.mass[0]
    again = system_of(lat)
    np.testing.assert_array_equal(s.args[6], again.args[6])  # same seed, same scatter


def test_mass_chain_config_errors_are_readable():
    with pytest.raises(ConfigError, match="variation.0.target = bond.k9: not a parameter"):
        scene({**LATTICES["mass_chain"],
               "variation": [{"kind": "defects", "target": "bond.k9", "sites": [0], "value": 1.0}]})
    with pytest.raises(ConfigError, match="unknown junction"):
        scene({**LATTICES["mass_network"], "branches": [{"name": "a", "n_units": 3, "end": "K"}]})
    with pytest.raises(ConfigError, match="law"):
        scene({**LATTICES["mass_chain"], "bond": {"law": "spring", "k_n_per_m": 1.0}})


def test_mass_grid_shape_is_rows_by_columns():
    s = system_of(LATTICES["mass_grid"])  # nx = 4 columns, ny = 3 rows
    assert s.grid_shape == (3, 4)
    row, col = np.divmod(np.arange(s.n_sites), 4)
    np.testing.assert_allclose(s.site_coords["x"], col * 0.01)
    np.testing.assert_allclose(s.site_coords["y"], row * 0.01)
    assert system_of(LATTICES["mass_chain"]).grid_shape is None


def test_mass_network_ends_and_dashpots_follow_the_branches():
    sc = scene(LATTICES["mass_network"], damping={"dashpot_n_s_per_m": 0.01},
               excitation={"kind": "impact", "velocity_m_s": 0.1})
    p = build_problem(sc)
    s = p.system
    assert s.ends["left"] == [0, 4] and s.ends["right"] == [11]
    assert np.count_nonzero(s.v0) == 2
    assert len(p.terms.dash_ij) == len(s.neighbour_pairs) == 12


def test_mass_chain_friction_enters_as_explicit_drive_and_limits_dt():
    lat = {**LATTICES["mass_chain"], "friction": {"force_n": 0.02, "regularisation_m_s": 1e-4}}
    p = build_problem(scene(lat))
    rows = p.terms.drv_mode == 2
    assert rows.sum() == 12
    rate = 0.02 / (0.002 * 1e-4) * p.system.scales.time_s
    assert p.stable_dt <= 1.0 / rate * (1 + 1e-12)


def test_mass_chain_without_rotation_rejects_rotation_imperfection():
    sc = scene(LATTICES["mass_chain"], imperfection={"kind": "rotation_seed", "theta_rad": 0.01})
    with pytest.raises(ValueError, match="rotation field"):
        build_problem(sc)
