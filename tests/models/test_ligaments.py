"""The general rigid-unit ligament law (flexmm.models.ligaments, docs/physics.md §1.9).

Oracles: the numpy reference, finite differences of the energy (force) and of the force
(Hessian-vector product), zero net force, and the rotating-squares sheet's own kernel — the
sheet is this law on its hinge points, so the two give the same forces.
"""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from conftest import EXAMPLE_LATTICES
from flexmm.config import scene_from_dict
from flexmm.models import MODELS
from flexmm.models import ligaments as lg
from flexmm.models.hinge import H_HALF_A, H_HALF_B, H_KL, H_KS, H_KT, H_REST, H_SIGN
from flexmm.models.kernels import kernels_of
from flexmm.models.rotating_triangles import kagome_hinges, sublattice_sign


def random_network(rng, n=7, n_lig=15, law="paper"):
    """Units at random centres with ligaments between random points, axes, stiffnesses and rest
    lengths, under one of the ligament laws."""
    ua = rng.integers(0, n, n_lig)
    ub = (ua + rng.integers(1, n, n_lig)) % n
    lig = np.zeros((n_lig, lg.N_LIGAMENT_PARAMS))
    lig[:, [lg.L_AX, lg.L_AY, lg.L_BX, lg.L_BY, lg.L_OX, lg.L_OY]] = rng.normal(size=(n_lig, 6))
    ang = rng.uniform(0, 2 * np.pi, n_lig)
    lig[:, lg.L_EX], lig[:, lg.L_EY] = np.cos(ang), np.sin(ang)
    lig[:, [lg.L_KL, lg.L_KS, lg.L_KT]] = rng.uniform(0.2, 2.0, (n_lig, 3))
    lig[:, lg.L_LEN] = rng.uniform(0.5, 1.5, n_lig)
    args = lg.NetworkArgs(ua.astype(np.int64), ub.astype(np.int64), lig, np.empty(n), np.empty(n), lg.LAWS[law])
    return args, 0.3 * rng.normal(size=3 * n)


def force(q, args):
    f = np.empty(q.size)
    lg.network_force(q, args, f)
    return f


@pytest.mark.parametrize("law", sorted(lg.LAWS))
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_network_force_is_minus_the_energy_gradient_and_matches_the_reference(seed, law):
    args, q = random_network(np.random.default_rng(seed), law=law)
    f = force(q, args)
    e_ref, f_ref = lg.network_reference(q, args)
    assert lg.network_energy(q, args) == pytest.approx(e_ref, rel=1e-13)
    assert_allclose(f, f_ref, rtol=0, atol=1e-13 * np.abs(f_ref).max())
    h = 1e-6
    fd = np.empty_like(q)
    for k in range(q.size):
        up, dn = q.copy(), q.copy()
        up[k] += h
        dn[k] -= h
        fd[k] = -(lg.network_energy(up, args) - lg.network_energy(dn, args)) / (2 * h)
    assert_allclose(f, fd, rtol=0, atol=1e-7 * np.abs(f).max())
    n = q.size // 3
    assert abs(f[:n].sum()) < 1e-12 and abs(f[n : 2 * n].sum()) < 1e-12  # internal forces balance


@pytest.mark.parametrize("law", sorted(lg.LAWS))
@pytest.mark.parametrize("seed", [3, 4])
def test_network_hessian_vector_product_is_the_force_derivative(seed, law):
    rng = np.random.default_rng(seed)
    args, q = random_network(rng, law=law)
    dq = rng.normal(size=q.size)
    hv = np.empty_like(q)
    lg.network_hvp(q, args, dq, hv)
    h = 1e-6
    fd = -(force(q + h * dq, args) - force(q - h * dq, args)) / (2 * h)
    assert_allclose(hv, fd, rtol=0, atol=1e-7 * np.abs(hv).max())


