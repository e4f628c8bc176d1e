"""Regions of a rigid network (lattice.regions, docs/physics.md §1.9): their tables, their errors, and
the energy a long-wave pulse carries across an interface against the impedances of linear theory."""

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from flexmm.assemble import build_problem
from flexmm.config import ConfigError, scene_from_dict
from flexmm.integrators.runner import integrate
from flexmm.linear.network import bloch_split, cell_lattice, long_wave_mode, network_bands, region_medium
from flexmm.models import ligaments as lg
from flexmm.models.geometry import GeometryError
from flexmm.models.ligaments import NetworkArgs
from flexmm.models.network import build

LAW = {"a_m": 0.01, "k_long_n_per_m": 1e4, "k_shear_n_per_m": 3e3, "k_rot_n_m_per_rad": 2e-3,
       "areal_density_kg_m2": 20.0}
HALF = {"right": {"box_m": [0.0195, -1.0, 1.0, 1.0]}}  # columns 2.. of a θ0 = 0 sheet (pitch 0.01 m)


def lattice(**fields):
    return scene_from_dict({"name": "t", "lattice": {"kind": "rigid_network", **LAW, **fields},
                            "solver": {"duration_s": 1e-3}}).lattice


def test_a_region_sets_its_ligaments_and_masses_and_the_interface_is_in_series():
    plain = build(lattice(n_rows=2, n_cols=4, unit_sets=HALF))
    same = build(lattice(n_rows=2, n_cols=4, unit_sets=HALF, regions=[{"units": "right", "k_long_n_per_m": 1e4}]))
    assert_array_equal(same.args.ligaments, plain.args.ligaments)
    net = build(lattice(n_rows=2, n_cols=4, unit_sets=HALF, regions=[
        {"units": "right", "k_long_n_per_m": 4e4, "k_rot_n_m_per_rad": 0.0, "areal_density_kg_m2": 60.0}]))
    col = np.arange(8) % 4
    inside = col >= 2
    assert_allclose(net.mass.reshape(3, 8)[:, inside], 3 * plain.mass.reshape(3, 8)[:, inside], rtol=1e-15)
    assert_array_equal(net.mass.reshape(3, 8)[:, ~inside], plain.mass.reshape(3, 8)[:, ~inside])
    a, b, lig = net.args.unit_a, net.args.unit_b, net.args.ligaments
    both, across = inside[a] & inside[b], inside[a] != inside[b]
    assert across.sum() == 2 and both.sum() == 4
    assert np.all(lig[both, lg.L_KL] == 4.0) and np.all(lig[both, lg.L_KT] == 0.0)
    assert np.allclose(lig[across, lg.L_KL], 2 * 4.0 / 5.0) and np.all(lig[across, lg.L_KT] == 0.0)
    assert np.all(lig[~both & ~across, lg.L_KL] == 1.0)
    assert np.all(lig[:, lg.L_KS] == 0.3)  # not given: the lattice's everywhere


def test_region_errors_are_clear():
    with pytest.raises(ConfigError, match="regions.*not a named unit set"):
        lattice(n_rows=2, n_cols=4, regions=[{"units": "nowhere", "k_long_n_per_m": 1.0}])
    with pytest.raises(ConfigError, match="at least one of"):
        lattice(n_rows=2, n_cols=4, unit_sets=HALF, regions=[{"units": "right"}])
    twice = lattice(n_rows=2, n_cols=4, unit_sets={**HALF, "all": {"box_m": [-1, -1, 1, 1]}},
                    regions=[{"units": "right", "k_long_n_per_m": 2e4}, {"units": "all", "k_long_n_per_m": 3e4}])
    with pytest.raises(GeometryError, match="two regions"):
        build(twice)


def _speed_m_s(**law) -> float:
    """The long-wave longitudinal speed along x of the uniform periodic sheet with ``law`` (Bloch bands)."""
    lat = lattice(n_rows=2, n_cols=2, left="periodic", right="periodic", bottom="periodic", top="periodic",
                  **{**LAW, **law, "a_m": LAW["a_m"]})
    k = 1e-4
    scales = build(cell_lattice(lat)).scales
    return float(network_bands(lat, np.array([[k, 0.0]]))[0, 1] / k * scales.length_m / scales.time_s)


