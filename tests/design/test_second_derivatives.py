"""Second-derivative kernels (flexmm.design.kernels) against differences of the force kernels.

Every model kind with gradient kernels (``design.kernels``, ``design.kernels_extra``): the
Hessian-vector product is checked against central differences of both the compiled force
kernel and the model's numpy reference (``KERNELS[...].reference``); the parameter products
(adjoint and tangent) against central differences of the force in the parameter tables.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from conftest import LEGO_CHAIN, LEGO_SHEET

from flexmm.assemble import build_system
from flexmm.config import scene_from_dict
from flexmm.design.kernels import (
    model_adjoint,
    model_tangent,
    param_tables,
    with_tables,
)
from flexmm.design.kernels_extra import sheet_offsets
from flexmm.models.harmonic import HarmonicArgs
from flexmm.models.hinge import H_SIGN, N_HINGE_PARAMS
from flexmm.models.kernels import kernels_of, model_force

CHAIN = {**LEGO_CHAIN, "n_units": 7, "theta0_rad": 0.2,
         "variation": [{"kind": "gradient", "target": "k_rot_n_m_per_rad", "start": 5e-4, "end": 9e-4}]}
LAWS = {
    "polynomial": {"law": "polynomial", "k1_n_per_m": 100.0, "k2_n_per_m2": 2e3, "k3_n_per_m3": 1e5},
    "toda": {"law": "toda", "a_n": 5.0, "b_per_m": 300.0},
    "hertz": {"law": "hertz", "stiffness_n_per_m_p": 1e7, "exponent": 1.5, "precompression_m": 1e-3},
    "sine": None,
}
SHEET = dict(LEGO_SHEET, n_rows=3, n_cols=4, theta0_rad=0.15)
LATTICES = {"chain": CHAIN,
            "sheet": SHEET,
            "sheet-ligament": dict(SHEET, n_rows=2, ligament_length_m=0.002, theta0_rad=-0.2, bottom="periodic",
                                   top="periodic"),
            "mass-polynomial": {"kind": "mass_chain", "n_units": 7, "spacing_m": 0.01, "mass_kg": 0.01,
                                "bond": LAWS["polynomial"]},
            "mass-toda-sine": {"kind": "mass_chain", "n_units": 7, "spacing_m": 0.01, "mass_kg": 0.01,
                               "bond": LAWS["toda"], "onsite": [{"law": "sine", "amplitude_j": 1e-3,
                                                                   "period_m": 0.02}]},
            "mass-hertz": {"kind": "mass_chain", "n_units": 7, "spacing_m": 0.01, "mass_kg": 0.01,
                           "bond": LAWS["hertz"], "left": "fixed", "right": "fixed"}}
#: configs/j_magnets_transition_wave.yaml's units (a 2 × 3 strip)
MAGNETS = {"kind": "rotating_squares_sheet", "n_rows": 2, "n_cols": 3, "a_m": 0.02, "k_long_n_per_m": 5e4,
           "k_shear_n_per_m": 5e4, "k_rot_n_m_per_rad": 0.01, "mass_kg": 0.005,
           "magnets": {"moment_a_m2": 0.253, "recess_m": 0.003, "polarity": "attract"}}
LOADS = {"loads": [{"end": "left", "force_n": 0.2}, {"end": "right", "force_n": 0.2}], "theta_guess_rad": 0.1}
TRIANGLES = {"a_m": 0.02, "theta0_rad": 0.1, "k_long_n_per_m": 71690, "k_shear_n_per_m": 7169,
             "k_rot_n_m_per_rad": 0.5735, "mass_kg": 4.52e-3}
LATTICES |= {
    "sheet-magnets": MAGNETS,
    # near the closed state (θ ≈ 0.7 rad): facing magnets inside their core radius
    "sheet-magnets-closed": dict(MAGNETS, magnets={"moment_a_m2": 0.253, "recess_m": 0.003, "polarity": "attract",
                                                   "contact_stiffness_n_per_m": 2e4}),
    "sheet-magnets-repel-theta0": dict(MAGNETS, theta0_rad=0.1, magnets={"moment_a_m2": 0.2, "recess_m": 0.002,
                                                                         "polarity": "repel"},
                                       variation=[{"kind": "gradient", "target": "theta0_rad", "start": 0.05,
                                                   "end": 0.15}]),
    "linkage": {"kind": "bistable_linkage", "n_cols": 3, "bar_length_m": 0.02, "theta0_rad": 1.0472,
                "theta_deployed_rad": 0.4363, "mass_kg": 0.002, "k_pin_n_per_m": 1e5, "released_energy_j": 1.5,
                "barrier_fraction": 0.3},
    "chain-loaded": dict(CHAIN, theta0_rad=0.05, left="free", right="free", predeform=LOADS),
    "sheet-loaded": dict(SHEET, predeform=LOADS),
    "triangles-chain": {"kind": "rotating_triangles_chain", "n_units": 6, **TRIANGLES},
    "triangles-sheet": {"kind": "rotating_triangles_sheet", "n_rows": 2, "n_cols": 4, **TRIANGLES,
                        "bottom": "periodic", "top": "periodic",
                        "variation": [{"kind": "gradient", "target": "k_rot_n_m_per_rad", "start": 0.4,
                                       "end": 0.8}]},
    "harmonic": None,  # no scene: ``HarmonicArgs`` directly
    "network-quads": {"kind": "rigid_network", "pattern": "random_quads", "vertex_jitter": 0.1, "seed": 2,
                      "n_rows": 2, "n_cols": 3, "a_m": 0.01, "theta0_rad": 0.2, "ligament_length_m": 0.001,
                      "k_long_n_per_m": 1e4, "k_shear_n_per_m": 3e3, "k_rot_n_m_per_rad": 2e-3,
                      "areal_density_kg_m2": 20.0},
    # DifFlexMM's ligament laws on disordered quads (axis along each rest gap)
    "network-difflexmm": {"kind": "rigid_network", "pattern": "random_quads", "vertex_jitter": 0.1, "seed": 2,
                          "n_rows": 2, "n_cols": 3, "a_m": 0.01, "theta0_rad": 0.2, "ligament_length_m": 0.001,
                          "k_long_n_per_m": 1e4, "k_shear_n_per_m": 3e3, "k_rot_n_m_per_rad": 2e-3,
                          "areal_density_kg_m2": 20.0, "ligament_law": "difflexmm"},
    "network-difflexmm-linear": {"kind": "rigid_network", "n_rows": 2, "n_cols": 3, "a_m": 0.01, "theta0_rad": 0.2,
                                 "ligament_length_m": 0.001, "k_long_n_per_m": 1e4, "k_shear_n_per_m": 3e3,
                                 "k_rot_n_m_per_rad": 2e-3, "areal_density_kg_m2": 20.0,
                                 "ligament_law": "difflexmm_linear"},
    # nearly closed pores (acute corners 0.256 a apart at rest) and a cutoff just below: the random
    # states put vertices inside it
    "network-contact": {"kind": "rigid_network", "n_rows": 3, "n_cols": 3, "a_m": 0.01, "theta0_rad": 0.6,
                        "k_long_n_per_m": 1e4, "k_shear_n_per_m": 3e3, "k_rot_n_m_per_rad": 2e-3,
                        "areal_density_kg_m2": 20.0, "contact": {"stiffness_n_per_m": 1e4, "cutoff_m": 2.5e-3}},
    # configs/g_magnetic_bistable_unidirectional.yaml's laws (a chain of masses: dipole bonds to
    # first and second neighbours, an asymmetric double well on site)
    "mass-dipole-bistable": {"kind": "mass_chain", "n_units": 7, "spacing_m": 0.02, "mass_kg": 0.005,
                             "bond": {"law": "dipole", "distance_m": 0.02, "moment_a_m2": 0.5},
                             "bond2": {"law": "dipole", "distance_m": 0.04, "moment_a_m2": 0.5},
                             "onsite": [{"law": "bistable_cubic", "alpha_n_per_m3": 1e7, "beta": 0.3,
                                         "jump_m": 0.004}]},
}
#: (rotation, contraction) of a state near which a lattice is checked (default: small random
#: displacements about rest): the units rotated and their centres drawn together
CLOSED = {"sheet-magnets-closed": (0.7, 0.3)}


def _closed(system, name):
    """The state ``CLOSED[name]``: θ = rotation, positions contracted about the origin."""
    rot, contraction = CLOSED[name]
    n, length = system.n_sites, system.scales.length_m
    q = np.zeros(system.ndof)
    q[:n] = -contraction * system.site_coords["x"] / length
    q[n : 2 * n] = -contraction * system.site_coords["y"] / length
    q[2 * n :] = rot
    return q


def _system(name):
    if name == "harmonic":
        return SimpleNamespace(args=HarmonicArgs(np.linspace(0.5, 2.0, 5)), ndof=5)
    return build_system(scene_from_dict({"name": "k", "lattice": LATTICES[name], "solver": {"duration_s": 1.0}}))[0]


def _force(q, args):
    out = np.zeros_like(q)
    model_force(q, args, out)
    return out


@pytest.fixture(params=sorted(LATTICES))
def setup(request):
    try:
        system = _system(request.param)
    except Exception as err:  # a law config key this test guessed wrong: say so
        pytest.fail(f"{request.param}: {err}")
    rng = np.random.default_rng(4)
    n = system.ndof
    q = rng.normal(0.0, 0.01 if request.param.startswith("mass") else 0.05, n)
    if request.param in CLOSED:
        q += _closed(system, request.param)
    return system.args, q, rng.normal(size=n), rng


def test_hvp_matches_differences_of_compiled_and_reference_forces(setup):
    args, q, lam, _ = setup
    n = q.size
    t1, t2 = param_tables(args)
    out = np.zeros(n)
    model_adjoint(q, args, lam, out, np.zeros_like(t1), np.zeros_like(t2))
    eps = 1e-6
    ref = kernels_of(type(args)).reference
    fd = np.array([lam @ (_force(q + eps * e, args) - _force(q - eps * e, args)) / (2 * eps) for e in np.eye(n)])
    fd_ref = np.array([lam @ (ref(q + eps * e, args)[1] - ref(q - eps * e, args)[1]) / (2 * eps) for e in np.eye(n)])
    scale = np.abs(out).max()
    assert np.abs(out - fd).max() < 1e-7 * scale
    assert np.abs(out - fd_ref).max() < 1e-7 * scale


def test_parameter_adjoint_and_tangent_match_differences(setup):
    args, q, lam, rng = setup
    n = q.size
    t1, t2 = param_tables(args)
    g1, g2 = np.zeros_like(t1), np.zeros_like(t2)
    model_adjoint(q, args, lam, np.zeros(n), g1, g2)
    d1 = rng.normal(size=t1.shape) * np.maximum(np.abs(t1), 1e-3)
    d2 = rng.normal(size=t2.shape) * np.maximum(np.abs(t2), 1e-3)
    if t1.ndim == 2 and t1.shape[1] == 7:
        d1[:, H_SIGN] = 0.0  # discrete
    dq = rng.normal(size=n)
    eps = 1e-6

    def force_at(s):
        return _force(q + s * dq, with_tables(args, t1 + s * d1, t2 + s * d2))

    fd = (force_at(eps) - force_at(-eps)) / (2 * eps)
    tan = np.zeros(n)
    model_tangent(q, args, dq, d1, d2, tan)
    assert np.abs(tan - fd).max() < 1e-7 * np.abs(fd).max()
    hv = np.zeros(n)
    model_adjoint(q, args, dq, hv, np.zeros_like(t1), np.zeros_like(t2))  # symmetric: (∂F/∂q) dq
    projected = lam @ hv + np.vdot(g1, d1) + np.vdot(g2, d2)
    assert projected == pytest.approx(lam @ fd, rel=1e-7)


def test_closed_magnets_are_in_their_cores():
    """The closed state of ``sheet-magnets-closed`` exercises the dipoles' core: its r_c and k_c
    get nonzero parameter products (zero while no magnet pair is inside r_c)."""
    system = _system("sheet-magnets-closed")
    args = system.args
    rng = np.random.default_rng(1)
    t1, t2 = param_tables(args)
    o_core = sheet_offsets(args)[2]
    for q, active in ((np.zeros(system.ndof), False), (_closed(system, "sheet-magnets-closed"), True)):
        g2 = np.zeros_like(t2)
        model_adjoint(q, args, rng.normal(size=q.size), np.zeros(q.size), np.zeros_like(t1), g2)
        assert (g2[o_core] != 0.0 and g2[o_core + 1] != 0.0) == active


#: lattices whose kernels are checked to rounding against the complex step of the numpy
#: reference (one loop of scalar hinge kernels: triangles, sheets with or without joints)
EXACT = ("triangles-chain", "triangles-sheet", "sheet", "sheet-ligament", "linkage", "sheet-loaded")


def _reference_force(q, args, t1, t2):
    """The model's numpy reference force at (q, tables t1, t2), complex-safe (complex step)."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", np.exceptions.ComplexWarning)  # energies taken as float
        return kernels_of(type(args)).reference(q, with_tables(args, t1, t2))[1]


