"""Geometry sources of the rigid_network (docs/physics.md §1.9): a geometry file (read back equal to
the generator it was written from; every fault reported at its file:line), the rotating hexagons and
rectangles, the outline mask, and named unit sets for clamps and drives."""

import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from numpy.testing import assert_allclose

from conftest import GEOMETRY_FILE
from flexmm.assemble import build_problem
from flexmm.config import ConfigError, scene_from_dict
from flexmm.integrators.runner import integrate
from flexmm.models import MODELS
from flexmm.models import geometry as geo
from flexmm.models.network import geometry as generated_geometry

LAW = {"k_long_n_per_m": 1e4, "k_shear_n_per_m": 3e3, "k_rot_n_m_per_rad": 2e-3, "areal_density_kg_m2": 20.0}


def scene(lattice: dict, **extra):
    return scene_from_dict({"name": "t", "lattice": lattice, "solver": {"duration_s": 2e-3}, **extra})


def built(lattice: dict):
    s = scene(lattice)
    return MODELS[s.lattice.kind].build(s.lattice)


def write_network(path: Path, vertices_m: np.ndarray, links, **extra) -> str:
    """A geometry file of polygons (N, V, 2) in m and links (a, b, vertex of a, vertex of b)."""
    a, b, va, vb = (np.asarray(x).tolist() for x in links[:4])
    data = {"units": [{"vertices_m": p.tolist()} for p in vertices_m],
            "ligaments": [{"a": p, "i": i, "b": q, "j": j} for p, q, i, j in zip(a, b, va, vb)], **extra}
    path.write_text(yaml.safe_dump(data))
    return str(path)


@pytest.mark.parametrize("shape", [{"theta0_rad": 0.2}, {"theta0_rad": 0.1, "ligament_length_m": 0.002}])
def test_a_file_of_the_generated_squares_is_that_network(tmp_path, shape):
    """The squares generator written to a geometry file (vertices in m, zero or finite gaps, default
    axes) and read back: the same masses, centres, energies and forces (to round-off of the
    coordinates' trip through metres)."""
    a = 0.01
    lat = {"kind": "rigid_network", "a_m": a, "n_rows": 3, "n_cols": 4, **LAW, **shape}
    gen = built(lat)
    vertices, links = generated_geometry(scene(lat).lattice)
    path = write_network(tmp_path / "squares.yaml", vertices * a, links)
    net = built({"kind": "rigid_network", "geometry": path, "a_m": a, **LAW})
    assert net.n_sites == gen.n_sites == 12
    assert_allclose(net.mass, gen.mass, rtol=1e-12)
    assert_allclose(net.site_coords["x"], gen.site_coords["x"], atol=1e-15)
    n = net.n_sites
    rng = np.random.default_rng(5)
    q = 0.1 * rng.normal(size=3 * n)
    f_gen, f_net = np.empty(3 * n), np.empty(3 * n)
    gen.force(q, gen.args, f_gen)
    net.force(q, net.args, f_net)
    assert_allclose(f_net, f_gen, rtol=0, atol=1e-11 * np.abs(f_gen).max())
    assert net.energy(q, net.args) == pytest.approx(gen.energy(q, gen.args), rel=1e-11)


def test_mixed_file_masses_stiffnesses_and_sets():
    """The shipped test file: a given mass and inertia are used, the others follow the polygons;
    per-ligament stiffnesses override the lattice's; the sets are the units they name."""
    net = built({"kind": "rigid_network", "geometry": GEOMETRY_FILE, **LAW})
    sc, n = net.scales, net.n_sites
    mass = net.mass[:n] * sc.mass_kg
    assert mass[0] == pytest.approx(20.0 * 1e-4) and mass[2] == pytest.approx(20.0 * 0.5 * 0.01 * 0.008)
    assert mass[3] == pytest.approx(1e-3) and net.mass[2 * n + 3] * sc.inertia == pytest.approx(2e-8)
    lig = net.args.ligaments
    kl = 1e4
    assert lig[1, 9] * kl == pytest.approx(500.0) and lig[0, 9] * kl == pytest.approx(3e3)
    assert lig[5, 8] * kl == pytest.approx(2e4)
    assert lig[3, 10] * kl * net.scales.length_m**2 == pytest.approx(0.01)
    assert_allclose(lig[4, 6:8], [0.0, 1.0])
    assert net.site_groups == {"left_pair": [0, 2], "top": [2, 3]}


