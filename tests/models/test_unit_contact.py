"""Vertex–edge contact between rigid units sharing a pore (flexmm.models.unit_contact, docs/physics.md §1.9).

Oracles: the barrier's closed-form stiffness, finite differences of the energy (force) and of the
force (Hessian-vector product), the numpy reference, the rest gap of a rhombic pore
((a/√2) cos 2θ0 for squares hinged vertex to vertex), zero net force, energy conservation of an
undamped run through repeated contacts, and central differences of a gradient through contacts.
"""

import math
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose

import flexmm

from flexmm.config import scene_from_dict
from flexmm.models import MODELS
from flexmm.models import ligaments as lg
from flexmm.models import unit_contact as uc

LAW = {"kind": "rigid_network", "a_m": 0.01, "k_long_n_per_m": 1e4, "k_shear_n_per_m": 3e3,
       "k_rot_n_m_per_rad": 2e-3, "areal_density_kg_m2": 20.0}
CONTACT = {"stiffness_n_per_m": 1e4, "cutoff_m": 2e-4}
NETWORKS = {
    "squares": dict(LAW, n_rows=3, n_cols=4, theta0_rad=0.6),
    "squares-ligament": dict(LAW, n_rows=3, n_cols=4, theta0_rad=0.5, ligament_length_m=0.001),
    "quads-difflexmm": dict(LAW, pattern="random_quads", vertex_jitter=0.08, seed=1, n_rows=3, n_cols=3,
                            theta0_rad=0.4, ligament_length_m=0.001, ligament_law="difflexmm"),
    "kagome": dict(LAW, pattern="rotating_triangles", n_rows=3, n_cols=4, theta0_rad=0.3),
    # periodic: pairs across the wraps, with the lattice shift of their ligament
    "squares-torus": dict(LAW, n_rows=2, n_cols=4, theta0_rad=0.6, left="periodic", right="periodic",
                          bottom="periodic", top="periodic"),
    "kagome-strip": dict(LAW, pattern="rotating_triangles", n_rows=2, n_cols=4, theta0_rad=0.3,
                         left="periodic", right="periodic"),
}


def built(lattice: dict):
    scene = scene_from_dict({"name": "t", "lattice": lattice, "solver": {"duration_s": 1e-3}})
    return MODELS["rigid_network"].build(scene.lattice)


def force(q, args):
    f = np.empty(q.size)
    lg.network_force(q, args, f)
    return f


def test_barrier_law():
    """E, E' and E'' agree with differences of E; E'' = k[(c/d)³ − 1] (k at 2^(−1/3) c, 7k at c/2);
    energy, force and stiffness vanish at the cutoff and beyond."""
    k, c, h = 3.0, 0.2, 1e-6
    for d in (0.03, 0.1, 0.17, 0.199):
        e, de, dde = uc.barrier(d, k, c)
        assert de == pytest.approx((uc.barrier(d + h, k, c)[0] - uc.barrier(d - h, k, c)[0]) / (2 * h), rel=1e-7, abs=1e-9 * k * c)
        assert dde == pytest.approx((uc.barrier(d + h, k, c)[1] - uc.barrier(d - h, k, c)[1]) / (2 * h), rel=1e-6, abs=1e-8 * k)
        assert e > 0 and de < 0
    assert uc.barrier(c / 2, k, c)[2] == pytest.approx(7 * k, rel=1e-14)
    assert uc.barrier(c * 2 ** (-1 / 3), k, c)[2] == pytest.approx(k, rel=1e-13)
    assert uc.barrier(c, k, c) == (0.0, 0.0, 0.0) and uc.barrier(2 * c, k, c) == (0.0, 0.0, 0.0)
    assert max(abs(x) for x in uc.barrier(c * (1 - 1e-6), k, c)) < 1e-4 * k


def test_pairs_face_each_other_across_the_pores():
    """Squares hinged vertex to vertex: four pairs per ligament, and the closest ones are the far
    vertices of the acute corners of the rhombic pores, (a/√2) cos 2θ0 from the facing edge."""
    for theta0 in (0.3, 0.6):
        system = built(dict(LAW, n_rows=3, n_cols=4, theta0_rad=theta0, contact=CONTACT))
        args = system.args
        assert args.contacts.shape == (4 * args.unit_a.size, uc.N_CONTACT_PARAMS)
        assert np.all(args.contact_units[:, 0] != args.contact_units[:, 1])
        dist = uc.rest_distances(args.contact_units, args.contacts)
        assert dist.min() == pytest.approx(math.cos(2 * theta0) / math.sqrt(2), rel=1e-12)
        assert np.all(args.contacts[:, uc.C_K] == 1.0)  # k / k_l
        assert np.all(args.contacts[:, uc.C_CUT] == 0.02)  # c / a


