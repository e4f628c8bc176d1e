"""The drawn units sit where the model's kinematics put them (docs/physics.md §1, §2), every model kind.

For each example lattice of tests/conftest.py (one or more per model kind) a dataset with known
fields is written and rendered; the test then reads the drawn polygons and bodies back from the
figure and compares them with the kinematics computed here from the physics document: hinge points
±(a/2)(cos φ, sin φ), ±(a/2)(−sin φ, cos φ) about the centre (x + u, y + v), φ = σ(θ0 + θ) with
σ the checkerboard sign, θ0 per unit from the built model. The drawn hinge points then give the
model's energy (hinge springs from their separations), which is compared with the model's own.
"""

from __future__ import annotations

import numpy as np
import pytest
from render_helpers import NOT_RENDERED, build, hinge_points_drawn, polygons, random_fields, write_run

from flexmm.render.api import RenderOptions, still_figure

RIGID = ("rotating_squares_chain", "rotating_squares_sheet", "bistable_linkage")


def _args(system):
    """The hinge tables (a chain under constant loads wraps them: LoadedChainArgs.chain)."""
    return getattr(system.args, "chain", system.args)


def _theta0(system) -> np.ndarray:
    """θ0 per unit as the model stores it (chain: site table, sheet and linkage: args.theta0)."""
    if system.model == "rotating_squares_chain":
        return np.asarray(_args(system).site_prm[:, 0])
    return np.asarray(system.args.theta0)


def _sigma(system) -> np.ndarray:
    """Checkerboard sign (−1)^i along a chain, (−1)^(row + col) in a sheet (§1)."""
    if system.model == "rotating_squares_chain":
        return np.where(np.arange(system.n_sites) % 2 == 0, 1.0, -1.0)
    row, col = system.site_coords["row"], system.site_coords["col"]
    return np.where((row + col) % 2 == 0, 1.0, -1.0)


def _half(lat) -> float:
    return (lat.bar_length_m if lat.kind == "bistable_linkage" else lat.a_m) / 2


def expected_hinge_points(lat, system, fields: dict, k: int) -> np.ndarray:
    """(N, 4, 2): right, top, left, bottom hinge points of every unit at frame k (§1, §1.2)."""
    n = system.n_sites
    x = system.site_coords["x"] + fields["u"][k]
    y = system.site_coords.get("y", np.zeros(n)) + fields.get("v", np.zeros((k + 1, n)))[k]
    phi = _sigma(system) * (_theta0(system) + fields["theta"][k])
    h = _half(lat)
    e1 = np.stack([np.cos(phi), np.sin(phi)], 1)
    e2 = np.stack([-np.sin(phi), np.cos(phi)], 1)
    c = np.stack([x, y], 1)
    return np.stack([c + h * e1, c + h * e2, c - h * e1, c - h * e2], 1)


def _render(tmp_path, lattice, system, fields, k, **opts):
    run = write_run(tmp_path / "run", lattice, system, fields)
    return still_figure(run, RenderOptions(time_s=1e-3 * k, color="theta" if "theta" in fields else "u", **opts))


@pytest.mark.parametrize("shape", ["square", "cross", "bars"])
def test_drawn_hinge_points_follow_the_kinematics(example_lattice, shape, tmp_path):
    kind, example = example_lattice
    if kind not in RIGID:
        pytest.skip("rotating units only (masses: test_bodies_sit_at_x_plus_u)")
    lat, system = build(example["lattice"])
    fields = random_fields(system, 3, seed=3)
    for k in (0, 2):
        pic = _render(tmp_path / f"k{k}", example["lattice"], system, fields, k, shape=shape)
        drawn = hinge_points_drawn(polygons(pic))
        want = expected_hinge_points(lat, system, fields, k)
        np.testing.assert_allclose(drawn, want, rtol=0, atol=1e-12 * lat.model_dump().get("a_m", 1.0) + 1e-15)


def _hinges(system):
    """(a, b, axis) of the model's hinges; the periodic wraps are left out (drawn apart)."""
    args = _args(system)
    a, b = np.asarray(args.hinge_a), np.asarray(args.hinge_b)
    axis = np.zeros(a.size, np.int64) if system.model == "rotating_squares_chain" else np.asarray(args.hinge_axis)
    if system.model == "rotating_squares_chain":
        return a, b, axis
    row, col = system.site_coords["row"], system.site_coords["col"]
    near = (np.abs(row[a] - row[b]) <= 1) & (np.abs(col[a] - col[b]) <= 1)
    return a[near], b[near], axis[near]