def test_a_rest_gap_prestresses_the_ligament(tmp_path):
    """rest_gap_m different from the vertices' separation: the reference is stretched by the
    difference (energy ½ k_l δ² along the axis), the default one is stress-free."""
    sq = np.array([[0, 0], [0.01, 0], [0.01, 0.01], [0, 0.01]], float)
    units = [sq, sq + [0.012, 0.0]]
    links = ([0, 0], [1, 1], [1, 2], [0, 3])
    free = built({"kind": "rigid_network", "geometry": write_network(tmp_path / "a.yaml", np.array(units), links),
                  **LAW})
    assert free.energy(np.zeros(6), free.args) == pytest.approx(0.0, abs=1e-30)
    data = yaml.safe_load((tmp_path / "a.yaml").read_text())
    data["ligaments"][0]["rest_gap_m"] = [0.0025, 0.0]
    (tmp_path / "b.yaml").write_text(yaml.safe_dump(data))
    pre = built({"kind": "rigid_network", "geometry": str(tmp_path / "b.yaml"), **LAW})
    e_si = pre.energy(np.zeros(6), pre.args) * pre.scales.energy
    assert e_si == pytest.approx(0.5 * 1e4 * 0.0005**2, rel=1e-12)


def broken(tmp_path, edit) -> str:
    """The test file edited, written one unit and one ligament per line."""
    data = yaml.safe_load(Path(GEOMETRY_FILE).read_text())
    edit(data)
    path = tmp_path / "bad.yaml"
    text = ["units:"] + [f"  - {yaml.safe_dump(u, default_flow_style=True, width=1000).strip()}" for u in data["units"]]
    text += ["ligaments:"] + [f"  - {yaml.safe_dump(g, default_flow_style=True, width=1000).strip()}" for g in data["ligaments"]]
    path.write_text("\n".join(text) + "\n")
    return str(path)


def line_of(path: str, text: str) -> int:
    return next(k + 1 for k, line in enumerate(Path(path).read_text().splitlines()) if text in line)


@pytest.mark.parametrize("edit, message, at", [
    (lambda d: d["units"][1].update(vertices_m=[[0.008, 0], [0.018, 0], [0.018, 0.01], [0.008, 0.01]]),
     "units 0 and 1 overlap", "0.008"),
    (lambda d: d["ligaments"][2].update(b=7), "unit 7 does not exist", "b: 7"),
    (lambda d: d["ligaments"][2].update(j=5), "unit 2 has no vertex 5", "j: 5"),
    (lambda d: d["units"][0].update(vertices_m=[[0, 0], [0.01, 0], [0.004, 0.004], [0.01, 0.01], [0, 0.01]]),
     "not convex", "0.004"),
    (lambda d: d["units"][0].update(vertices_m=[[0, 0], [0.01, 0.01], [0.01, 0], [0, 0.01]]),
     "self-intersecting", "[0.01, 0.01], [0.01, 0]"),
    (lambda d: d["units"][0].update(vertices_m=[[0, 0], [0.01, 0], [0.01, 0], [0.01, 0.01], [0, 0.01]]),
     "duplicate vertex", "[0.01, 0], [0.01, 0]"),
    (lambda d: d.update(ligaments=[g for g in d["ligaments"] if g["b"] != 3]),
     "disconnected pieces: units 3", "0.017"),
])
def test_geometry_faults_are_reported_at_their_line(tmp_path, edit, message, at):
    path = broken(tmp_path, edit)
    with pytest.raises(ConfigError, match=message) as err:
        built({"kind": "rigid_network", "geometry": path, **LAW})
    issue = err.value.issues[0]
    assert issue.source == path and issue.line == line_of(path, at)