def wrapped(system) -> np.ndarray:
    """(C,) bool: the contact pairs that act across a periodic boundary (rest separation not that of
    the two units' centres in the cell)."""
    args, centres = system.args, system.unit_shapes().centres
    d = centres[args.contact_units[:, 0]] - centres[args.contact_units[:, 1]]
    return np.hypot(*(args.contacts[:, [uc.C_DX, uc.C_DY]] - d).T) > 1e-9


def test_pairs_across_a_periodic_boundary_use_their_ligament_s_shift():
    """A torus of squares has the pairs of every ligament, wraps included, and each wrapped pair
    is the pair of the unwrapped sheet it copies: the same offsets and rest distance."""
    torus = built(dict(NETWORKS["squares-torus"], contact=CONTACT))
    open_sheet = built(dict(LAW, n_rows=4, n_cols=6, theta0_rad=0.6, contact=CONTACT))
    args = torus.args
    assert args.contacts.shape == (4 * args.unit_a.size, uc.N_CONTACT_PARAMS)
    across = wrapped(torus)
    assert across.sum() == 4 * np.any(torus.periodic.link_shifts, 1).sum()
    dist = uc.rest_distances(args.contact_units, args.contacts)
    assert_allclose(np.sort(np.unique(dist.round(12))), np.sort(np.unique(
        uc.rest_distances(open_sheet.args.contact_units, open_sheet.args.contacts).round(12))), rtol=1e-12)
    assert dist[across].min() == pytest.approx(math.cos(1.2) / math.sqrt(2), rel=1e-12)


def test_a_cutoff_beyond_the_open_pores_is_a_clear_error():
    with pytest.raises(uc.ContactError, match="cutoff"):
        built(dict(NETWORKS["squares"], contact={"stiffness_n_per_m": 1e4, "cutoff_m": 3e-3}))


def in_contact(system, rng):
    """The network's args with every pair's cutoff at 1.3 times its rest distance, and a random
    state about rest: most pairs in contact, some with the closest point at an edge's end."""
    args = system.args
    table = args.contacts.copy()
    table[:, uc.C_CUT] = 1.3 * uc.rest_distances(args.contact_units, table)
    return args._replace(contacts=table), 0.02 * rng.normal(size=system.ndof)


@pytest.mark.parametrize("name", sorted(NETWORKS))
def test_contact_force_hvp_and_reference(name):
    """Compiled = numpy reference (1e-13), force = −∇E and the Hessian-vector product = the
    force's derivative (central differences), internal forces balance; contacts active."""
    system = built(dict(NETWORKS[name], contact=CONTACT))
    rng = np.random.default_rng(3)
    args, q = in_contact(system, rng)
    n = system.n_sites
    e_c, _ = uc.contacts_reference(q, n, args.contact_units, args.contacts)
    assert e_c > 0.1 * lg.network_energy(q, args)
    f = force(q, args)
    e_ref, f_ref = lg.network_reference(q, args)
    assert lg.network_energy(q, args) == pytest.approx(e_ref, rel=1e-13)
    assert_allclose(f, f_ref, rtol=0, atol=1e-13 * np.abs(f_ref).max())
    h = 1e-7
    fd = np.array([-(lg.network_energy(q + h * e, args) - lg.network_energy(q - h * e, args)) / (2 * h)
                   for e in np.eye(q.size)])
    assert_allclose(f, fd, rtol=0, atol=1e-6 * np.abs(f).max())
    assert abs(f[:n].sum()) < 1e-12 * np.abs(f).max() and abs(f[n : 2 * n].sum()) < 1e-12 * np.abs(f).max()
    dq = rng.normal(size=q.size)
    hv = np.empty_like(q)
    lg.network_hvp(q, args, dq, hv)
    fdh = -(force(q + h * dq, args) - force(q - h * dq, args)) / (2 * h)
    assert_allclose(hv, fdh, rtol=0, atol=1e-6 * np.abs(hv).max())


def test_the_second_derivative_oracles_see_contacts():
    """``tests/design/test_second_derivatives.py``'s ``network-contact`` lattice puts vertices
    inside the cutoff at its random states (so its Hessian and adjoint checks cover contacts)."""
    from design.test_second_derivatives import LATTICES

    system = built(LATTICES["network-contact"])
    q = np.random.default_rng(4).normal(0.0, 0.05, system.ndof)  # the fixture's state
    args = system.args
    assert uc.contacts_reference(q, system.n_sites, args.contact_units, args.contacts)[0] > 0.0


SCENE = Path(__file__).resolve().parents[2] / "configs" / "pore_closing_contact.yaml"


