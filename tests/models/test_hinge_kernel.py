"""Compiled model kernels against oracles: −∇E by finite differences, the numpy reference,
translation invariance and the rest state.

Every kind in ``flexmm.models.MODELS`` is checked with the examples of
``tests/conftest.py::EXAMPLE_LATTICES``; the rotating-squares chain is also checked against
its energy written out from docs/physics.md §1.1 (independent of ``flexmm.models.hinge``).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from flexmm.models import MODELS

N_STATES = 3
FD_STEP = 1e-6


def build(example_lattice, scene_dict, make_scene):
    kind, example = example_lattice
    scene = make_scene(scene_dict(example["lattice"]))
    return MODELS[kind].build(scene.lattice), example


def random_state(system, rng) -> np.ndarray:
    """Random q of moderate size: lengths ~0.05 (in the model's length unit), angles ~0.25 rad."""
    q = np.zeros(system.ndof)
    for k, f in enumerate(system.fields):
        sl = slice(k * system.n_sites, (k + 1) * system.n_sites)
        q[sl] = rng.normal(0.0, 0.05 if f.kind == "length" else 0.25, system.n_sites)
    return q


def forces(system, q) -> np.ndarray:
    out = np.full(system.ndof, np.nan)
    system.force(q, system.args, out)
    return out


def test_force_is_minus_energy_gradient(example_lattice, scene_dict, make_scene):
    system, _ = build(example_lattice, scene_dict, make_scene)
    rng = np.random.default_rng(11)
    for _ in range(N_STATES):
        q = random_state(system, rng)
        f = forces(system, q)
        grad = np.empty(system.ndof)
        for k in range(system.ndof):
            qp, qm = q.copy(), q.copy()
            qp[k] += FD_STEP
            qm[k] -= FD_STEP
            grad[k] = (system.energy(qp, system.args) - system.energy(qm, system.args)) / (2 * FD_STEP)
        # central differences: truncation ~ h² E''' ~ 1e-12, round-off ~ 1e-16 |E| / h
        tol = 1e-6 * np.max(np.abs(f)) + 1e-9
        assert np.max(np.abs(f + grad)) < tol, np.max(np.abs(f + grad))


def test_compiled_kernel_matches_numpy_reference(example_lattice, scene_dict, make_scene):
    system, _ = build(example_lattice, scene_dict, make_scene)
    assert system.reference is not None, f"model {system.model} has no numpy reference"
    rng = np.random.default_rng(12)
    for _ in range(N_STATES):
        q = random_state(system, rng)
        f = forces(system, q)
        e_ref, f_ref = system.reference(q, system.args)
        e = system.energy(q, system.args)
        assert e == pytest.approx(e_ref, rel=1e-12, abs=1e-15)
        np.testing.assert_allclose(f, f_ref, rtol=0, atol=1e-12 * np.max(np.abs(f_ref)) + 1e-15)


def test_internal_forces_sum_to_zero(example_lattice, scene_dict, make_scene):
    """Free ends, no on-site terms: a rigid translation costs nothing, so Σ F = 0 per length field."""
    system, example = build(example_lattice, scene_dict, make_scene)
    if not example["translation_invariant"]:
        pytest.skip("example has on-site terms")
    rng = np.random.default_rng(13)
    for _ in range(N_STATES):
        q = random_state(system, rng)
        f = forces(system, q)
        e = system.energy(q, system.args)
        for k, fs in enumerate(system.fields):
            if fs.kind != "length":
                continue
            sl = slice(k * system.n_sites, (k + 1) * system.n_sites)
            assert abs(f[sl].sum()) < 1e-12 * np.sum(np.abs(f[sl])) + 1e-15
            shifted = q.copy()
            shifted[sl] += 0.37
            assert system.energy(shifted, system.args) == pytest.approx(e, rel=1e-12, abs=1e-15)


def test_rest_state_has_zero_energy_and_force(example_lattice, scene_dict, make_scene, request):
    system, example = build(example_lattice, scene_dict, make_scene)
    if example.get("not_at_rest"):
        request.applymarker(pytest.mark.xfail(reason=example["not_at_rest"], strict=True))
    q = np.zeros(system.ndof)
    assert abs(system.energy(q, system.args)) < 1e-28  # zero up to rounding of the hinge rest lengths
    assert np.max(np.abs(forces(system, q))) < 1e-14


# ------------------------------------------------------- rotating chain vs docs/physics.md §1.1
def documented_chain_energy(cfg, u_m: np.ndarray, theta: np.ndarray) -> float:
    """Total energy (J) of the chain of docs/physics.md §1.1 with uniform θ0, written from the text.

    E = Σ_hinges ½k_l Δx² + ½k_s Δy² + ½k_θ Δφ² + Σ_units n_v [s_v k_l a² G²/4 + k_θ θ²],
    Δx = u_{i+1} − u_i + a cosθ0 − (a/2)[cos(θ0+θ_i) + cos(θ0+θ_{i+1})],
    Δy = (a/2)[sin(θ0+θ_{i+1}) − sin(θ0+θ_i)], Δφ = θ_i + θ_{i+1}, G = cosθ0 − cos(θ0+θ).
    """
    a, t0 = cfg.a_m, cfg.theta0_rad
    c, s = np.cos(t0 + theta), np.sin(t0 + theta)
    dx = np.diff(u_m) + a * math.cos(t0) - 0.5 * a * (c[:-1] + c[1:])
    dy = 0.5 * a * np.diff(s)
    dphi = theta[:-1] + theta[1:]
    hinges = 0.5 * (cfg.k_long_n_per_m * dx**2 + cfg.k_shear_n_per_m * dy**2 + cfg.k_rot_n_m_per_rad * dphi**2)
    g = math.cos(t0) - c
    lateral = cfg.n_lateral * (int(cfg.lateral_stretch) * cfg.k_long_n_per_m * a * a * g**2 / 4
                               + cfg.k_rot_n_m_per_rad * theta**2)
    return float(hinges.sum() + lateral.sum())


@pytest.mark.parametrize("name", ["lego-theta0-nv1", "sheet-wave-nv2-sv", "single-row-stiff"])
def test_chain_energy_matches_the_documented_energy(name, example_lattices, scene_dict, make_scene):
    scene = make_scene(scene_dict(example_lattices["rotating_squares_chain"][name]["lattice"]))
    cfg = scene.lattice
    system = MODELS[cfg.kind].build(cfg)
    n, sc = system.n_sites, system.scales
    rng = np.random.default_rng(14)
    for _ in range(N_STATES):
        q = random_state(system, rng)
        u_m = q[system.dof("u", 0) : system.dof("u", 0) + n] * sc.coordinate("length")
        theta = q[system.dof("theta", 0) : system.dof("theta", 0) + n]
        expected = documented_chain_energy(cfg, u_m, theta)
        assert system.energy(q, system.args) * sc.energy == pytest.approx(expected, rel=1e-12)