def _across(theta0: float, ratio: float, density: float, mode_launch: bool = True, region=None, **lattice):
    """A right-going long-wave pulse (gaussian of 10 pitches) in a strip of squares at rest rotation
    ``theta0`` periodic in y meets a region with stiffnesses × ``ratio`` and density × ``density``
    (or the fields ``region``): (energy beyond the interface once the pulse has split / total, the
    impedances Z₁, Z₂ of the Bloch long-wave modes, the share of the launch's energy in right-going
    acoustic waves). The launch is the acoustic mode (``long_wave_mode``: u = g, θ its slaved
    counter-rotation) or, without ``mode_launch``, u = g alone."""
    nc = 400
    if region is None:
        region = {"k_long_n_per_m": ratio * 1e4, "k_shear_n_per_m": ratio * 3e3, "k_rot_n_m_per_rad": ratio * 2e-3,
                  "areal_density_kg_m2": density * 20.0}
    pitch = math.cos(theta0) + lattice.get("ligament_length_m", 0.0) / 0.01
    scene = scene_from_dict({"name": "t", "solver": {"duration_s": 1e-3}, "lattice": {
        "kind": "rigid_network", "n_rows": 2, "n_cols": nc, **LAW, "theta0_rad": theta0, "bottom": "periodic",
        "top": "periodic", "unit_sets": {"far": {"box_m": [(nc / 2 - 0.5) * pitch * 0.01, -1, 100, 1]}},
        "regions": [{"units": "far", **region}], **lattice}})
    problem = build_problem(scene)
    system, lat = problem.system, scene.lattice
    n = system.n_sites
    near, far_mode = long_wave_mode(region_medium(lat)), long_wave_mode(region_medium(lat, lat.regions[0]))
    c = near.speed_m_s * system.scales.time_s / system.scales.length_m
    x = system.unit_shapes().centres[:, 0]
    far = x > (nc / 2 - 0.5) * pitch
    x0, width = (nc / 2 - 100) * pitch, 10.0 * pitch
    g = 1e-5 * np.exp(-(((x - x0) / width) ** 2))
    slope = -2 * (x - x0) / width**2 * g
    curvature = (4 * (x - x0) ** 2 / width**4 - 2 / width**2) * g
    row, col = np.divmod(np.arange(n), nc)
    cell = 2 * (row % 2) + col % 2
    shape, grad = near.shape[:, cell], near.gradient[:, cell] * mode_launch
    q0, v0 = (shape * g + grad * slope).ravel(), (-c * (shape * slope + grad * curvature)).ravel()

    plain = build(lat.model_copy(update={"regions": []}))  # the launch lies in the near medium
    split = bloch_split(region_medium(lat), plain, q0, v0, near)
    ahead = split.mode_forward / split.total
    tr = integrate(problem, "pefrl", h=problem.dt / 2, n_frames=2, t_end=140 * pitch / c, q0=q0, v0=v0)
    assert tr.status == "finished"
    q, v = tr.q[-1], tr.v[-1]
    a = system.args
    inside = far[a.unit_a] & far[a.unit_b]
    beyond = NetworkArgs(a.unit_a[inside], a.unit_b[inside], a.ligaments[inside], np.zeros(n), np.zeros(n), a.law)
    kinetic = 0.5 * system.mass * v * v
    transmitted = (kinetic.reshape(3, n)[:, far].sum() + system.energy(q, beyond)) / (system.energy(q, a) + kinetic.sum())
    return transmitted, near.impedance_kg_per_m_s, far_mode.impedance_kg_per_m_s, ahead


@pytest.mark.parametrize("theta0, ratio, density", [(0.0, 4.0, 1.0), (0.0, 1.0, 3.0), (0.2, 4.0, 1.0), (0.2, 1.0, 3.0)])
def test_energy_across_an_interface_is_the_impedance_transmission(theta0, ratio, density):
    """The energy beyond the interface once the pulse has split is 4 Z₁Z₂/(Z₁ + Z₂)² of the total,
    Z = ρc of the two sides' long-wave Bloch modes, at θ0 = 0 and at θ0 = 0.2 when the launch is the
    acoustic mode with its counter-rotation (measured 0.88972, 0.92628, 0.89027, 0.93071 against
    8/9, 0.92820, 8/9, 0.92820: the pulse's finite width, 0.005 % at 20 pitches)."""
    transmitted, z1, z2, _ = _across(theta0, ratio, density)
    assert transmitted == pytest.approx(4 * z1 * z2 / (z1 + z2) ** 2, rel=4e-3)
    c1, c2 = _speed_m_s(theta0_rad=theta0), _speed_m_s(theta0_rad=theta0, **{
        "k_long_n_per_m": ratio * 1e4, "k_shear_n_per_m": ratio * 3e3, "k_rot_n_m_per_rad": ratio * 2e-3})
    assert math.isclose(c2 / c1, math.sqrt(ratio), rel_tol=1e-6)  # the bands scale as they must
    assert math.isclose(z2 / z1, math.sqrt(ratio * density), rel_tol=1e-6)


