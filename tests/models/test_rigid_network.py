"""The rigid_network lattice kind (docs/physics.md §1.9): geometry generators, polygon inertia, the
rotating-squares sheet reproduced as a network, and energy conservation of an undamped run."""

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from flexmm.assemble import build_problem
from flexmm.config import ConfigError, scene_from_dict
from flexmm.integrators.runner import integrate
from flexmm.models import MODELS
from flexmm.models.network import polygon_inertia

LAW = {"a_m": 0.01, "k_long_n_per_m": 1e4, "k_shear_n_per_m": 3e3, "k_rot_n_m_per_rad": 2e-3,
       "areal_density_kg_m2": 20.0}


def scene(lattice: dict, **extra):
    return scene_from_dict({"name": "t", "lattice": lattice, "solver": {"duration_s": 2e-3}, **extra})


def built(lattice: dict):
    s = scene(lattice)
    return MODELS[s.lattice.kind].build(s.lattice)


def test_polygon_inertia_of_a_square_and_a_triangle():
    """Mass, centroid and polar inertia of a square of diagonal a (m = ρa²/2, J = m a²/12) and of a
    right triangle (J about its centroid = m (b² + h²)/18), both placed off the origin."""
    a, rho = 2.0, 3.0
    sq = np.array([[[a / 2, 0], [0, a / 2], [-a / 2, 0], [0, -a / 2]]]) + [5.0, -1.0]
    m, c, j = polygon_inertia(sq, rho)
    assert m[0] == pytest.approx(rho * a * a / 2)
    assert_allclose(c[0], [5.0, -1.0], atol=1e-12)
    assert j[0] == pytest.approx(m[0] * a * a / 12)
    b, h = 3.0, 1.5
    tri = np.array([[[0, 0], [b, 0], [0, h]]]) + [-2.0, 4.0]
    m, c, j = polygon_inertia(tri, rho)
    assert m[0] == pytest.approx(rho * b * h / 2)
    assert_allclose(c[0], [-2.0 + b / 3, 4.0 + h / 3], atol=1e-12)
    assert j[0] == pytest.approx(m[0] * (b * b + h * h) / 18)


@pytest.mark.parametrize("geometry", [{"theta0_rad": 0.2}, {"theta0_rad": 0.1, "ligament_length_m": 0.002}])
def test_squares_network_is_the_rotating_squares_sheet(geometry):
    """Built from configs, the squares network and the sheet have the same masses, rest positions,
    energies and forces (the sheet's θ is staggered: rotations σθ, torques σ·)."""
    shape = {"n_rows": 4, "n_cols": 5}
    net = built({"kind": "rigid_network", **LAW, **shape, **geometry})
    sheet = built({"kind": "rotating_squares_sheet", **LAW, **shape, **geometry})
    n = sheet.n_sites
    r, c = np.divmod(np.arange(n), 5)
    sigma = np.where((r + c) % 2 == 0, 1.0, -1.0)
    assert_allclose(net.mass, sheet.mass, rtol=1e-13)
    for name in ("x", "y"):
        assert_allclose(net.site_coords[name], sheet.site_coords[name], rtol=0, atol=1e-15)
    rng = np.random.default_rng(11)
    for amplitude in (0.01, 0.3):
        q = amplitude * rng.normal(size=3 * n)
        qn = q.copy()
        qn[2 * n :] *= sigma
        f_sheet, f_net = np.empty(3 * n), np.empty(3 * n)
        sheet.force(q, sheet.args, f_sheet)
        net.force(qn, net.args, f_net)
        f_net[2 * n :] *= sigma
        assert_allclose(f_net, f_sheet, rtol=0, atol=1e-13 * np.abs(f_sheet).max())
        assert net.energy(qn, net.args) == pytest.approx(sheet.energy(q, sheet.args), rel=1e-13)