@pytest.mark.parametrize("name", EXACT)
def test_adjoint_and_tangent_equal_complex_step_of_reference(name):
    """(∂F/∂q)ᵀλ, (∂F/∂p)ᵀλ and the tangent against Im F(x + iε d)/ε of the numpy reference (no
    cancellation: exact to rounding), to 1e-12 of their scale: a dropped or altered term of the
    hinge, frame or joint algebra fails here even where central differences (1e-7) would not."""
    system = _system(name)
    args = system.args
    rng = np.random.default_rng(7)
    n = system.ndof
    q = rng.normal(0.0, 0.05, n)
    lam, dq = rng.normal(size=n), rng.normal(size=n)
    t1, t2 = param_tables(args)
    d1 = rng.normal(size=t1.shape) * np.maximum(np.abs(t1), 1e-3)
    hinges = t1.shape[1] == N_HINGE_PARAMS  # a hinge table (the triangles': a ligament table)
    if hinges:
        d1[:, H_SIGN] = 0.0  # discrete
    d2 = rng.normal(size=t2.shape) * np.maximum(np.abs(t2), 1e-3)
    eps = 1e-30
    c1, c2 = t1.astype(complex), t2.astype(complex)

    def step(dq_, d1_, d2_):
        return _reference_force(q + 1j * eps * dq_, args, c1 + 1j * eps * d1_, c2 + 1j * eps * d2_).imag / eps

    out, g1, g2 = np.zeros(n), np.zeros_like(t1), np.zeros_like(t2)
    model_adjoint(q, args, lam, out, g1, g2)
    hv = step(lam, 0 * t1, 0 * t2)  # ∂F/∂q is symmetric
    assert np.abs(out - hv).max() <= 1e-12 * np.abs(hv).max()
    for table, grad, other in ((0, g1, t2), (1, g2, t1)):
        if grad.size == 0:  # no contacts between the triangles
            continue
        ref = np.zeros(grad.size)
        for k in range(grad.size):
            e = np.zeros(grad.size)
            e[k] = 1.0
            e = e.reshape(grad.shape)
            ref[k] = lam @ (step(0 * q, e, 0 * other) if table == 0 else step(0 * q, 0 * other, e))
        if table == 0 and hinges:
            ref.reshape(t1.shape)[:, H_SIGN] = 0.0  # not differentiated
        assert np.abs(grad.ravel() - ref).max() <= 1e-12 * np.abs(ref).max()
    tan = np.zeros(n)
    model_tangent(q, args, dq, d1, d2, tan)
    ref = step(dq, d1, d2)
    assert np.abs(tan - ref).max() <= 1e-12 * np.abs(ref).max()