def test_a_displacement_launch_at_theta0_transmits_its_acoustic_share():
    """At θ0 = 0.2 a pulse of u alone is not the acoustic mode (it lacks the counter-rotation the strain
    drives): its Bloch split puts 0.7315 of its energy in the right-going acoustic branch and the rest in
    optical branches running both ways. The energy beyond the interface is 4 Z₁Z₂/(Z₁ + Z₂)² of that
    share (0.6524 measured against 0.6502: +0.3 %, the optical waves that cross), where reading the
    whole launch as the mode predicts 8/9."""
    transmitted, z1, z2, ahead = _across(0.2, 4.0, 1.0, mode_launch=False)
    assert 0.70 < ahead < 0.76
    assert transmitted == pytest.approx(4 * z1 * z2 / (z1 + z2) ** 2 * ahead, rel=6e-3)


def test_the_bloch_split_of_a_mode_launch_runs_one_way():
    """The split of the acoustic mode's pulse (θ0 = 0.2) is all forward acoustic but for the
    launch's O((ka)²) error, sums to the state's energy, and its forward field is the pulse."""
    lat = lattice(n_rows=2, n_cols=200, theta0_rad=0.2, bottom="periodic", top="periodic")
    system = build(lat)
    n = system.n_sites
    mode = long_wave_mode(region_medium(lat))
    c = mode.speed_m_s * system.scales.time_s / system.scales.length_m
    x = system.unit_shapes().centres[:, 0]
    x0, width = x.mean(), 12.0
    g = 1e-5 * np.exp(-(((x - x0) / width) ** 2))
    slope = -2 * (x - x0) / width**2 * g
    curvature = (4 * (x - x0) ** 2 / width**4 - 2 / width**2) * g
    row, col = np.divmod(np.arange(n), 200)
    cell = 2 * (row % 2) + col % 2
    shape, grad = mode.shape[:, cell], mode.gradient[:, cell]
    q, v = (shape * g + grad * slope).ravel(), (-c * (shape * slope + grad * curvature)).ravel()
    split = bloch_split(region_medium(lat), system, q, v, mode)
    energy = system.energy(q, system.args) + 0.5 * np.sum(system.mass * v * v)
    assert split.total == pytest.approx(energy, rel=1e-9)
    assert split.mode_forward / energy > 0.998
    assert split.backward.sum() / energy < 2e-3
    assert_allclose(split.field[:n], g, atol=2e-3 * g.max())


def test_a_region_of_another_rest_rotation_transmits_by_the_impedances():
    """Squares at θ0 = 0.05 (ligaments 0.32 a) meet a region at θ0 = 0.3 on the same grid (its ligaments
    0.363 a, the interface's 0.362 a and skewed): the more rotated squares are softer (Z₂/Z₁ = 0.784),
    and of the mode pulse's forward acoustic energy the interface reflects (Z₁ − Z₂)²/(Z₁ + Z₂)², Z from
    each side's Bloch mode (measured 0.01434 against 0.01461: the pulse's finite width)."""
    transmitted, z1, z2, ahead = _across(0.05, 1.0, 1.0, region={"theta0_rad": 0.3}, ligament_length_m=0.0032)
    assert z2 / z1 == pytest.approx(0.784, abs=2e-3)
    assert ahead > 0.998
    reflected = 1 - transmitted / ahead
    assert reflected == pytest.approx(((z1 - z2) / (z1 + z2)) ** 2, rel=4e-2)