def test_hinged_points_of_neighbours_meet_at_rest(example_lattice, tmp_path):
    """At rest a hinge's two points coincide, or lie one ligament apart along the hinge axis."""
    kind, example = example_lattice
    if kind not in RIGID:
        pytest.skip("rotating units only")
    lat, system = build(example["lattice"])
    fields = random_fields(system, 2)
    pts = hinge_points_drawn(polygons(_render(tmp_path, example["lattice"], system, fields, 0, shape="square")))
    a, b, axis = _hinges(system)
    pa = np.where(axis[:, None] == 0, pts[a, 0], pts[a, 1])  # right (top) point of A
    pb = np.where(axis[:, None] == 0, pts[b, 2], pts[b, 3])  # left (bottom) point of B
    gap = pb - pa
    ell = getattr(lat, "ligament_length_m", 0.0)
    along = np.where(axis == 0, gap[:, 0], gap[:, 1])
    across = np.where(axis == 0, gap[:, 1], gap[:, 0])
    np.testing.assert_allclose(along, ell, atol=1e-12)
    if "θ0 gradient" in example.get("not_at_rest", ""):  # §1: a θ0 gradient pre-stresses the shear springs
        t0 = _theta0(system)
        np.testing.assert_allclose(across, _half(lat) * (np.sin(t0[b]) - np.sin(t0[a])) * _sigma(system)[a],
                                   atol=1e-12)
    else:
        np.testing.assert_allclose(across, 0.0, atol=1e-12)


def test_rotating_one_unit_turns_its_corners_about_its_centre(example_lattice, tmp_path):
    """θ on one unit only: its hinge points turn by σθ about its centre, every other unit stays."""
    kind, example = example_lattice
    if kind not in RIGID:
        pytest.skip("rotating units only")
    _, system = build(example["lattice"])
    n = system.n_sites
    fields = {f.name: np.zeros((2, n)) for f in system.fields}
    i, theta = n // 2, 0.3
    fields["theta"][1, i] = theta
    rest = polygons(_render(tmp_path / "a", example["lattice"], system, fields, 0, shape="cross"))
    turned = polygons(_render(tmp_path / "b", example["lattice"], system, fields, 1, shape="cross"))
    others = np.arange(n) != i
    np.testing.assert_allclose(turned[others], rest[others], atol=1e-15)
    centre = np.array([system.site_coords["x"][i], system.site_coords.get("y", np.zeros(n))[i]])
    ang = _sigma(system)[i] * theta
    rot = np.array([[np.cos(ang), -np.sin(ang)], [np.sin(ang), np.cos(ang)]])
    np.testing.assert_allclose(turned[i], (rest[i] - centre) @ rot.T + centre, atol=1e-12)


def drawn_energy(lat, system, pts: np.ndarray, theta: np.ndarray, ghosts: np.ndarray | None) -> float:
    """Hinge energy (J) from the drawn hinge points: ½k_l Δl² + ½k_s Δs² + ½k_θ(θ_A + θ_B)², Δl and
    Δs the separation of the hinged points along and across the axis minus the ligament (§1), the
    chain's lateral hinges from the mirror rows (§1.1) and the linkage's double well in ψ."""
    sc = system.scales
    args = _args(system)
    kl = sc.stiffness * np.asarray(args.hinge_prm[:, 4])
    ks = sc.stiffness * np.asarray(args.hinge_prm[:, 5])
    kt = sc.energy * np.asarray(args.hinge_prm[:, 6])
    a_all, b_all = np.asarray(args.hinge_a), np.asarray(args.hinge_b)
    a, b, axis = _hinges(system)
    keep = np.isin(np.stack([a_all, b_all], 1).view([("", a_all.dtype)] * 2).ravel(),
                   np.stack([a, b], 1).view([("", a.dtype)] * 2).ravel())
    kl, ks, kt = kl[keep], ks[keep], kt[keep]
    pa = np.where(axis[:, None] == 0, pts[a, 0], pts[a, 1])
    pb = np.where(axis[:, None] == 0, pts[b, 2], pts[b, 3])
    gap = pb - pa
    ell = getattr(lat, "ligament_length_m", 0.0)
    dl = np.where(axis == 0, gap[:, 0], gap[:, 1]) - ell
    ds = np.where(axis == 0, gap[:, 1], gap[:, 0])
    dphi = theta[a] + theta[b]
    e = 0.5 * np.sum(kl * dl**2 + ks * ds**2 + kt * dphi**2)
    if lat.kind == "bistable_linkage":
        from flexmm.models.linkage import joint_stiffness

        s = 2 * (lat.theta_deployed_rad - lat.theta0_rad)
        k = joint_stiffness(lat.released_energy_j, s, lat.barrier_fraction)
        beta = lat.barrier_fraction
        e += np.sum(k * (dphi**4 / 4 - (1 + beta) * s * dphi**3 / 3 + beta * s * s * dphi**2 / 2))
    if ghosts is not None and lat.n_lateral:
        n = pts.shape[0]
        mirror = hinge_points_drawn(ghosts[:n])
        stretch = pts[:, 3, 1] - mirror[:, 1, 1]  # bottom of the unit minus top of its image below
        kl_unit = lat.k_long_n_per_m
        kt_unit = lat.k_rot_n_m_per_rad
        sv = float(lat.lateral_stretch)
        e += np.sum(lat.n_lateral * (0.25 * sv * kl_unit * stretch**2 + kt_unit * theta**2))
    return float(e)


