"""Bloch bands of periodic rigid-unit networks (flexmm.linear.network) against independent results:
the rotating-squares sheet's own cell (linear.sheet), the eigenvalues of a periodic network's whole
Hessian, a geometry file of the same cell, and the group velocity of a wave packet run on the network."""

import math

import numpy as np
import pytest
import yaml
from numpy.testing import assert_allclose

from flexmm.assemble import build_problem
from flexmm.config import ConfigError, scene_from_dict
from flexmm.integrators.common import empty_terms
from flexmm.integrators.runner import integrate
from flexmm.linalg import bloch_eigen, bloch_frequencies, dense_matrix
from flexmm.linear.network import NotPeriodic, cell_lattice, group_velocity, network_bands, network_cell
from flexmm.linear.sheet import squares_cell
from flexmm.models.network import build, generated
from flexmm.stability import dynamical_operator

LAW = {"a_m": 0.01, "k_long_n_per_m": 1e4, "k_shear_n_per_m": 3e3, "k_rot_n_m_per_rad": 2e-3,
       "areal_density_kg_m2": 20.0}
PERIODIC = {"left": "periodic", "right": "periodic", "bottom": "periodic", "top": "periodic"}


def lattice(**fields):
    return scene_from_dict({"name": "t", "lattice": fields, "solver": {"duration_s": 1e-3}}).lattice


@pytest.mark.parametrize("geometry", [{"theta0_rad": 0.2, "ligament_length_m": 0.001}, {"theta0_rad": 0.0}])
def test_squares_network_bands_are_the_rotating_squares_sheet_bands(geometry):
    """The periodic squares network's 2 × 2 cell holds two of the sheet's two-unit primitive cells:
    its 12 bands at k are the sheet's 6 at k and at k + (π/h, 0) (h the pitch), to 1e-8."""
    net = lattice(kind="rigid_network", n_rows=4, n_cols=6, **LAW, **geometry, **PERIODIC)
    sheet = lattice(kind="rotating_squares_sheet", n_rows=4, n_cols=4, **LAW, **geometry)
    h = math.cos(geometry["theta0_rad"]) + geometry.get("ligament_length_m", 0.0) / LAW["a_m"]
    k = np.random.default_rng(3).uniform(-math.pi / h, math.pi / h, (16, 2))
    cell = squares_cell(sheet)
    expected = np.sort(np.concatenate([bloch_frequencies(cell, k), bloch_frequencies(cell, k + [math.pi / h, 0.0])],
                                      1), 1)
    got = network_bands(net, k)
    assert got.shape == (16, 12)
    assert_allclose(got, expected, rtol=0, atol=1e-8 * expected.max())


@pytest.mark.parametrize("pattern", ["rotating_triangles", "rotating_hexagons", "rectangles"])
def test_bands_on_the_torus_wave_vectors_are_the_eigenvalues_of_its_hessian(pattern):
    """A 4 × 4 periodic sheet is 2 × 2 copies of the 2 × 2 cell: the eigenvalues of its whole mass-weighted
    Hessian (central differences of the compiled force) are the cell's bands at the four wave vectors
    that fit the torus (2π m/L_x, 2π n/L_y), m, n ∈ {0, 1}."""
    extra = {"aspect_ratio": 0.6, "ligament_length_m": 0.001} if pattern == "rectangles" else {}
    lat = lattice(kind="rigid_network", pattern=pattern, n_rows=4, n_cols=4, theta0_rad=0.15, **LAW, **extra,
                  **PERIODIC)
    system = build(lat)
    op, _ = dynamical_operator(system, empty_terms())
    torus = np.linalg.eigvalsh(dense_matrix(op, system.ndof))
    (lx, _), (_, ly) = system.periodic.vectors
    k = np.array([[2 * math.pi * m / lx, 2 * math.pi * n / ly] for m in (0, 1) for n in (0, 1)])
    cell = network_cell(build(cell_lattice(lat)))
    bands = np.sort(bloch_eigen(cell, k).ravel())
    assert_allclose(bands, torus, rtol=0, atol=1e-7 * torus.max())
    assert torus[3] > 1e-3 * torus.max()  # three zero modes (rigid motions), then a gap: a real check