def test_energy_is_conserved_through_repeated_contacts():
    """The pore-closing scene, smaller, run as ``flexmm run`` runs it (default accuracy, undamped):
    pores close into contact several times, no vertex reaches its edge, and the total energy stays
    within 1e-6 of its initial value."""
    res = flexmm.run(SCENE, **{"lattice.n_rows": 4, "lattice.n_cols": 8, "solver.duration_s": 0.012})
    assert res.ok
    ds, system = res.dataset, MODELS["rigid_network"].build(res.scene.lattice)
    args, n, a = system.args, system.n_sites, res.scene.lattice.a_m
    q = np.concatenate([ds["u"].values / a, ds["v"].values / a, ds["theta"].values], axis=1)
    gaps = np.array([uc.pair_distances(qk, n, args.contact_units, args.contacts) for qk in q])
    touching = np.any(gaps < args.contacts[:, uc.C_CUT], axis=1)
    assert np.sum(touching[1:] & ~touching[:-1]) >= 3  # separate contact episodes
    assert 0.0 < gaps.min() < 0.5 * args.contacts[0, uc.C_CUT]
    energy = ds["total_energy"].values
    assert np.max(np.abs(energy - energy[0])) <= 1e-6 * energy[0]


def test_energy_is_conserved_through_contacts_across_a_periodic_boundary():
    """A 2 × 4 torus of squares at θ0 = 0.6 whose halves rush at each other across the x wrap
    (u̇ = ±4 m/s), run as ``flexmm run`` runs it (default accuracy, undamped): the pores across the
    wrap close into contact again and again, no vertex reaches its edge, and the total energy stays
    within 1e-6 of its initial value."""
    from flexmm.api import run_scene

    scene = scene_from_dict({"name": "t", "solver": {"duration_s": 0.03}, "output": {"n_frames": 301},
                             "lattice": dict(NETWORKS["squares-torus"], contact=CONTACT),
                             "initial": {"fields": [{"field": "u", "value": "0", "rate": "where(i >= 2, 4.0, -4.0)"}]}})
    res = run_scene(scene, in_memory=True)
    assert res.status == "finished"
    ds, system = res.dataset, MODELS["rigid_network"].build(scene.lattice)
    args, n, a = system.args, system.n_sites, scene.lattice.a_m
    q = np.concatenate([ds["u"].values / a, ds["v"].values / a, ds["theta"].values], axis=1)
    gaps = np.array([uc.pair_distances(qk, n, args.contact_units, args.contacts) for qk in q])
    cut = args.contacts[0, uc.C_CUT]
    touching = np.any(gaps[:, wrapped(system)] < cut, axis=1)
    assert np.sum(touching[1:] & ~touching[:-1]) >= 3  # separate contact episodes across the wrap
    assert 0.0 < gaps.min() < 0.5 * cut
    energy = ds["total_energy"].values
    assert np.max(np.abs(energy - energy[0])) <= 1e-6 * energy[0]


def test_gradient_through_contacts_matches_central_differences():
    """``flexmm design``'s adjoint through a pore closing into contact (a 2 × 3 network, damped):
    the gradient of a smooth objective of the trajectory with respect to the ligament table, the
    contact table, the inverse masses and the initial state equals central differences to 1e-6."""
    import yaml

    from design.test_gradient import _central, _directions, _objective
    from flexmm.assemble import build_problem
    from flexmm.design.gradient import trajectory_of

    data = yaml.safe_load(SCENE.read_text())
    data["lattice"].update(n_rows=2, n_cols=3)
    data["excitation"]["velocity_m_s"] = 3.0
    data["damping"] = {"viscous": {"damping_ratio": 0.02}}
    problem = build_problem(scene_from_dict(data))
    h = problem.dt / 10
    traj, raw = trajectory_of(problem, nsteps=800, stride=5, h=h)
    rec, _ = traj.run(raw)
    args, n = problem.system.args, problem.system.n_sites
    gaps = np.array([uc.pair_distances(q, n, args.contact_units, args.contacts) for q in rec.q])
    assert gaps.min() < 0.5 * args.contacts[0, uc.C_CUT]  # the run goes deep into contact
    objective = _objective((traj.n_samples, traj.obs.size))
    _, grad, _ = traj.gradient(raw, objective, segment=8)
    directions = _directions(raw, np.random.default_rng(0), traj.terms.drv_shape, traj.terms.drv_mode)
    for block in ("t1", "t2", "minv", "q0", "v0"):
        arr = getattr(raw, block)
        fd = _central(traj, raw, arr, arr.copy(), directions[block], objective)
        adj = float(np.vdot(getattr(grad, block), directions[block]))
        assert abs(adj - fd) < 1e-6 * abs(fd), (block, adj, fd)