def test_a_region_of_another_rest_rotation_is_built_on_the_lattice_grid():
    """Its squares turn by ±θ0 of the region about the lattice's centres, the reference is stress-free,
    and the ligaments inside it and across its boundary span what the pitch leaves."""
    net = build(lattice(n_rows=2, n_cols=6, theta0_rad=0.1, ligament_length_m=0.002,
                        unit_sets={"r": {"box_m": [0.03, -1, 1, 1]}}, regions=[{"units": "r", "theta0_rad": 0.2}]))
    plain = build(lattice(n_rows=2, n_cols=6, theta0_rad=0.1, ligament_length_m=0.002))
    shapes, ref = net.unit_shapes(), plain.unit_shapes()
    assert_allclose(shapes.centres, ref.centres, rtol=0, atol=1e-15)
    col = np.arange(12) % 6
    turn = np.arctan2(shapes.vertices[:, 0, 1], shapes.vertices[:, 0, 0])  # the right vertex's direction
    sigma = np.where((np.arange(12) // 6 + col) % 2 == 0, 1.0, -1.0)
    assert_allclose(turn, sigma * np.where(col >= 3, 0.2, 0.1), atol=1e-14)
    q = np.zeros(3 * 12)
    assert net.energy(q, net.args) < 1e-30
    a, b, lig = net.args.unit_a, net.args.unit_b, net.args.ligaments
    length = lig[:, lg.L_LEN] * 0.01
    pitch = 0.01 * math.cos(0.1) + 0.002
    inside = (col[a] >= 3) & (col[b] >= 3)
    across = (col[a] >= 3) != (col[b] >= 3)
    assert_allclose(length[inside], pitch - 0.01 * math.cos(0.2), rtol=1e-12)
    skew = math.hypot(pitch - 0.005 * (math.cos(0.1) + math.cos(0.2)), 0.005 * (math.sin(0.2) - math.sin(0.1)))
    assert_allclose(length[across], skew, rtol=1e-12)


def test_regions_whose_squares_do_not_meet_are_refused_at_their_line(tmp_path):
    path = tmp_path / "s.yaml"
    path.write_text("""name: t
solver: {duration_s: 1.0e-3}
lattice:
  kind: rigid_network
  n_rows: 2
  n_cols: 6
  a_m: 0.01
  k_long_n_per_m: 1.0e4
  k_shear_n_per_m: 3.0e3
  k_rot_n_m_per_rad: 2.0e-3
  areal_density_kg_m2: 20.0
  unit_sets:
    r: {box_m: [0.03, -1, 1, 1]}
  regions:
    - {units: r, theta0_rad: 0.2}
""")
    from flexmm.config import load_scene

    with pytest.raises(ConfigError, match=r"s.yaml:15: lattice.regions.0.theta0_rad.*do not meet.*0\.0009983 m long"):
        load_scene(path)
    with pytest.raises(ConfigError, match="wider"):
        lattice(n_rows=2, n_cols=6, theta0_rad=0.3, unit_sets=HALF, regions=[{"units": "right", "theta0_rad": 0.1}])
    with pytest.raises(ConfigError, match="pattern rotating_squares"):
        lattice(n_rows=2, n_cols=6, pattern="rectangles", aspect_ratio=0.5, unit_sets=HALF,
                regions=[{"units": "right", "theta0_rad": 0.1}])


def test_a_region_of_another_ligament_law_is_that_law_inside_and_the_lattice_s_outside():
    """A region of DifFlexMM's linearised law in a network of the paper's (ligaments 0.3 a): the
    energy at a random state is the paper network's over the ligaments not inside the region plus the
    linearised network's over those inside (each built uniform), to round-off."""
    common = dict(n_rows=2, n_cols=6, theta0_rad=0.2, ligament_length_m=0.003, unit_sets={"r": {"box_m": [0.035, -1, 1, 1]}})
    mixed = build(lattice(**common, regions=[{"units": "r", "ligament_law": "difflexmm_linear"}]))
    paper, linear = build(lattice(**common)), build(lattice(**common, ligament_law="difflexmm_linear"))
    q = 0.05 * np.random.default_rng(0).normal(size=3 * 12)
    a = mixed.args
    inside = mixed.unit_shapes().centres[:, 0] > 3.5
    both = inside[a.unit_a] & inside[a.unit_b]
    assert both.sum() == 7

    def part(system, rows):
        s = system.args
        return system.energy(q, NetworkArgs(s.unit_a[rows], s.unit_b[rows], s.ligaments[rows], np.zeros(12),
                                            np.zeros(12), s.law))

    assert mixed.energy(q, a) == pytest.approx(part(paper, ~both) + part(linear, both), rel=1e-13)
    assert part(paper, both) != pytest.approx(part(linear, both), rel=1e-3)  # the laws do differ here
    with pytest.raises(ConfigError, match=r"regions\.0\.ligament_law.*nonlinear difflexmm"):
        lattice(**common, ligament_law="difflexmm", regions=[{"units": "r", "ligament_law": "paper"}])


def test_a_law_interface_does_not_reflect_long_longitudinal_waves():
    """The two laws differ in the shear spring's coupling to the units' mean rotation θ̄, which the
    longitudinal mode (counter-rotating units: θ̄ = 0 on every link) does not move: equal impedances
    (to 3e-7), and the interface reflects under 1e-5 of the mode pulse's energy (6.8e-6 measured)."""
    transmitted, z1, z2, ahead = _across(0.2, 1.0, 1.0, region={"ligament_law": "difflexmm_linear"},
                                         ligament_length_m=0.003)
    assert z2 / z1 == pytest.approx(1.0, abs=1e-6)
    assert 0 < 1 - transmitted / ahead < 1e-5
