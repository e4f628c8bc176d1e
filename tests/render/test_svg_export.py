"""``flexmm export RUN --svg``: the reference geometry read back with the standard library's XML
parser and compared with the geometry file the run was built from (not with the dataset)."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import yaml
from conftest import GEOMETRY_FILE
from render_helpers import build, export, random_fields, write_run


SVG = "{http://www.w3.org/2000/svg}"
LAW = {"kind": "rigid_network", "k_long_n_per_m": 1e4, "k_shear_n_per_m": 3e3, "k_rot_n_m_per_rad": 2e-3,
       "areal_density_kg_m2": 20.0}


def read_svg(path):
    """(polygons [(site, (V, 2) mm)], lines [(sites, (2, 2) mm)]) of an exported drawing."""
    root = ET.parse(path).getroot()
    polys = [(int(p.get("data-site")), np.array([[float(c) for c in xy.split(",")] for xy in p.get("points").split()]))
             for p in root.iter(f"{SVG}polygon")]
    lines = [(tuple(int(s) for s in ln.get("data-sites").split()),
              np.array([[float(ln.get("x1")), float(ln.get("y1"))], [float(ln.get("x2")), float(ln.get("y2"))]]))
             for ln in root.iter(f"{SVG}line")]
    return root, polys, lines


def test_svg_of_a_geometry_file_is_that_file(tmp_path):
    """Every unit of the file is one polygon with the file's vertices (mm, in order, a triangle with 3
    points although the stored polygons are padded to 4), every ligament a line from vertex i of a to
    vertex j of b; the page is in mm and the drawing is flipped to y up."""
    lattice = dict(LAW, geometry=GEOMETRY_FILE)
    _, system = build(lattice)
    run = write_run(tmp_path / "net", lattice, system, random_fields(system, 3)).parent
    result = export(run, "--svg", "-q")
    assert result.exit_code == 0, result.output
    path = run / "render_test.svg"
    assert result.output.strip() == str(path)
    root, polys, lines = read_svg(path)
    geo = yaml.safe_load(open(GEOMETRY_FILE))
    assert [s for s, _ in polys] == list(range(4))
    for (_, p), unit in zip(polys, geo["units"]):
        np.testing.assert_allclose(p, 1e3 * np.array(unit["vertices_m"], float), rtol=0, atol=1e-9)
    assert len(lines) == len(geo["ligaments"])
    for (sites, seg), g in zip(lines, geo["ligaments"]):
        assert sites == (g["a"], g["b"])
        ends = [geo["units"][g["a"]]["vertices_m"][g["i"]], geo["units"][g["b"]]["vertices_m"][g["j"]]]
        np.testing.assert_allclose(seg, 1e3 * np.array(ends, float), rtol=0, atol=1e-9)
    assert root.get("width").endswith("mm") and root.find(f"{SVG}g").get("transform") == "scale(1,-1)"


def test_svg_of_generated_hexagons_and_refusals(tmp_path):
    lattice = dict(LAW, pattern="rotating_hexagons", a_m=0.01, n_rows=3, n_cols=4, theta0_rad=0.2)
    _, system = build(lattice)
    run = write_run(tmp_path / "hex", lattice, system, random_fields(system, 2)).parent
    out = tmp_path / "cut" / "hex.svg"
    (tmp_path / "cut").mkdir()
    assert export(run, "--format", "svg", "--out", out, "-q").exit_code == 0
    _, polys, lines = read_svg(out)
    assert len(polys) == 12 and all(p.shape == (6, 2) for _, p in polys) and len(lines) == system.args.unit_a.size
    side = np.hypot(*np.diff(np.vstack([polys[0][1], polys[0][1][:1]]), axis=0).T)
    np.testing.assert_allclose(side, 10.0, rtol=1e-9)  # regular hexagons of side a = 10 mm (written to 1e-9 mm)
    chain = {"kind": "mass_chain", "n_units": 10, "spacing_m": 0.01, "mass_kg": 0.01,
             "bond": {"law": "linear", "k_n_per_m": 100.0}}
    _, masses = build(chain)
    plain = write_run(tmp_path / "masses", chain, masses, random_fields(masses, 2)).parent
    result = export(plain, "--svg")
    assert result.exit_code == 2 and "stores no unit shapes" in result.output