def difflexmm_energy(q, centres, r_a, r_b, v0, ua, ub, k, law):
    """DifFlexMM's ligament energy in its own variables: each joined point moves with its unit,
    d = x + (R(θ) − I) r, the bond is c = v0 + d_b − d_a (v0 the rest bond vector, l0 = |v0|);
    nonlinear strains (|c|/l0 − 1, the angle of c less that of R(θ̄) v0 in [−π, π), Δθ) or
    linearised ones (d·v0/l0², v0 × d/l0² − θ̄, Δθ), E = ½ k_l (ε l0)² + ½ k_s (γ l0)² + ½ k_θ Δθ²."""
    n = centres.shape[0]
    x, th = q[: 2 * n].reshape(2, n).T, q[2 * n :]

    def moved(unit, r):
        c, s = np.cos(th[unit]), np.sin(th[unit])
        return x[unit] + np.stack([c * r[:, 0] - s * r[:, 1], s * r[:, 0] + c * r[:, 1]], 1) - r

    d = moved(ub, r_b) - moved(ua, r_a)
    l0 = np.hypot(v0[:, 0], v0[:, 1])
    mean, dth = 0.5 * (th[ua] + th[ub]), th[ub] - th[ua]
    if law == "difflexmm":
        c = v0 + d
        axial = np.hypot(c[:, 0], c[:, 1]) / l0 - 1
        pushed = np.arctan2(v0[:, 1], v0[:, 0]) + mean
        shear = np.mod(np.arctan2(c[:, 1], c[:, 0]) - pushed + np.pi, 2 * np.pi) - np.pi
    else:
        axial = np.sum(d * v0, 1) / l0**2
        shear = (v0[:, 0] * d[:, 1] - v0[:, 1] * d[:, 0]) / l0**2 - mean
    return float(np.sum(0.5 * k[0] * (axial * l0) ** 2 + 0.5 * k[1] * (shear * l0) ** 2 + 0.5 * k[2] * dth**2))


@pytest.mark.parametrize("law", ["difflexmm", "difflexmm_linear"])
def test_difflexmm_laws_are_difflexmms_ligament_energy(law):
    """Units at random centres, ligaments with random rest bond vectors v0 between random points:
    the network's energy (table: axis v0/|v0|, rest length |v0|, rest offset X_b − X_a − v0)
    equals DifFlexMM's ligament energy written in its own variables, at large random states."""
    rng = np.random.default_rng(21)
    n, n_lig = 6, 12
    centres = 3 * rng.normal(size=(n, 2))
    ua = rng.integers(0, n, n_lig)
    ub = (ua + rng.integers(1, n, n_lig)) % n
    r_a, v0 = rng.normal(size=(n_lig, 2)), rng.normal(size=(n_lig, 2))
    r_b = centres[ua] + r_a + v0 - centres[ub]
    k = rng.uniform(0.2, 2.0, 3)
    lig = np.zeros((n_lig, lg.N_LIGAMENT_PARAMS))
    length = np.hypot(v0[:, 0], v0[:, 1])
    lig[:, [lg.L_AX, lg.L_AY]], lig[:, [lg.L_BX, lg.L_BY]] = r_a, r_b
    lig[:, [lg.L_OX, lg.L_OY]] = centres[ub] - centres[ua] - v0
    lig[:, [lg.L_EX, lg.L_EY]] = v0 / length[:, None]
    lig[:, [lg.L_KL, lg.L_KS, lg.L_KT, lg.L_LEN]] = np.column_stack([np.tile(k, (n_lig, 1)), length])
    args = lg.NetworkArgs(ua, ub, lig, np.empty(n), np.empty(n), lg.LAWS[law])
    for amplitude in (0.0, 0.05, 0.5):
        q = amplitude * rng.normal(size=3 * n)
        expected = difflexmm_energy(q, centres, r_a, r_b, v0, ua, ub, k, law)
        assert lg.network_energy(q, args) == pytest.approx(expected, rel=1e-12, abs=1e-15)


def test_linearised_law_is_the_nonlinear_laws_linearisation():
    """At rest the two DifFlexMM laws have the same Hessian (the same small-amplitude waves), and
    the energies part at third order in the amplitude."""
    rng = np.random.default_rng(8)
    nonlinear, _ = random_network(rng, law="difflexmm")
    lig = nonlinear.ligaments  # stress-free at rest: g = 0 at q = 0
    lig[:, [lg.L_OX, lg.L_OY]] = lig[:, [lg.L_AX, lg.L_AY]] - lig[:, [lg.L_BX, lg.L_BY]]
    linear = nonlinear._replace(law=lg.LAWS["difflexmm_linear"])
    q0 = np.zeros(3 * nonlinear.cos.size)
    for dq in rng.normal(size=(3, q0.size)):
        h_nl, h_lin = np.empty_like(q0), np.empty_like(q0)
        lg.network_hvp(q0, nonlinear, dq, h_nl)
        lg.network_hvp(q0, linear, dq, h_lin)
        assert_allclose(h_nl, h_lin, rtol=0, atol=1e-13 * np.abs(h_lin).max())
    dq = rng.normal(size=q0.size)
    gaps = [abs(lg.network_energy(s * dq, nonlinear) - lg.network_energy(s * dq, linear)) for s in (1e-2, 5e-3)]
    assert gaps[0] / gaps[1] == pytest.approx(8.0, rel=0.05)