def test_schema_errors_of_the_file_and_the_scene(tmp_path):
    path = broken(tmp_path, lambda d: d["units"][3].pop("inertia_kg_m2"))
    with pytest.raises(ConfigError, match="give both mass_kg and inertia_kg_m2") as err:
        built({"kind": "rigid_network", "geometry": path, **LAW})
    assert err.value.issues[0].source == path and err.value.issues[0].line == line_of(path, "mass_kg")
    (tmp_path / "list.yaml").write_text("- 1\n- 2\n")
    with pytest.raises(ConfigError, match="expected a mapping with a list of"):
        scene({"kind": "rigid_network", "geometry": str(tmp_path / "list.yaml"), "a_m": 0.01, **LAW})
    with pytest.raises(ConfigError, match="not found"):
        scene({"kind": "rigid_network", "geometry": str(tmp_path / "none.yaml"), **LAW})
    with pytest.raises(ConfigError, match="remove theta0_rad"):
        scene({"kind": "rigid_network", "geometry": GEOMETRY_FILE, "theta0_rad": 0.1, **LAW})
    with pytest.raises(ConfigError, match="n_cols"):
        scene({"kind": "rigid_network", "geometry": GEOMETRY_FILE, "n_cols": 9, **LAW})
    with pytest.raises(ConfigError, match="fixed_units \\['nope'\\]"):
        scene({"kind": "rigid_network", "geometry": GEOMETRY_FILE, "fixed_units": ["nope"], **LAW})
    with pytest.raises(ConfigError, match="excitation units 'nope'"):
        scene({"kind": "rigid_network", "geometry": GEOMETRY_FILE, **LAW},
              excitation={"kind": "impact", "velocity_m_s": 1.0, "units": "nope"})


def test_a_relative_geometry_path_is_relative_to_the_scene_file(tmp_path):
    from flexmm.config import load_scene

    (tmp_path / "g.yaml").write_text(Path(GEOMETRY_FILE).read_text())
    (tmp_path / "s.yaml").write_text(yaml.safe_dump({"name": "t", "solver": {"duration_s": 1e-3},
                                                     "lattice": {"kind": "rigid_network", "geometry": "g.yaml", **LAW}}))
    s = load_scene(tmp_path / "s.yaml")
    assert s.lattice.geometry == str((tmp_path / "g.yaml").resolve()) and s.lattice.n_units == 4


def test_named_sets_are_clamped_and_driven():
    """fixed_units holds every DOF of its set; an impact on ``units`` moves exactly that set."""
    lat = {"kind": "rigid_network", "geometry": GEOMETRY_FILE, "fixed_units": ["top"], **LAW,
           "unit_sets": {"hit": {"circle_m": [0.017, 0.005, 0.004]}}}
    problem = build_problem(scene(lat, excitation={"kind": "impact", "velocity_m_s": 0.3, "units": "hit"}))
    s = problem.system
    n = s.n_sites
    assert np.flatnonzero(s.inv_mass == 0).tolist() == [2, 3, n + 2, n + 3, 2 * n + 2, 2 * n + 3]
    assert np.flatnonzero(s.v0).tolist() == [1]
    tr = integrate(problem, "pefrl", h=problem.dt, n_frames=3, t_end=problem.duration)
    assert tr.status == "finished" and np.all(tr.q[-1][[2, 3, n + 2, n + 3]] == 0)


