"""Rigid units drawn from the shapes their datasets store (render.structure.ShapeStructure): every
rigid-unit model (squares, linkage, triangles, networks). Oracles: joined points meet at rest, every drawn unit is its stored
polygon moved rigidly, and the drawn joints give back the model's own energy."""

import numpy as np
import pytest

from flexmm.models import ligaments as lg
from flexmm.models.kernels import kernels_of
from flexmm.render.api import RenderOptions, still_figure
from render_helpers import build, polygons, random_fields, write_run

SHAPED = ("rotating_triangles_chain", "rotating_triangles_sheet", "rigid_network")
#: every model drawn from stored shapes (the squares' hinges are their own law: energy in test_kinematics.py)
RIGID = SHAPED + ("rotating_squares_chain", "rotating_squares_sheet", "bistable_linkage")


def drawn(tmp_path, lattice, system, fields, k):
    """(polygons (N, V, 2), joint segments (L, 2, 2)) drawn at frame k."""
    run = write_run(tmp_path / "run", lattice, system, fields)
    pic = still_figure(run, RenderOptions(time_s=1e-3 * k, color="theta"))
    line = pic.fig.lines  # one polyline of 2-point segments broken by NaN points
    xy = np.stack([line.get_xdata(), line.get_ydata()], -1).reshape(-1, 3, 2)[:, :2]
    return polygons(pic), xy


def shaped(example_lattice, kinds=SHAPED):
    kind, example = example_lattice
    if kind not in kinds:
        pytest.skip(f"{kind}: {'masses' if kind not in RIGID else 'the hinge law of the squares'}")
    return example["lattice"]


def test_joined_points_meet_at_rest_and_units_keep_their_shape(example_lattice, tmp_path):
    lattice = shaped(example_lattice, RIGID)
    lat, system = build(lattice)
    fields = random_fields(system, 2, seed=3, amplitude=0.5)
    rest_poly, rest_segs = drawn(tmp_path / "a", lattice, system, fields, 0)
    sh = system.unit_shapes()
    a = system.scales.length_m
    # at rest each drawn joint spans the model's rest gap g0 = X_b − X_a − o (a network's ligament
    # table), or nothing (triangles are hinged at their vertices)
    expected = np.zeros((sh.links.shape[0], 2))
    if getattr(lat, "ligament_length_m", 0.0):  # a square sheet's ligaments, along each hinge's axis
        ua, ub = sh.links.T
        along_x = system.site_coords["row"][ua] == system.site_coords["row"][ub]
        expected = lat.ligament_length_m * np.stack([along_x, ~along_x], 1)
    if hasattr(system.args, "ligaments"):
        from flexmm.models import ligaments as lg
        xy = np.stack([system.site_coords["x"], system.site_coords["y"]], 1)
        ua, ub = sh.links.T
        expected = xy[ub] - xy[ua] - system.args.ligaments[:, [lg.L_OX, lg.L_OY]] * a
    if sh.images is not None:  # a chain's lateral hinges meet the mirror images at rest too
        expected = np.concatenate([expected, np.zeros((sh.images.size, 2))])
    gaps = rest_segs[:, 1] - rest_segs[:, 0]
    if lat.kind == "rotating_squares_chain" and np.ptp(sh.angle * sh.rotation_sign):
        # a graded chain (1D: its shear is measured from the rest state): corners offset across the row
        gaps, expected = gaps[:, 0], expected[:, 0]
    np.testing.assert_allclose(gaps, expected, rtol=0, atol=1e-12 * a)
    poly, _ = drawn(tmp_path / "b", lattice, system, fields, 1)
    # each unit moved rigidly: its edge lengths are those of the rest polygon
    edges = lambda p: np.hypot(*(np.roll(p, -1, 1) - p).transpose(2, 0, 1))  # noqa: E731
    np.testing.assert_allclose(edges(poly), edges(rest_poly), rtol=1e-12)
    # and turned by rotation_sign · θ about its centre
    n = system.n_sites
    d_rest = rest_poly[:, 0] - rest_poly.mean(1)
    d_now = poly[:, 0] - poly.mean(1)
    turned = np.arctan2(d_rest[:, 0] * d_now[:, 1] - d_rest[:, 1] * d_now[:, 0], np.sum(d_rest * d_now, 1))
    np.testing.assert_allclose(turned, sh.rotation_sign * fields["theta"][1][:n], atol=1e-9)


def test_drawn_joints_give_the_model_energy(example_lattice, tmp_path):
    """E = Σ ½ k_l (g·e)² + ½ k_s (g·n)² + ½ k_θ Δφ² with g the change of each drawn joint's
    segment and Δφ the change of the drawn units' relative rotation: the model's energy."""
    lattice = shaped(example_lattice)
    if "periodic" in lattice.values():
        pytest.skip("a periodic wrap's hinge is not drawn: the drawing holds part of the energy")
    lat, system = build(lattice)
    fields = random_fields(system, 2, seed=5, amplitude=0.3)
    _, rest_segs = drawn(tmp_path / "a", lattice, system, fields, 0)
    _, segs = drawn(tmp_path / "b", lattice, system, fields, 1)
    sc, n = system.scales, system.n_sites
    lig = getattr(system.args, "network", system.args).ligaments  # the triangles' hinges are ligaments
    e = lig[:, [lg.L_EX, lg.L_EY]]
    k = lig[:, [lg.L_KL, lg.L_KS, lg.L_KT]]
    g = ((segs[:, 1] - segs[:, 0]) - (rest_segs[:, 1] - rest_segs[:, 0])) / sc.length_m
    nrm = np.stack([-e[:, 1], e[:, 0]], 1)
    phi = system.unit_shapes().rotation_sign * fields["theta"][1][:n]
    ends = system.unit_shapes().links
    dphi = phi[ends[:, 1]] - phi[ends[:, 0]]
    energy = 0.5 * np.sum(k[:, 0] * np.sum(g * e, 1) ** 2 + k[:, 1] * np.sum(g * nrm, 1) ** 2 + k[:, 2] * dphi**2)
    q = np.concatenate([fields[f.name][1] / sc.coordinate(f.kind) for f in system.fields])
    assert energy == pytest.approx(kernels_of(type(system.args)).reference(q, system.args)[0], rel=1e-9)