def sheet_as_network(system):
    """The ligament table of a rotating-squares sheet: its hinge points at rest, each hinge's
    axis, and its rest offset (the rest length along the axis, no shear offset)."""
    ha, hb, hax, hprm, theta0 = system.args[:5]
    n = theta0.size
    # σ_A from the hinge sign (σ_A on x hinges, −σ_A on y hinges); σ_B = −σ_A
    sig_a = np.where(hax == 0, hprm[:, H_SIGN], -hprm[:, H_SIGN])
    sigma = np.zeros(n)
    sigma[ha], sigma[hb] = sig_a, -sig_a
    phi0 = sigma * theta0  # the units' orientations at rest
    lig = np.zeros((ha.size, lg.N_LIGAMENT_PARAMS))
    x = hax == 0
    hA, hB = hprm[:, H_HALF_A], hprm[:, H_HALF_B]
    ca, sa, cb, sb = np.cos(phi0[ha]), np.sin(phi0[ha]), np.cos(phi0[hb]), np.sin(phi0[hb])
    # x hinge: right corner of A, left corner of B; y hinge: top of A, bottom of B
    lig[:, lg.L_AX], lig[:, lg.L_AY] = np.where(x, hA * ca, -hA * sa), np.where(x, hA * sa, hA * ca)
    lig[:, lg.L_BX], lig[:, lg.L_BY] = np.where(x, -hB * cb, hB * sb), np.where(x, -hB * sb, -hB * cb)
    lig[:, lg.L_OX], lig[:, lg.L_OY] = np.where(x, hprm[:, H_REST], 0.0), np.where(x, 0.0, hprm[:, H_REST])
    lig[:, lg.L_EX], lig[:, lg.L_EY] = np.where(x, 1.0, 0.0), np.where(x, 0.0, 1.0)
    lig[:, lg.L_KL], lig[:, lg.L_KS], lig[:, lg.L_KT] = hprm[:, H_KL], hprm[:, H_KS], hprm[:, H_KT]
    return lg.NetworkArgs(ha, hb, lig, np.empty(n), np.empty(n)), sigma


@pytest.mark.parametrize("lattice", [
    {"n_rows": 4, "n_cols": 5, "theta0_rad": 0.25},
    {"n_rows": 3, "n_cols": 6, "theta0_rad": 0.1, "ligament_length_m": 0.002, "left": "periodic",
     "right": "periodic"},
])
def test_rotating_squares_sheet_is_the_ligament_law_on_its_hinge_points(lattice):
    """The sheet's kernel and the general law on the sheet's geometry give the same forces (θ of
    the sheet is staggered: the units' rotations are σθ, their torques σ times the sheet's)."""
    cfg = {"kind": "rotating_squares_sheet", "a_m": 0.01, "k_long_n_per_m": 1e4, "k_shear_n_per_m": 3e3,
           "k_rot_n_m_per_rad": 2e-3, "areal_density_kg_m2": 20.0, **lattice}
    scene = scene_from_dict({"name": "t", "lattice": cfg, "solver": {"duration_s": 1e-3}})
    system = MODELS["rotating_squares_sheet"].build(scene.lattice)
    net, sigma = sheet_as_network(system)
    assert_same_forces(system, net, sigma, (0.0, 0.05, 0.4), seed=5)


def assert_same_forces(system, net, sigma, amplitudes, seed):
    """The model's forces and energy at random staggered states equal the network's at the same
    states with rotations σθ (torques σ times), to 1e-13 of the largest force."""
    n = sigma.size
    rng = np.random.default_rng(seed)
    for amplitude in amplitudes:
        q = amplitude * rng.normal(size=3 * n)
        f_model = np.empty(3 * n)
        system.force(q, system.args, f_model)
        qn = q.copy()
        qn[2 * n :] *= sigma
        f_net = force(qn, net)
        f_net[2 * n :] *= sigma
        assert_allclose(f_net, f_model, rtol=0, atol=1e-13 * max(np.abs(f_model).max(), 1.0))
        assert lg.network_energy(qn, net) == pytest.approx(system.energy(q, system.args), rel=1e-13, abs=1e-15)