def test_generated_patterns_are_valid_networks():
    """Hexagons and rectangles: convex, non-overlapping, connected (the checks of a geometry file);
    the hexagons' free vertices touch at |θ0| = π/6 (their pores close); rectangles of aspect 1 are
    the squares."""
    for pattern, extra in (("rotating_hexagons", {"theta0_rad": 0.3}), ("rectangles", {"aspect_ratio": 0.5}),
                           ("rotating_hexagons", {"theta0_rad": -0.5})):
        cfg = scene({"kind": "rigid_network", "pattern": pattern, "a_m": 1.0, "n_rows": 4, "n_cols": 5,
                     **LAW, **extra}).lattice
        vertices, links = generated_geometry(cfg)
        a, b, va, vb, _ = links
        assert geo.geometry_issues(list(vertices), va * 0 + a, va, b, vb) == []
        # the ligaments join coincident vertices (hinged vertex to vertex) or a gap along their axis
        gap = vertices[b, vb] - vertices[a, va]
        assert np.max(np.abs(gap)) < 1e-12 if pattern == "rotating_hexagons" else True
    cfg = scene({"kind": "rigid_network", "pattern": "rotating_hexagons", "a_m": 1.0, "n_rows": 4, "n_cols": 5,
                 **LAW, "theta0_rad": math.pi / 6 - 1e-9}).lattice
    vertices, _ = generated_geometry(cfg)
    free = vertices[:, 1::2].reshape(-1, 2)
    d = np.hypot(*(free[:, None, :] - free[None, :, :]).transpose(2, 0, 1))
    np.fill_diagonal(d, np.inf)
    assert d.min() < 1e-8  # two free vertices meet: the pore is closed
    hexa = built({"kind": "rigid_network", "pattern": "rotating_hexagons", "a_m": 0.01, "n_rows": 2, "n_cols": 3,
                  **LAW, "theta0_rad": 0.3})
    m = 20.0 * 1.5 * math.sqrt(3) * 1e-4  # ρ (3√3/2) s²
    n = hexa.n_sites
    assert_allclose(hexa.mass[:n] * hexa.scales.mass_kg, m, rtol=1e-13)
    assert_allclose(hexa.mass[2 * n :] * hexa.scales.inertia, 5 / 12 * m * 1e-4, rtol=1e-13)
    with pytest.raises(ConfigError, match="π/6"):
        scene({"kind": "rigid_network", "pattern": "rotating_hexagons", "a_m": 1.0, "n_rows": 2, "n_cols": 3,
               **LAW, "theta0_rad": 0.6})
    with pytest.raises(geo.GeometryError, match="the pores have closed"):  # rectangles close at |θ0| = π/4
        built({"kind": "rigid_network", "pattern": "rectangles", "aspect_ratio": 0.5, "a_m": 0.01, "n_rows": 4,
               "n_cols": 4, "theta0_rad": 0.8, **LAW})
    for pattern in ("rotating_hexagons", "rectangles"):  # the spacing is the columns' pitch
        net = built({"kind": "rigid_network", "pattern": pattern, "a_m": 0.01, "n_rows": 2, "n_cols": 4,
                     "theta0_rad": 0.2, **LAW, **({"aspect_ratio": 0.5} if pattern == "rectangles" else {})})
        assert net.spacing_m == pytest.approx(net.site_coords["x"][1] - net.site_coords["x"][0], rel=1e-12)
    sq = built({"kind": "rigid_network", "a_m": 0.01, "n_rows": 3, "n_cols": 3, "theta0_rad": 0.2, **LAW})
    rc = built({"kind": "rigid_network", "pattern": "rectangles", "a_m": 0.01, "n_rows": 3, "n_cols": 3,
                "theta0_rad": 0.2, **LAW})
    assert_allclose(rc.args.ligaments, sq.args.ligaments, atol=1e-15)
    assert_allclose(rc.mass, sq.mass, rtol=1e-14)


def test_the_mask_cuts_units_and_refuses_pieces():
    base = {"kind": "rigid_network", "a_m": 0.01, "n_rows": 6, "n_cols": 6, "theta0_rad": 0.2, **LAW}
    full = built(base)
    centre = [2.5 * 0.01 * math.cos(0.2)] * 2
    holed = built(dict(base, mask={"holes": [{"circle_m": [*centre, 0.012]}]}))
    x, y = full.site_coords["x"], full.site_coords["y"]
    inside = np.hypot(x - centre[0], y - centre[1]) <= 0.012
    assert inside.sum() == 4 and holed.n_sites == 32
    kept = np.flatnonzero(~inside)
    assert_allclose(holed.site_coords["x"], x[kept]) and assert_allclose(holed.site_coords["y"], y[kept])
    # every kept link of the full sheet, and only those
    pairs = {(int(kept[p]), int(kept[q])) for p, q in zip(holed.args.unit_a, holed.args.unit_b)}
    expected = {(int(p), int(q)) for p, q in zip(full.args.unit_a, full.args.unit_b) if not inside[p] and not inside[q]}
    assert pairs == expected
    outline = [[-0.001, -0.001], [0.06, -0.001], [0.06, 0.03], [-0.001, 0.03]]
    assert built(dict(base, mask={"outline_m": outline})).n_sites == 6 * 4
    with pytest.raises(geo.GeometryError, match="disconnected pieces"):  # a slot across the sheet
        built(dict(base, mask={"holes": [{"polygon_m": [[0.018, -1], [0.022, -1], [0.022, 1], [0.018, 1]]}]}))
    with pytest.raises(geo.GeometryError, match="keeps no unit"):
        built(dict(base, mask={"outline_m": [[1, 1], [2, 1], [2, 2]]}))