def test_random_quads_conserve_energy_in_an_undamped_impact():
    """An impact on a disordered quad network, undamped, PEFRL: the total energy stays within
    1e-6 of the energy put in, and the disorder really changed the units (masses differ)."""
    lattice = {"kind": "rigid_network", "pattern": "random_quads", "vertex_jitter": 0.08, "seed": 3,
               "n_rows": 6, "n_cols": 12, "theta0_rad": 0.25, **LAW}
    problem = build_problem(scene(lattice, excitation={"kind": "impact", "velocity_m_s": 0.5}))
    system = problem.system
    assert np.ptp(system.mass[: system.n_sites]) > 0.05
    tr = integrate(problem, "pefrl", h=problem.dt, n_frames=51, t_end=problem.duration)
    assert tr.status == "finished"
    e = np.array([system.energy(q, system.args) + 0.5 * np.sum(system.mass * v * v) for q, v in zip(tr.q, tr.v)])
    assert e[0] > 0
    assert np.max(np.abs(e - e[0])) < 1e-6 * e[0]
    assert np.max(np.abs(tr.q[-1][2 * system.n_sites :])) > 1e-4  # the units turned


def test_network_config_errors_are_clear():
    with pytest.raises(ConfigError, match="vertex_jitter"):
        scene({"kind": "rigid_network", "vertex_jitter": 0.1, "n_rows": 2, "n_cols": 3, **LAW})
    with pytest.raises(ConfigError, match="periodic"):
        scene({"kind": "rigid_network", "left": "periodic", "right": "periodic", "n_rows": 2, "n_cols": 5, **LAW})
    with pytest.raises(ConfigError, match="ligament_length_m > 0"):
        scene({"kind": "rigid_network", "ligament_law": "difflexmm", "n_rows": 2, "n_cols": 3, **LAW})
    with pytest.raises(ConfigError, match="cutoff_m"):
        scene({"kind": "rigid_network", "contact": {"stiffness_n_per_m": 1.0, "cutoff_m": -1e-3}, "n_rows": 2,
               "n_cols": 3, **LAW})
    assert math.isfinite(built({"kind": "rigid_network", "n_rows": 1, "n_cols": 3, **LAW}).mass.sum())


def test_triangle_network_is_the_rotating_triangles_sheet():
    """The kagome generated as a network and rotating_triangles_sheet with the same side, twist,
    springs and (polygon) masses: the same rest positions, SI masses, forces and energies to 1e-13
    (the sheet's θ is staggered: rotations σθ, torques σ·)."""
    a, rho, t0 = 0.02, 20.0, 0.2
    law = {"a_m": a, "theta0_rad": t0, "k_long_n_per_m": 7e4, "k_shear_n_per_m": 7e3, "k_rot_n_m_per_rad": 0.5}
    shape = {"n_rows": 4, "n_cols": 6}
    net = built({"kind": "rigid_network", "pattern": "rotating_triangles", "areal_density_kg_m2": rho, **law, **shape})
    tri = built({"kind": "rotating_triangles_sheet", "mass_kg": rho * math.sqrt(3) / 4 * a * a, **law, **shape})
    n = tri.n_sites
    r, c = np.divmod(np.arange(n), 6)
    sigma = np.where((r + c) % 2 == 0, 1.0, -1.0)
    si = lambda s, kinds: np.concatenate([np.full(n, s.scales.generalised_force(k)) for k in kinds])  # noqa: E731
    assert_allclose(net.mass * np.repeat([net.scales.mass_kg] * 2 + [net.scales.inertia], n),
                    tri.mass * np.repeat([tri.scales.mass_kg] * 2 + [tri.scales.inertia], n), rtol=1e-13)
    for name in ("x", "y"):
        assert_allclose(net.site_coords[name], tri.site_coords[name], rtol=0, atol=1e-15)
    rng = np.random.default_rng(12)
    for amplitude in (0.01, 0.2):
        q = amplitude * rng.normal(size=3 * n)  # SI-equal states: lengths in units of a for both
        qn = q.copy()
        qn[2 * n :] *= sigma
        f_tri, f_net = np.empty(3 * n), np.empty(3 * n)
        tri.force(q, tri.args, f_tri)
        net.force(qn, net.args, f_net)
        f_tri *= si(tri, ("length", "length", "angle"))
        f_net *= si(net, ("length", "length", "angle"))
        f_net[2 * n :] *= sigma
        assert_allclose(f_net, f_tri, rtol=0, atol=1e-13 * np.abs(f_tri).max())
        assert net.energy(qn, net.args) * net.scales.energy == pytest.approx(
            tri.energy(q, tri.args) * tri.scales.energy, rel=1e-13)
