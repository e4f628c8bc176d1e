"""The shipped scenes of the rigid network's geometry sources show what docs/scenes.md ("Geometry
sources") says, in numbers (slow: each runs its scene)."""

import numpy as np
import pytest
from rigid_scene_checks import run

from flexmm.analysis.report.analyze import analyze_run

pytestmark = pytest.mark.slow


def largest_u(ds, box) -> float:
    """max |u| over the run of the units whose centre lies in box = (x0, y0, x1, y1) (m)."""
    x, y = ds["x"].values, ds["y"].values
    x0, y0, x1, y1 = box
    sel = (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)
    return float(np.abs(ds["u"].values[:, sel]).max())


def pulse_of(path, field="u"):
    return analyze_run(path, field_spec=field).pulses[0]


def test_rotating_hexagons_pulse_softens_with_amplitude(tmp_path):
    """The 2 mm push makes a 1.17 mm u pulse at 26.86 m/s that turns the hexagons by 0.05 rad; the
    same push at 20 µm runs at 27.44 m/s: the large pulse is about 2 % slower."""
    _, ds, big = run("rotating_hexagons_pulse", tmp_path)
    _, _, small = run("rotating_hexagons_pulse", tmp_path / "small", ["excitation.amplitude_m=2e-5"])
    p, q = pulse_of(big.path), pulse_of(small.path)
    assert p.amplitude == pytest.approx(1.17e-3, rel=0.02) and p.speed_m_s == pytest.approx(26.86, rel=0.01)
    assert q.speed_m_s == pytest.approx(27.44, rel=0.01)
    assert 0.01 < 1 - p.speed_m_s / q.speed_m_s < 0.03
    assert 0.045 < np.abs(ds["theta"].values).max() < 0.055


def test_the_hole_casts_a_shadow(tmp_path):
    """Behind the hole the largest |u| is 0.42 of what the same units see without it."""
    behind, beside = (0.5, 0.12, 0.7, 0.19), (0.5, 0.0, 0.7, 0.05)
    scene, ds, _ = run("rotating_squares_hole", tmp_path)
    _, full, _ = run("rotating_squares_hole", tmp_path / "full", ["lattice.mask=null"])
    assert ds.sizes["site"] == 1223 and full.sizes["site"] == 1260
    with_hole, without = largest_u(ds, behind), largest_u(full, behind)
    assert with_hole == pytest.approx(0.293e-3, rel=0.02) and without == pytest.approx(0.703e-3, rel=0.02)
    assert with_hole / without < 0.5
    assert largest_u(ds, beside) == pytest.approx(0.240e-3, rel=0.02)


def test_tapered_sheet_from_a_geometry_file(tmp_path):
    """The pulse from the two struck units reaches the thin end at 15.4 ms; its peak |u̇| falls from
    0.96 m/s (unit 2) to 0.16–0.19 m/s along the taper."""
    _, ds, _ = run("tapered_squares_impact", tmp_path)
    t, ud = ds["time"].values, ds["u_dot"].values[:, :40]
    arrival = [int(np.argmax(np.abs(ud[:, k]) > 0.1)) for k in range(40)]
    first = [np.abs(ud[: arrival[k] + 15, k]).max() for k in range(40)]
    assert t[arrival[38]] == pytest.approx(15.4e-3, abs=0.3e-3)
    assert first[2] == pytest.approx(0.964, rel=0.02)
    assert all(0.15 < first[k] < 0.2 for k in (10, 15, 20, 25, 30, 35))


def test_a_disk_spreads_the_centre_kick(tmp_path):
    """The 657-unit disk: the mean largest |θ| in rings around the centre falls as r^(-0.58) from
    0.0027 rad (4–7 cm) to 0.0015 rad (13–19 cm), near a 2D wave's r^(-1/2), and rises at the rim."""
    _, ds, _ = run("rotating_squares_disk", tmp_path)
    assert ds.sizes["site"] == 657
    r = np.hypot(ds["x"].values - 0.235216, ds["y"].values - 0.235216)
    peak = np.abs(ds["theta"].values).max(0)
    edges = np.arange(0.04, 0.23, 0.03)
    rings = [(r[(r >= lo) & (r < hi)].mean(), peak[(r >= lo) & (r < hi)].mean()) for lo, hi in zip(edges, edges[1:])]
    rm, pm = np.array(rings).T
    assert pm[0] == pytest.approx(2.68e-3, rel=0.03) and pm[4] == pytest.approx(1.49e-3, rel=0.03)
    assert np.polyfit(np.log(rm[:-1]), np.log(pm[:-1]), 1)[0] == pytest.approx(-0.58, abs=0.03)
    assert pm[-1] > 1.2 * pm[-2]  # the free rim