def test_rotating_hexagons_force_is_minus_the_energy_gradient_and_conserve_energy():
    """Hexagons twisted by θ0 = 0.25: the compiled force equals −∇E by central differences at a
    random state, and an undamped impact (PEFRL) keeps the total energy within 1e-6 of the energy
    put in while the units turn."""
    lat = {"kind": "rigid_network", "pattern": "rotating_hexagons", "a_m": 0.01, "n_rows": 4, "n_cols": 10,
           "theta0_rad": 0.25, **LAW}
    problem = build_problem(scene(lat, excitation={"kind": "impact", "velocity_m_s": 0.5}))
    s = problem.system
    rng = np.random.default_rng(8)
    q = 0.05 * rng.normal(size=s.ndof)
    f = np.empty(s.ndof)
    s.force(q, s.args, f)
    h, fd = 1e-6, np.empty(s.ndof)
    for k in range(s.ndof):
        e = np.zeros(s.ndof)
        e[k] = h
        fd[k] = -(s.energy(q + e, s.args) - s.energy(q - e, s.args)) / (2 * h)
    assert_allclose(f, fd, rtol=0, atol=1e-7 * np.abs(f).max())
    tr = integrate(problem, "pefrl", h=problem.dt, n_frames=51, t_end=problem.duration)
    assert tr.status == "finished"
    e = np.array([s.energy(q, s.args) + 0.5 * np.sum(s.mass * v * v) for q, v in zip(tr.q, tr.v)])
    assert e[0] > 0 and np.max(np.abs(e - e[0])) < 1e-6 * e[0]
    assert np.max(np.abs(tr.q[-1][2 * s.n_sites :])) > 1e-4


def test_kicks_and_drives_act_on_named_sets():
    """A kick and a force drive given ``units`` act on that set's units only (the end gives the
    drive's direction), and a kick may not name both an end and a set."""
    lat = {"kind": "rigid_network", "geometry": GEOMETRY_FILE, **LAW}
    kicked = build_problem(scene(lat, excitation={"kind": "kicks", "kicks": [
        {"units": "top", "velocity_y_m_s": 0.2}]})).system
    n = kicked.n_sites
    assert np.flatnonzero(kicked.v0).tolist() == [n + 2, n + 3]
    driven = build_problem(scene(lat, excitation={"kind": "boundary_force", "end": "bottom", "units": "left_pair",
                                                  "amplitude_n": 0.5, "duration_s": 1e-3}))
    assert driven.terms.drv_dof.tolist() == [n + 0, n + 2]  # v of units 0 and 2 (the bottom's normal field)
    with pytest.raises(ConfigError, match="exactly one of end, sites or units"):
        scene(lat, excitation={"kind": "kicks", "kicks": [{"end": "left", "units": "top", "velocity_x_m_s": 1.0}]})
    with pytest.raises(ConfigError, match="not both"):
        scene(lat, excitation={"kind": "impact", "velocity_m_s": 1.0, "units": "top", "sites": [0]})


def test_the_documented_geometry_file_builds(tmp_path):
    """The example geometry file of docs/scenes.md ("Geometry sources") is a valid network."""
    text = (Path(__file__).resolve().parents[2] / "docs" / "scenes.md").read_text()
    block = text.split("## Geometry sources")[1].split("```yaml\n")[1].split("```")[0]
    (tmp_path / "doc.yaml").write_text(block)
    net = built({"kind": "rigid_network", "geometry": str(tmp_path / "doc.yaml"), **LAW})
    assert net.n_sites == 2 and net.args.unit_a.size == 2 and net.site_groups == {"left": [0]}


def test_a_malformed_unit_is_reported_in_the_file_when_built(tmp_path):
    path = broken(tmp_path, lambda d: d["units"][1].update(vertices_m=[[0.012, 0]], oops=1))
    s = scene({"kind": "rigid_network", "geometry": path, **LAW})  # the scene only counts the units
    with pytest.raises(ConfigError) as err:
        MODELS["rigid_network"].build(s.lattice)
    text = str(err.value)
    assert f"{path}:3: units.1.vertices_m" in text and "units.1.oops" in text