def test_drawn_geometry_gives_the_model_energy(example_lattice, tmp_path):
    """The energy of the hinge springs, read off the drawing, equals the model's potential energy."""
    kind, example = example_lattice
    if kind not in RIGID:
        pytest.skip("rotating units only")
    lat, system = build(example["lattice"])
    if getattr(lat, "magnets", None) is not None or getattr(lat, "predeform", None) is not None \
            or (getattr(lat, "variation", []) and getattr(lat, "n_lateral", 0)) \
            or getattr(lat, "left", "") == "periodic" or getattr(lat, "bottom", "") == "periodic":
        pytest.skip("magnets, end loads, varied lateral hinges, periodic wraps (not drawn): see test_energy.py")
    fields = random_fields(system, 2, seed=5, amplitude=0.5)
    pic = _render(tmp_path, example["lattice"], system, fields, 1, shape="square")
    ghosts = None
    if pic.fig.ghosts is not None:
        ghosts = np.array([p.vertices[:4] for p in pic.fig.ghosts.get_paths()])
    e = drawn_energy(lat, system, hinge_points_drawn(polygons(pic)), fields["theta"][1], ghosts)
    sc = system.scales
    q = np.concatenate([fields[f.name][1] / sc.coordinate(f.kind) for f in system.fields])
    e_model = system.reference(q, system.args)[0] * sc.energy
    assert e == pytest.approx(e_model, rel=1e-9)


@pytest.mark.parametrize("stored", [True, False], ids=["rest-state-stored", "older-dataset"])
def test_bodies_sit_at_x_plus_u(example_lattice, tmp_path, monkeypatch, stored):
    """Masses: body centres at the rest position plus (initial displacement + u) along the chain
    (x for chains and grids); within a network branch, neighbours are one spacing plus their
    relative displacement apart along the branch. The initial displacement is the dataset's
    ``u_rest`` (the lattice is not relaxed again), or relaxed from the config for older datasets."""
    kind, example = example_lattice
    if kind in RIGID:
        pytest.skip("masses only")
    if kind in NOT_RENDERED:
        pytest.skip(f"{kind} is drawn from its stored shapes (tests/render/test_shapes.py), not by the renderer tested here")
    lat, system = build(example["lattice"])
    fields = random_fields(system, 2, seed=7)
    run = write_run(tmp_path / "run", example["lattice"], system, fields, state=stored)
    if stored:
        def no_relaxation(_p):
            raise AssertionError("the render relaxed the lattice again")
        monkeypatch.setattr("flexmm.render.masses.relaxed_initial", no_relaxation)
    pic = still_figure(run, RenderOptions(time_s=1e-3, color="u"))
    drawn = np.asarray(pic.fig.bodies.get_offsets())
    x0 = system.initial_displacement_m
    pos = x0 + fields["u"][1]
    if kind in ("mass_chain", "mass_grid"):
        want = np.stack([system.site_coords["x"] + pos, system.site_coords.get("y", np.zeros(system.n_sites))], 1)
        np.testing.assert_allclose(drawn, want, atol=1e-12)
        return
    for sites in system.site_groups.values():
        if len(sites) < 2:
            continue
        step = drawn[sites[1:]] - drawn[sites[:-1]]
        length = np.hypot(step[:, 0], step[:, 1])
        np.testing.assert_allclose(length, lat.spacing_m + np.diff(pos[sites]), atol=1e-12)
        direction = step / length[:, None]
        np.testing.assert_allclose(direction, np.broadcast_to(direction[0], direction.shape), atol=1e-12)
