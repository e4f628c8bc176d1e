"""The one linear-algebra module (flexmm.linalg) against direct dense computations.

The Hessian-vector product against the Hessian from second differences of the energy (not of
the force it differentiates); ω_max, the fastest mode and the warm-started Lanczos against the
dense mass-weighted eigenproblem, on every model kind's example lattice; the Bloch bands of
1D and 2D cells (synthetic spring lattices, the rotating-squares sheet's cell, plan.domain's bands)
against the eigenvalues of finite periodic lattices.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import EXAMPLE_LATTICES
from scipy.linalg import eigh

from flexmm import linalg
from flexmm._blas import single_blas_thread
from flexmm.integrators.common import empty_terms
from flexmm.linear.sheet import squares_cell
from flexmm.models import MODELS
from flexmm.plan.domain import bloch_dispersion
from flexmm.stability import dynamical_operator, hessian_operator, omega_max, top_mode

H_E = 1e-4  # step of the energy's second differences (model units)


def build(example_lattice, scene_dict, make_scene):
    kind, example = example_lattice
    return MODELS[kind].build(make_scene(scene_dict(example["lattice"])).lattice)


def energy_hessian(system, q: np.ndarray) -> np.ndarray:
    """Dense Hessian of the compiled energy at q by 4-point second differences (truncation ~h²,
    round-off ~u|E|/h²), independent of the force."""
    n, h = system.ndof, H_E
    e = lambda x: system.energy(x, system.args)
    H = np.empty((n, n))
    for i in range(n):
        for j in range(i, n):
            d = np.zeros(n)
            d[i] += h
            dj = np.zeros(n)
            dj[j] += h
            H[i, j] = H[j, i] = (e(q + d + dj) - e(q + d - dj) - e(q - d + dj) + e(q - d - dj)) / (4 * h * h)
    return H


def small_state(system, rng) -> np.ndarray:
    q = np.zeros(system.ndof)
    for k, f in enumerate(system.fields):
        sl = slice(k * system.n_sites, (k + 1) * system.n_sites)
        q[sl] = rng.normal(0.0, 0.02 if f.kind == "length" else 0.1, system.n_sites)
    return np.where(system.inv_mass > 0, q, 0.0)


def test_hessian_vector_product_is_the_dense_energy_hessian_times_the_vector(example_lattice, scene_dict,
                                                                              make_scene):
    system = build(example_lattice, scene_dict, make_scene)
    rng = np.random.default_rng(3)
    q = small_state(system, rng)
    H = energy_hessian(system, q)
    kx = linalg.force_hessian(system.force, system.args, q)
    for _ in range(3):
        x = rng.standard_normal(system.ndof)
        ref = H @ x
        assert np.max(np.abs(kx(x) - ref)) <= 1e-5 * np.max(np.abs(ref)) + 1e-7 * np.max(np.abs(H))
    assert not np.any(kx(np.zeros(system.ndof)))


def test_central_difference_of_a_gradient_is_its_hessian() -> None:
    a = np.array([[3.0, 1.0, 0.0], [1.0, 2.0, -0.5], [0.0, -0.5, 1.0]])
    grad = lambda y: a @ y + y**3
    y, v = np.array([0.3, -0.2, 0.5]), np.array([1.0, 2.0, -1.0])
    exact = (a + np.diag(3 * y**2)) @ v
    assert linalg.central_difference(grad, y, v) == pytest.approx(exact, rel=1e-9)


def test_omega_max_and_top_mode_are_the_dense_mass_weighted_eigenpair(example_lattice, scene_dict, make_scene):
    system = build(example_lattice, scene_dict, make_scene)
    terms = empty_terms()
    free = np.flatnonzero(system.inv_mass > 0)
    H = energy_hessian(system, np.zeros(system.ndof))[np.ix_(free, free)]
    lam, vec = eigh(H, np.diag(system.mass[free]))
    w_ref = math.sqrt(max(lam[-1], 0.0))
    assert omega_max(system, terms) == pytest.approx(w_ref, rel=1e-5)
    # the iterative paths (Lanczos for ω_max, ARPACK for the mode) give the same as the dense one
    op, idx = dynamical_operator(system, terms)
    assert math.sqrt(max(linalg.top_eigenvalue(op, system.ndof, idx, dense_limit=0), 0.0)) == pytest.approx(
        w_ref, rel=1e-5)
    lam_it, _ = linalg.top_eigenpair(op, system.ndof, idx, dense_limit=0)
    assert math.sqrt(max(lam_it, 0.0)) == pytest.approx(w_ref, rel=1e-5)
    w, shape = top_mode(system, terms)
    assert w == pytest.approx(w_ref, rel=1e-5) and np.all(shape[system.inv_mass <= 0] == 0)
    if lam[-1] - lam[-2] > 1e-3 * lam[-1]:  # a simple top eigenvalue: the shape is its eigenvector
        ref = vec[:, -1] / vec[np.argmax(np.abs(vec[:, -1])), -1]
        got = shape[free] / shape[free][np.argmax(np.abs(ref))]
        assert np.max(np.abs(got - ref)) < 1e-4


def test_lanczos_converges_to_the_dense_top_eigenvalue_on_a_long_chain(make_scene, lego_config) -> None:
    """500 DOFs (beyond the dense limit): Lanczos on the matrix-free operator, warm-started Lanczos
    from the top mode, against the dense eigenvalue of the same operator."""
    lego_config["lattice"].update(n_units=250, left="free")
    system = MODELS["rotating_squares_chain"].build(make_scene(lego_config).lattice)
    op, idx = dynamical_operator(system, empty_terms())
    assert idx.size > linalg.DENSE_LIMIT
    with single_blas_thread():
        lam = np.linalg.eigvalsh(linalg.dense_matrix(op, system.ndof, idx))
    assert omega_max(system, empty_terms()) ** 2 == pytest.approx(lam[-1], rel=1e-5)
    top, x = linalg.top_eigenpair(op, system.ndof, idx)
    assert top == pytest.approx(lam[-1], rel=1e-8)
    warm, _ = linalg.warm_lanczos(op, x + 1e-3 * np.random.default_rng(1).standard_normal(x.size), 6)
    assert lam[-1] * (1 - 1e-6) <= warm <= lam[-1] * (1 + 1e-9)  # warm start: tight; a Ritz value: a lower bound
    cold, _ = linalg.warm_lanczos(op, np.random.default_rng(2).standard_normal(x.size), 6)
    assert cold <= lam[-1] * (1 + 1e-9)


def _spectrum(K: np.ndarray, mass: np.ndarray) -> np.ndarray:
    return np.sort(eigh(K, np.diag(mass), eigvals_only=True))


def _spring(K: np.ndarray, i: int, j: int, k: float) -> None:
    K[i, i] += k
    K[j, j] += k
    K[i, j] -= k
    K[j, i] -= k


def test_bloch_bands_of_a_1d_cell_are_the_periodic_chain_spectrum() -> None:
    """Diatomic chain (masses 1, 2.5) with nearest (k1, k2 alternating) and next-nearest (k3) springs,
    periodic over P cells: the Bloch ω² at q = 2πj/P are its eigenvalues."""
    P, mass = 7, np.array([1.0, 2.5])
    n = 2 * P
    K = np.zeros((n, n))
    for s in range(n):
        _spring(K, s, (s + 1) % n, 1.0 if s % 2 == 0 else 0.4)
        _spring(K, s, (s + 2) % n, 0.15)
    cell_of = (np.arange(n) // 2).astype(float)
    cell = linalg.read_cell(lambda x: K @ x, n, [6, 7], np.arange(n) % 2, cell_of, mass,
                            keep=lambda off: np.abs(off[:, 0]) <= P // 2)
    q = 2 * math.pi * np.arange(P) / P
    bands = linalg.bloch_eigen(cell, q)
    assert np.sort(bands.ravel()) == pytest.approx(_spectrum(K, np.tile(mass, P)), abs=1e-12)
    w = linalg.bloch_frequencies(cell, q)
    assert w[0, 0] == pytest.approx(0.0, abs=1e-7) and np.all(np.isfinite(w))


def test_bloch_bands_of_a_2d_cell_are_the_periodic_sheet_spectrum() -> None:
    """Square lattice with a two-site cell (a checkerboard of masses 1 and 3), springs to the four
    nearest neighbours (k 1 along x, 0.6 along y) and along one diagonal (0.2), on a 6 × 4 torus;
    one DOF per site: the Bloch ω² at the torus's wave vectors are its eigenvalues."""
    nx, ny = 6, 4
    n = nx * ny
    site = lambda ix, iy: (iy % ny) * nx + ix % nx
    K = np.zeros((n, n))
    for iy in range(ny):
        for ix in range(nx):
            _spring(K, site(ix, iy), site(ix + 1, iy), 1.0)
            _spring(K, site(ix, iy), site(ix, iy + 1), 0.6)
            _spring(K, site(ix, iy), site(ix + 1, iy + 1), 0.2)
    iy, ix = np.divmod(np.arange(n), nx)
    sub = (ix + iy) % 2
    mass_site = np.where(sub == 0, 1.0, 3.0)
    wrap = lambda d, m: (d + m // 2) % m - m // 2
    pos = np.stack([wrap(ix, nx), wrap(iy, ny)], axis=1).astype(float)
    # cell: site 0 (sublattice 0) and its right neighbour (sublattice 1); positions by minimum image
    cell = linalg.read_cell(lambda x: K @ x, n, [0, 1], sub, pos, [1.0, 3.0])
    # wave vectors of the torus folded into the cell's zone: exp(i k·r) periodic over the torus
    ks = np.array([[2 * math.pi * a / nx, 2 * math.pi * b / ny] for a in range(nx) for b in range(ny)])
    bands = linalg.bloch_eigen(cell, ks)  # each torus mode appears twice (two sites per cell)
    assert np.sort(bands.ravel()) == pytest.approx(np.repeat(_spectrum(K, mass_site), 2), abs=1e-12)


def _periodic_squares_sheet(make_scene, scene_dict, theta0: float, n: int):
    lattice = dict(EXAMPLE_LATTICES["rotating_squares_sheet"]["theta0-3x4"]["lattice"], n_rows=n, n_cols=n,
                   theta0_rad=theta0, left="periodic", right="periodic", bottom="periodic", top="periodic")
    lat = make_scene(scene_dict(lattice)).lattice
    system = MODELS[lat.kind].build(lat)
    K = linalg.dense_matrix(hessian_operator(system, empty_terms()), system.ndof)
    return lat, system, _spectrum(K, system.mass)


@pytest.mark.parametrize("theta0", [0.0, 0.2])
def test_squares_sheet_bloch_cell_gives_the_periodic_sheet_spectrum(theta0, make_scene, scene_dict) -> None:
    """The two-unit cell of the rotating-squares sheet (linear.sheet) at the wave vectors of a
    6 × 6 torus: its eigenfrequencies, each twice (k and k + (π, π)/a fold onto the same modes)."""
    lat, system, lam = _periodic_squares_sheet(make_scene, scene_dict, theta0, 6)
    h = system.spacing_m / system.scales.length_m
    ks = np.array([[2 * math.pi * a / (6 * h), 2 * math.pi * b / (6 * h)] for a in range(6) for b in range(6)])
    bands = np.sort(linalg.bloch_eigen(squares_cell(lat), ks).ravel())
    np.testing.assert_allclose(bands, np.repeat(lam, 2), rtol=1e-6, atol=1e-7 * lam.max())


def test_plan_dispersion_bands_are_periodic_sheet_eigenvalues(make_scene, scene_dict) -> None:
    """plan.domain's bands along x (k_y = 0) at the torus's k_x are eigenvalues of the periodic sheet."""
    _, system, lam = _periodic_squares_sheet(make_scene, scene_dict, 0.15, 8)
    disp = bloch_dispersion(system, empty_terms(), n_k=5)  # k = 0, π/4, …, π: allowed on 8 columns
    w2 = disp.omega.ravel() ** 2
    gap = np.min(np.abs(w2[:, None] - lam[None, :]), axis=1)
    assert np.max(gap) < 1e-6 * lam.max()
    assert disp.omega.shape == (5, 12) and disp.stable


def _banded_matrix(n: int, blocks: int, band: int, extras: int, seed: int = 3) -> np.ndarray:
    """A random symmetric matrix in the lattice layout of ``linalg.banded_row_sums``: field-major
    blocks of n sites coupled within ``band`` sites, plus extra DOFs coupled to a few sites."""
    rng = np.random.default_rng(seed)
    nd = blocks * n + extras
    a = np.zeros((nd, nd))
    site = np.arange(blocks * n) % n
    near = np.abs(site[:, None] - site[None, :]) <= band
    a[: blocks * n, : blocks * n] = np.where(near, rng.standard_normal((blocks * n, blocks * n)), 0.0)
    for e in range(blocks * n, nd):
        a[e, rng.integers(0, blocks * n, 2)] = rng.standard_normal(2)
        a[e, e] = 5.0
    return 0.5 * (a + a.T)


@pytest.mark.parametrize("band", [1, 2])
def test_banded_row_sums_are_the_absolute_row_sums_and_bound_the_top_eigenvalue(band) -> None:
    """Probing with combs recovers Σ_j |A_ij| exactly (the dense matrix is the oracle), and the
    bounds bracket the dense λ_max: Gershgorin above, a window's principal submatrix below."""
    a = _banded_matrix(n=60, blocks=2, band=band, extras=1)
    op = lambda x: a @ x  # noqa: E731
    sums = linalg.banded_row_sums(op, 60, a.shape[0], band)
    np.testing.assert_allclose(sums.sum(axis=0), np.abs(a).sum(axis=1), rtol=1e-12)
    np.testing.assert_allclose(sums[0, :60], np.abs(a[:60, :60]).sum(axis=1), rtol=1e-12)  # by field
    lo, up = linalg.banded_bounds(op, 60, a.shape[0])
    top = np.linalg.eigvalsh(a)[-1]
    assert lo <= top * (1 + 1e-12) and top <= up * (1 + 1e-12)


def test_banded_row_sums_refuse_a_matrix_with_a_coupling_outside_the_band() -> None:
    """One coupling 10 sites apart: the probes would fold it onto a wrong column; the random
    product check notices and the bound is refused (None), for every band tried."""
    a = _banded_matrix(n=60, blocks=2, band=1, extras=0)
    a[5, 15] = a[15, 5] = 0.7
    op = lambda x: a @ x  # noqa: E731
    assert linalg.banded_row_sums(op, 60, 120, 1) is None
    assert linalg.banded_bounds(op, 60, 120) is None


def test_omega_max_of_a_large_chain_is_the_bound_above_the_true_value(make_scene, lego_config, monkeypatch) -> None:
    """Above ``BOUND_MIN_DOFS`` (lowered here) a uniform LEGO chain's ω_max is its Gershgorin bound:
    never below the dense ω_max, and within ``BOUND_MARGIN`` of it; a predeformed chain, whose
    bound is loose by ~9 %, gets the whole-lattice solve (the Lanczos value) instead."""
    from flexmm import stability

    lego_config["lattice"].update(n_units=250, left="free")
    system = MODELS["rotating_squares_chain"].build(make_scene(lego_config).lattice)
    op, idx = dynamical_operator(system, empty_terms())
    with single_blas_thread():
        dense = math.sqrt(np.linalg.eigvalsh(linalg.dense_matrix(op, system.ndof, idx))[-1])
    lanczos = omega_max(system, empty_terms())
    monkeypatch.setattr(stability, "BOUND_MIN_DOFS", 100)
    bound = omega_max(system, empty_terms())
    assert dense <= bound <= dense * (1 + stability.BOUND_MARGIN)
    assert bound != lanczos
    lo, up = linalg.banded_bounds(op, system.n_sites, system.ndof)
    assert lo <= dense ** 2 <= up * (1 + 1e-9)
    from pathlib import Path

    from flexmm.assemble import build_system
    from flexmm.config.loader import load_scene

    monkeypatch.setattr(stability, "BOUND_MIN_DOFS", 10**9)
    path = Path(__file__).resolve().parents[1] / "configs" / "predeformed_rarefaction_soliton.yaml"
    system, terms = build_system(load_scene(path))
    q_ref = np.concatenate([system.rest_state, system.q0[system.rest_state.size:]])
    solved = omega_max(system, terms, q_ref)
    monkeypatch.setattr(stability, "BOUND_MIN_DOFS", 100)
    assert omega_max(system, terms, q_ref) == solved
