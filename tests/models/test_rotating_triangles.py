"""The rotating-triangles chain and kagome sheet (docs/physics.md §1.6).

Oracles: the rest geometry written from the triangles' vertex directions (neighbours' vertices
meet), the closed-form long-wave speed of the straight strip, the eigenvalues of the finite
periodic lattice's Hessian against the Bloch dispersion of ``flexmm.linear``, the speed of a
simulated small pulse against the Bloch long-wave speed, and the energy of undamped velocity
Verlet (error bounded, ∝ dt²). The kernels' force = −∇E and compiled = reference checks run
for every model kind in tests/models/test_hinge_kernel.py (examples in tests/conftest.py).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from conftest import LEGO_PARAMETERS
from scipy.linalg import eigh

from flexmm.assemble import build_problem
from flexmm.integrators.common import empty_terms
from flexmm.integrators.runner import energy, run_fixed
from flexmm.linalg import bloch_frequencies, dense_matrix
from flexmm.linear.dispersion import chain_cell
from flexmm.linear.triangles import (
    chain_bands,
    chain_long_wave_speed,
    sheet_bands,
    sheet_long_wave_speeds,
)
from flexmm.models import MODELS
from flexmm.models import ligaments as lg
from flexmm.models.rotating_triangles import centroids, sublattice_sign
from flexmm.stability import hessian_operator

A = 0.02
KL = LEGO_PARAMETERS["k_long_n_per_m"]
TRI = {"a_m": A, "k_long_n_per_m": KL, "k_shear_n_per_m": 0.1 * KL, "k_rot_n_m_per_rad": 0.02 * KL * A * A,
       "mass_kg": LEGO_PARAMETERS["mass_kg"],
       "inertia_kg_m2": LEGO_PARAMETERS["mass_kg"] * A * A / 12}


def chain(make_scene, scene_dict, **changes):
    lat = dict(TRI, kind="rotating_triangles_chain", n_units=8)
    lat.update(changes)
    scene = make_scene(scene_dict(lat, solver={"duration_s": 1.0}))
    return MODELS[scene.lattice.kind].build(scene.lattice), scene


def sheet(make_scene, scene_dict, **changes):
    lat = dict(TRI, kind="rotating_triangles_sheet", n_rows=4, n_cols=6)
    lat.update(changes)
    scene = make_scene(scene_dict(lat, solver={"duration_s": 1.0}))
    return MODELS[scene.lattice.kind].build(scene.lattice)


def vertices(x, y, sigma, phi):
    """(N, 3, 2) vertices of equilateral triangles of side 1 (units of a): an up triangle
    (σ = +1) has them at 90°, 210°, 330° from its centroid, a down one at 270°, 30°, 150°, all
    turned by the actual rotation φ."""
    base = np.radians([90.0, 210.0, 330.0])[None, :] + np.where(sigma > 0, 0.0, math.pi)[:, None] + phi[:, None]
    return np.stack([x[:, None] + np.cos(base) / math.sqrt(3), y[:, None] + np.sin(base) / math.sqrt(3)], -1)


@pytest.mark.parametrize("theta0", [0.0, 0.3, -0.45])
def test_hinged_vertices_meet_at_rest(theta0, make_scene, scene_dict):
    """Every hinge joins a vertex of A to a vertex of B that coincide at rest (twisted kagome),
    its axis runs from A's centroid to B's, and interior triangles have three hinges."""
    s = sheet(make_scene, scene_dict, theta0_rad=theta0, n_rows=4, n_cols=6)
    n, a = s.n_sites, s.scales.length_m
    x, y = s.site_coords["x"] / a, s.site_coords["y"] / a
    sigma = np.where((s.site_coords["row"] + s.site_coords["col"]) % 2 == 0, 1.0, -1.0)
    vert = vertices(x, y, sigma, sigma * theta0)
    args, net = s.args, s.args.network
    for h, (ia, ib) in enumerate(zip(net.unit_a, net.unit_b)):
        gap = np.linalg.norm(vert[ia][:, None, :] - vert[ib][None, :, :], axis=-1)
        assert gap.min() < 1e-12, (h, gap.min())
        d = np.array([x[ib] - x[ia], y[ib] - y[ia]])
        np.testing.assert_allclose(d, net.ligaments[h, [lg.L_OX, lg.L_OY]], atol=1e-12)
        np.testing.assert_allclose(d, np.linalg.norm(d) * net.ligaments[h, [lg.L_EX, lg.L_EY]], atol=1e-12)
    degree = np.bincount(net.unit_a, minlength=n) + np.bincount(net.unit_b, minlength=n)
    row, col = s.site_coords["row"], s.site_coords["col"]
    ix, iy = s.site_grid()  # grid indices for planners and initial fields: columns and rows
    np.testing.assert_array_equal(ix, col)
    np.testing.assert_array_equal(iy, row)
    interior = (row > 0) & (row < 3) & (col > 0) & (col < 5)
    assert np.all(degree[interior] == 3)
    # the rest state has zero energy; the twist mechanism (θ0 → θ0 + t with the centroids
    # scaled by cos(θ0 + t)/cos θ0) stretches and shears nothing: it costs ½ k_θ (2t)² per hinge
    q = np.zeros(3 * n)
    assert abs(s.energy(q, args)) < 1e-28
    t = 0.05
    scale = math.cos(theta0 + t) / math.cos(theta0) - 1.0
    q[:n], q[n : 2 * n], q[2 * n :] = scale * x, scale * y, t
    expected = 0.5 * net.ligaments[0, lg.L_KT] * (2 * t) ** 2 * len(net.unit_a)
    assert s.energy(q, args) == pytest.approx(expected, rel=1e-10)


@pytest.mark.parametrize("kind", ["chain", "sheet"])
@pytest.mark.parametrize("theta0", [0.0, 0.3])
def test_rigid_motion_costs_nothing(kind, theta0, make_scene, scene_dict):
    """A free lattice turned as a whole by ψ (centroids rotated about the origin, every triangle's
    actual rotation ψ: staggered θ = σψ) and shifted keeps its vertices together and its hinge
    angles: zero energy and force for any ψ. With θ0 ≠ 0 this pins the documented sense of the
    twist (up triangles, σ = +1, turn by +θ0), which the rest state and the mechanism do not."""
    s = (chain(make_scene, scene_dict, n_units=7, theta0_rad=theta0)[0] if kind == "chain"
         else sheet(make_scene, scene_dict, theta0_rad=theta0, n_rows=3, n_cols=4))
    n, a = s.n_sites, s.scales.length_m
    x, _ = centroids(*(s.grid_shape or (1, n)), theta0)
    y = s.site_coords["y"] / a if "y" in s.site_coords else centroids(1, n, theta0)[1]
    sig_site = sublattice_sign(*(s.grid_shape or (1, n)))  # +1: points up (docs/physics.md §1.6)
    for psi in (0.4, -1.1):
        c, sn = math.cos(psi), math.sin(psi)
        q = np.concatenate([c * x - sn * y - x + 0.3, sn * x + c * y - y - 0.2, sig_site * psi])
        assert abs(s.energy(q, s.args)) < 1e-26
        assert np.max(np.abs(forces(s, q))) < 1e-12


def test_straight_strip_long_wave_speed_is_the_closed_form(make_scene, scene_dict):
    """θ0 = 0: c_L² = 4 K_s/(1 + 3 K_s) (in c0 = a sqrt(k_l/m)), docs/physics.md §1.6; the
    slower acoustic branch is flexural (ω ∝ q²)."""
    for ks in (0.02, 0.1, 0.6):
        _, scene = chain(make_scene, scene_dict, k_shear_n_per_m=ks * KL)
        assert chain_long_wave_speed(scene.lattice) == pytest.approx(math.sqrt(4 * ks / (1 + 3 * ks)), rel=1e-4)
        w1, w2 = chain_bands(scene.lattice, np.array([0.01, 0.02]))[:, 0]
        assert w2 / w1 == pytest.approx(4.0, rel=1e-2)
    _, free_twist = chain(make_scene, scene_dict, k_rot_n_m_per_rad=0.0)
    with pytest.raises(ValueError, match="no gap"):  # the mechanism has no gap: no long-wave limit
        chain_long_wave_speed(free_twist.lattice)


def forces(system, q) -> np.ndarray:
    out = np.full(system.ndof, np.nan)
    system.force(q, system.args, out)
    return out


def hessian(system) -> np.ndarray:
    return dense_matrix(hessian_operator(system, empty_terms()), system.ndof)


@pytest.mark.parametrize("theta0", [0.0, 0.25])
def test_bloch_bands_are_the_periodic_chain_spectrum(theta0, make_scene, scene_dict):
    """The 6 Bloch branches at q = 2πj/P (j = 0..P−1) are the eigenfrequencies of the periodic
    chain of P two-unit cells (its Hessian and mass matrix, eigenvalues computed directly)."""
    cells = 6
    periodic, _ = chain(make_scene, scene_dict, n_units=2 * cells, theta0_rad=theta0, left="periodic",
                        right="periodic")
    lam = eigh(hessian(periodic), np.diag(periodic.mass), eigvals_only=True)
    open_chain, _ = chain(make_scene, scene_dict, n_units=20, theta0_rad=theta0)
    qs = 2 * math.pi * np.arange(cells) / cells
    w = bloch_frequencies(chain_cell(open_chain, cell_sites=2), qs)
    bloch = np.sort(np.nan_to_num(w).ravel() ** 2)
    np.testing.assert_allclose(np.sort(lam), bloch, rtol=1e-6, atol=1e-7 * lam.max())


def pulse_speed(make_scene, scene_dict, theta0: float, width: float) -> tuple[float, float]:
    """(simulated, Bloch) long-wave speed (c0) of a small strain pulse released at rest on a free
    chain, Gaussian of standard deviation ``width`` sites: the peak of its right-going half,
    tracked between 0.3 and 0.6 of its run to the far end."""
    n = int(50 * width)
    _, scene = chain(make_scene, scene_dict, n_units=n, theta0_rad=theta0)
    c = chain_long_wave_speed(scene.lattice)
    x = np.arange(n) * math.cos(theta0)  # rest positions, units of a
    x0 = x[n // 4]
    q0 = np.zeros(3 * n)
    q0[:n] = np.cumsum(1e-4 * np.exp(-0.5 * ((x - x0) / (width * math.cos(theta0))) ** 2)) * math.cos(theta0)
    traj = run_fixed(build_problem(scene), "velocity_verlet", h=0.1, t_end=0.6 * (x[-1] - x0) / c, n_frames=3,
                     q0=q0, v0=np.zeros(3 * n))
    xm = 0.5 * (x[1:] + x[:-1])
    peaks = []
    for k in (1, 2):
        e = np.where(xm > x0, np.diff(traj.q[k, :n]), -np.inf)  # the left-going half is behind x0
        i = int(np.argmax(e))
        y0, y1, y2 = e[i - 1], e[i], e[i + 1]  # parabolic peak
        peaks.append(xm[i] + 0.5 * (y0 - y2) / (y0 - 2 * y1 + y2) * (xm[1] - xm[0]))
    return (peaks[1] - peaks[0]) / (traj.t[2] - traj.t[1]), c


@pytest.mark.parametrize("theta0", [0.0, 0.3])
def test_small_pulse_travels_at_the_bloch_long_wave_speed(theta0, make_scene, scene_dict):
    """A broad small pulse moves at the Bloch long-wave speed, up to dispersion: its peak lags by
    a fraction ∝ 1/width² (0.7 % at 12 sites, 0.2 % at 24 for θ0 = 0), so doubling the width
    divides the deficit by about 4 and the wider pulse is within 0.3 %."""
    (m1, c), (m2, _) = (pulse_speed(make_scene, scene_dict, theta0, w) for w in (12.0, 24.0))
    d1, d2 = 1 - m1 / c, 1 - m2 / c
    assert 0 < d2 < 0.003, (m2, c)
    assert 3.0 < d1 / d2 < 5.0, (d1, d2)


@pytest.mark.parametrize("kind", ["chain", "sheet"])
def test_verlet_energy_error_is_bounded_and_second_order(kind, make_scene, scene_dict):
    """Undamped velocity Verlet on a large-amplitude state (|θ| ~ 0.2 rad; a free chain of 24, a
    periodic 4 × 4 sheet): the energy error oscillates without drift (its mean over the last
    quarter of the run equals that over the first within 10 % of its range) and scales as dt²
    (halving dt divides it by 3.3 to 4.7; measured 3.87 chain, 3.53 sheet)."""
    lat = (dict(TRI, kind="rotating_triangles_chain", n_units=24) if kind == "chain" else
           dict(TRI, kind="rotating_triangles_sheet", n_rows=4, n_cols=4, left="periodic", right="periodic",
                bottom="periodic", top="periodic"))
    problem = build_problem(make_scene(scene_dict(dict(lat, theta0_rad=0.2), solver={"duration_s": 1.0})))
    n = problem.system.n_sites
    rng = np.random.default_rng(3)
    q0 = np.concatenate([rng.normal(0, 0.02, 2 * n), rng.normal(0, 0.2, n)])
    v0 = np.concatenate([rng.normal(0, 0.05, 2 * n), rng.normal(0, 0.3, n)])
    e0 = energy(problem, q0, v0)
    errors = []
    for h in (0.1, 0.05):
        traj = run_fixed(problem, "velocity_verlet", h=h, t_end=400.0, n_frames=401, q0=q0, v0=v0)
        de = np.array([energy(problem, q, v) for q, v in zip(traj.q, traj.v)]) - e0
        errors.append(np.max(np.abs(de)))
        quarter = de.size // 4
        assert abs(de[-quarter:].mean() - de[:quarter].mean()) < 0.1 * errors[-1]
    assert errors[0] < 5e-3 * e0
    assert 3.3 < errors[0] / errors[1] < 4.7, errors


# ------------------------------------------------------------------ kagome sheet
def sheet_lattice(make_scene, scene_dict, **changes):
    lat = dict(TRI, kind="rotating_triangles_sheet", n_rows=4, n_cols=4)
    lat.update(changes)
    return make_scene(scene_dict(lat)).lattice


@pytest.mark.parametrize("theta0", [0.0, 0.3])
def test_sheet_bloch_bands_are_the_periodic_sheet_spectrum(theta0, make_scene, scene_dict):
    """A periodic 4 × 6 kagome sheet (12 two-triangle cells): the eigenfrequencies of its Hessian
    are the Bloch branches at the wave vectors (2πi/L_x, 2πj/L_y), i < 6, j < 4 — each cell state
    twice, since (i, j) and (i + 3, j + 2) differ by a reciprocal lattice vector."""
    nr, nc = 4, 6
    lat = sheet_lattice(make_scene, scene_dict, n_rows=nr, n_cols=nc, theta0_rad=theta0, left="periodic",
                        right="periodic", bottom="periodic", top="periodic")
    system = MODELS[lat.kind].build(lat)
    lam = eigh(hessian(system), np.diag(system.mass), eigvals_only=True)
    lx, ly = nc * math.cos(theta0), nr * math.sqrt(3) * math.cos(theta0)
    i, j = np.meshgrid(np.arange(nc), np.arange(nr), indexing="ij")
    k = np.stack([2 * math.pi * i / lx, 2 * math.pi * j / ly], -1)
    bloch = np.sort(sheet_bands(lat, k).ravel() ** 2)
    np.testing.assert_allclose(np.repeat(np.sort(lam), 2), bloch, rtol=1e-6, atol=1e-7 * lam.max())


@pytest.mark.parametrize("theta0", [0.0, 0.3])
def test_sheet_long_waves_are_isotropic(theta0, make_scene, scene_dict):
    """The kagome has three-fold symmetry, so its in-plane elasticity is isotropic: the two
    acoustic speeds do not depend on the direction (a wrong hinge axis or rest length breaks this).
    At θ0 = 0 the homogenised moduli of docs/physics.md §1.6: c_T² = K_s/(1 + K_s), c_L² = c_T² + ½
    (in c0²), for any K_θ > 0 and J. With K_θ = 0 the twist mechanism has no gap and there is no
    such limit: refused."""
    lat = sheet_lattice(make_scene, scene_dict, theta0_rad=theta0)
    speeds = np.array([sheet_long_wave_speeds(lat, math.radians(phi)) for phi in (0.0, 17.0, 30.0, 45.0, 90.0)])
    np.testing.assert_allclose(speeds, np.broadcast_to(speeds[0], speeds.shape), rtol=1e-5)
    if theta0 == 0.0:
        for ks, kt, j in ((0.1, 0.02, 1 / 12), (0.02, 0.2, 0.3), (0.6, 0.002, 1 / 12)):
            lat = sheet_lattice(make_scene, scene_dict, k_shear_n_per_m=ks * KL, k_rot_n_m_per_rad=kt * KL * A * A,
                                inertia_kg_m2=j * TRI["mass_kg"] * A * A)
            c_t, c_l = sheet_long_wave_speeds(lat, 0.4)
            assert c_t**2 == pytest.approx(ks / (1 + ks), rel=1e-5)
            assert c_l**2 == pytest.approx(ks / (1 + ks) + 0.5, rel=1e-5)
        with pytest.raises(ValueError, match="no gap"):
            sheet_long_wave_speeds(sheet_lattice(make_scene, scene_dict, k_rot_n_m_per_rad=0.0), 0.4)


@pytest.mark.parametrize("name, c_long", [("rotating_triangles_chain", math.sqrt(4 * 0.1 / 1.3)),
                                          ("rotating_triangles_sheet", None)])
def test_scene_pulse_is_measured_at_the_long_wave_speed(name, c_long, tmp_path):
    """configs/rotating_triangles_{chain,sheet}.yaml: `flexmm analyze -f u` compares the pulse with
    the Bloch long-wave speed (for the strip, the closed form of docs/physics.md §1.6 at θ0 = 0,
    K_s = 0.1); the pulse (FWHM 4 ms, a few units) is slower by its dispersion, by less than 2 %."""
    from pathlib import Path

    from flexmm.analysis.report import analyze as report
    from flexmm.api import run_scene
    from flexmm.config import load_scene

    scene = load_scene(Path(__file__).resolve().parents[2] / "configs" / f"{name}.yaml")
    res = report.analyze_run(run_scene(scene, run_dir=tmp_path / "run").path, field_spec="u")
    speed = next(c for c in res.comparisons if c.quantity == "speed" and c.predicted is not None)
    c0 = scene.lattice.a_m * math.sqrt(scene.lattice.k_long_n_per_m / scene.lattice.mass_kg)
    if c_long is not None:
        assert speed.predicted == pytest.approx(c_long * c0, rel=1e-4)
    assert -0.02 < speed.rel_diff < 0


def test_shipped_chain_scene_reports_its_longitudinal_pulse_against_bloch(tmp_path) -> None:
    """`flexmm run` measures the field the triangles' theory predicts (u, ModelTheory.pulse_field)
    and compares it with the Bloch long-wave speed (measured −1.05 %: a 5-site pulse's dispersion)."""
    from flexmm.analysis.report import analyze as report
    from flexmm.api import run_scene
    from flexmm.config import load_scene

    root = Path(__file__).resolve().parents[2]
    res = report.analyze_run(run_scene(load_scene(root / "configs" / "rotating_triangles_chain.yaml"),
                                       run_dir=tmp_path / "r").path)
    p = max(res.pulses, key=lambda q: abs(q.amplitude))
    assert p.field == "u"
    speeds = [c for c in res.comparisons if "speed" in c.quantity and c.predicted]
    assert speeds and all(abs(c.rel_diff) < 0.02 for c in speeds), speeds