def test_a_periodic_geometry_file_has_the_bands_of_its_pattern(tmp_path):
    """The squares' 2 × 2 cell written as a geometry file with lattice_vectors_m and shifted ligaments
    has the pattern's bands, and its runs wrap (a uniform translation costs no force)."""
    pat = lattice(kind="rigid_network", n_rows=2, n_cols=2, theta0_rad=0.25, ligament_length_m=0.002, **LAW,
                  **PERIODIC)
    net = generated(pat)
    a, b, va, vb, _ = net.links
    a_m = LAW["a_m"]
    doc = {"units": [{"vertices_m": (v * a_m).tolist()} for v in net.vertices],
           "ligaments": [{"a": int(x), "i": int(i), "b": int(y), "j": int(j), "shift": s.tolist()}
                         for x, y, i, j, s in zip(a, b, va, vb, net.shifts)],
           "lattice_vectors_m": (net.cell * a_m).tolist()}
    path = tmp_path / "cell.yaml"
    path.write_text(yaml.safe_dump(doc))
    law = {k: v for k, v in LAW.items() if k != "a_m"}
    from_file = lattice(kind="rigid_network", geometry=str(path), a_m=a_m, **law)
    k = np.array([[0.3, -0.7], [1.1, 0.2], [0.0, 0.0]])
    assert_allclose(network_bands(from_file, k), network_bands(pat, k), rtol=0, atol=1e-10)
    system = build(from_file)
    q, f = np.zeros(system.ndof), np.zeros(system.ndof)
    q[: system.n_sites], q[system.n_sites : 2 * system.n_sites] = 0.3, -0.2
    system.force(q, system.args, f)
    assert np.abs(f).max() < 1e-12


def test_a_wave_packet_on_the_periodic_network_travels_at_the_group_velocity():
    """A small Gaussian packet of one Bloch mode (band 1 at k h = 0.5 along x, envelope 15 pitches wide)
    on a 2 × 160 periodic squares network, run with PEFRL: its energy centroid moves at the band's
    ∇ω (measured 0.83789 against 0.83700, relative error 1.1e-3: the packet's spectral width; 2.4e-4
    at twice the width)."""
    geometry = {"theta0_rad": 0.2, "ligament_length_m": 0.001}
    nc = 160
    scene = scene_from_dict({"name": "t", "solver": {"duration_s": 1e-3}, "lattice": {
        "kind": "rigid_network", "n_rows": 2, "n_cols": nc, **LAW, **geometry, **PERIODIC}})
    problem = build_problem(scene)
    system = problem.system
    small = build(cell_lattice(scene.lattice))
    h = math.cos(0.2) + 0.1
    k = np.array([0.5 / h, 0.0])
    band = 1
    lam, vec = bloch_eigen(network_cell(small), k, vectors=True)
    omega = math.sqrt(lam[band])
    vg = group_velocity(scene.lattice, k, band)
    n, nb = small.n_sites, system.n_sites
    centres = system.unit_shapes().centres
    row, col = np.divmod(np.arange(nb), nc)
    same = (row % 2) * 2 + col % 2  # the unit of the 2 × 2 cell each unit is a copy of
    x0, width = 0.3 * nc * h, 15 * h
    wave = 1e-6 * np.exp(-0.5 * ((centres[:, 0] - x0) / width) ** 2) * np.exp(1j * centres @ k)
    q0 = np.concatenate([(wave * vec[f * n + same, band]).real for f in range(3)])
    v0 = np.concatenate([(-1j * omega * wave * vec[f * n + same, band]).real for f in range(3)])
    tr = integrate(problem, "pefrl", h=problem.dt / 4, n_frames=41, t_end=0.4 * nc * h / vg[0], q0=q0, v0=v0)
    assert tr.status == "finished"
    length = nc * h
    ring = np.exp(2j * math.pi * centres[:, 0] / length)
    xs = []
    for q, v in zip(tr.q, tr.v):
        e = (0.5 * system.mass * (v * v + omega * omega * q * q)).reshape(3, nb).sum(0)
        xs.append(np.angle(np.sum(e * ring)) * length / (2 * math.pi))
    speed = np.polyfit(np.array(tr.t), np.unwrap(xs, period=length), 1)[0]
    assert abs(vg[1]) < 1e-8
    assert speed == pytest.approx(vg[0], rel=3e-3)