def triangles_from_vertices(lat, stiff, q):
    """Energy and forces of a triangle lattice written from its vertices (docs/physics.md §1.6),
    not from the ligament table: hinge axes e from ``kagome_hinges``, the actual rotations
    φ = σ(θ0 + θ) (σ_B = −σ_A), vertices r_A = h R(φ_A) e and r_B = −h R(φ_B) e (h = a/√3), the gap
    g = x_B − x_A + D e + r_B − r_A (D = 2h cos θ0), elongation g·e, shear g·n, hinge rotation
    θ_A + θ_B; ∂E/∂φ of a vertex r moved by its unit is ±(ẑ × r)·G. ``stiff`` (H, 3): k_l, k_s, k_θ."""
    n_rows, n_cols = getattr(lat, "n_rows", 1), getattr(lat, "n_cols", getattr(lat, "n_units", 0))
    ha, hb, beta = kagome_hinges(n_rows, n_cols, lat.left == "periodic", getattr(lat, "bottom", "") == "periodic")
    n, t0, h = n_rows * n_cols, lat.theta0_rad, 1 / np.sqrt(3)
    sig_a = sublattice_sign(n_rows, n_cols)[ha]
    u, v, th = q[:n], q[n : 2 * n], q[2 * n : 3 * n]
    e = np.stack([np.cos(beta), np.sin(beta)], 1)
    nrm = np.stack([-e[:, 1], e[:, 0]], 1)

    def rot(vec, ang):
        c, s = np.cos(ang), np.sin(ang)
        return np.stack([c * vec[:, 0] - s * vec[:, 1], s * vec[:, 0] + c * vec[:, 1]], 1)

    r_a, r_b = rot(h * e, sig_a * (t0 + th[ha])), rot(-h * e, -sig_a * (t0 + th[hb]))
    gap = np.stack([u[hb] - u[ha], v[hb] - v[ha]], 1) + 2 * h * np.cos(t0) * e + r_b - r_a
    el, es, ep = np.sum(gap * e, 1), np.sum(gap * nrm, 1), th[ha] + th[hb]
    kl, ks, kt = stiff.T
    energy = 0.5 * float(np.sum(kl * el**2 + ks * es**2 + kt * ep**2))
    G = (kl * el)[:, None] * e + (ks * es)[:, None] * nrm
    cross = lambda r: -r[:, 1] * G[:, 0] + r[:, 0] * G[:, 1]  # noqa: E731 - (ẑ × r)·G
    f = np.zeros(3 * n)
    for k, off in ((0, 0), (1, n)):
        np.add.at(f, off + ha, G[:, k])
        np.add.at(f, off + hb, -G[:, k])
    np.add.at(f, 2 * n + ha, sig_a * cross(r_a) - kt * ep)
    np.add.at(f, 2 * n + hb, sig_a * cross(r_b) - kt * ep)
    return energy, f


TRIANGLE_EXAMPLES = [(kind, name, ex["lattice"]) for kind, exs in EXAMPLE_LATTICES.items()
                     if kind.startswith("rotating_triangles") for name, ex in exs.items()]


@pytest.mark.parametrize(("kind", "name", "lattice"), TRIANGLE_EXAMPLES, ids=[f"{k}-{n}" for k, n, _ in TRIANGLE_EXAMPLES])
def test_rotating_triangles_are_the_ligament_law_on_their_hinge_points(kind, name, lattice):
    """Every triangle example of tests/conftest.py (strip and kagome, twisted, periodic, graded):
    the triangles' kernel and the general law on their hinge points give the same forces and
    energies as the hinges written from the triangles' vertices (θ staggered: the units'
    rotations are σθ); the triangles run on the network's kernels, with their torques times σ."""
    scene = scene_from_dict({"name": "t", "lattice": lattice, "solver": {"duration_s": 1e-3}})
    system = MODELS[kind].build(scene.lattice)
    net, sigma = system.args.network, system.args.sigma
    stiff = net.ligaments[:, [lg.L_KL, lg.L_KS, lg.L_KT]]
    rng = np.random.default_rng(9)
    n = sigma.size
    for amplitude in (0.02, 0.3):
        q = amplitude * rng.normal(size=3 * n)
        e_ref, f_ref = triangles_from_vertices(scene.lattice, stiff, q)
        f = np.empty(3 * n)
        system.force(q, system.args, f)
        assert_allclose(f, f_ref, rtol=0, atol=1e-13 * max(np.abs(f_ref).max(), 1.0))
        assert system.energy(q, system.args) == pytest.approx(e_ref, rel=1e-13, abs=1e-15)
        e_k, f_k = kernels_of(type(system.args)).reference(q, system.args)
        assert_allclose(f_k, f_ref, rtol=0, atol=1e-13 * max(np.abs(f_ref).max(), 1.0))
        assert e_k == pytest.approx(e_ref, rel=1e-13, abs=1e-15)