def test_periodic_network_config_errors():
    with pytest.raises(ConfigError, match="even n_cols"):
        lattice(kind="rigid_network", n_rows=2, n_cols=5, left="periodic", right="periodic", **LAW)
    with pytest.raises(ConfigError, match="left and right must both be periodic"):
        lattice(kind="rigid_network", n_rows=2, n_cols=4, left="periodic", **LAW)
    with pytest.raises(NotPeriodic, match="not periodic"):
        network_bands(lattice(kind="rigid_network", n_rows=2, n_cols=4, **LAW), np.zeros((1, 2)))


def test_the_bands_command_writes_the_path_and_refuses_what_has_no_bands(tmp_path):
    """`flexmm bands` on the shipped torus: Γ–X–M–Γ, three files, the longitudinal branch's slope at Γ
    the speed its scene's pulse is launched with (44.25 m/s); a lattice of another kind and a network
    without periods are user errors (exit 2, no traceback)."""
    from pathlib import Path

    from typer.testing import CliRunner

    from flexmm.cli import app

    repo = Path(__file__).resolve().parents[2]
    runner = CliRunner()
    res = runner.invoke(app, ["bands", str(repo / "configs" / "network_bloch_torus.yaml"), "--points", "16",
                              "--out", str(tmp_path / "b")])
    assert res.exit_code == 0, res.output
    assert sorted(p.name for p in (tmp_path / "b").iterdir()) == ["bands.json", "bands.png", "bands.txt"]
    rows = np.loadtxt(tmp_path / "b" / "bands.txt")
    assert rows.shape == (3 * 16 + 1, 3 + 12)
    slope = 2 * math.pi * rows[1, 4] / rows[1, 1]  # the faster acoustic branch at the first step along x
    assert slope == pytest.approx(44.25, rel=2e-3)
    for config, message in ((repo / "configs" / "lego_vector_soliton.yaml", "rigid_network"),
                            (repo / "configs" / "rotating_hexagons_pulse.yaml", "not periodic")):
        res = runner.invoke(app, ["bands", str(config), "--out", str(tmp_path / "c")])
        assert res.exit_code == 2 and message in res.output and "Traceback" not in res.output, res.output


def test_periodic_geometry_file_errors_name_the_line(tmp_path):
    """A shift in a file without lattice vectors, or with one entry too few, is reported at its line."""
    doc = {"units": [{"vertices_m": [[0, 0], [0.01, 0], [0.01, 0.01], [0, 0.01]]},
                     {"vertices_m": [[0.011, 0], [0.021, 0], [0.021, 0.01], [0.011, 0.01]]}],
           "ligaments": [{"a": 0, "i": 1, "b": 1, "j": 0}, {"a": 1, "i": 1, "b": 0, "j": 0, "shift": [1]}]}
    law = {k: v for k, v in LAW.items() if k != "a_m"}
    for vectors, message in ((None, "only a periodic file"), ([[0.022, 0], [0, 0.02]], "one entry per lattice vector")):
        path = tmp_path / "f.yaml"
        path.write_text(yaml.safe_dump({**doc, "lattice_vectors_m": vectors}))
        with pytest.raises(ConfigError, match=message) as err:
            build(lattice(kind="rigid_network", geometry=str(path), **law))
        assert f"{path}:" in str(err.value) and "ligaments.1.shift" in str(err.value)
