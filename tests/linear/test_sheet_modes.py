"""Plane-wave acoustic modes of the 2D sheet (flexmm.linear.sheet) against independent results."""

import math
from pathlib import Path

import pytest

from flexmm.config import load_scene
from flexmm.linalg import bloch_frequencies
from flexmm.linear.sheet import acoustic_modes, squares_cell
from flexmm.theory.rotating import RotatingChainND, long_wave_speed

REPO = Path(__file__).resolve().parents[2]


def _lattice(theta0: float):
    lat = load_scene(REPO / "configs" / "a_sheet_mode_separation.yaml").lattice
    return lat.model_copy(update={"theta0_rad": theta0})


@pytest.mark.parametrize("theta0", [0.0, 0.35])
def test_longitudinal_mode_along_x_is_the_planar_chain(theta0):
    """Along x the fast mode is longitudinal with the long-wave speed of the chain with n_v = 2,
    s_v = 1 (docs/physics.md §1.2 and §1.4: a planar wave in a wide sheet), the slow one transverse."""
    lat = _lattice(theta0)
    kl, a = lat.k_long_n_per_m, lat.a_m
    chain = RotatingChainND(theta0, lat.k_shear_n_per_m / kl, lat.k_rot_n_m_per_rad / (kl * a * a),
                            lat.unit_inertia_kg_m2 / (lat.unit_mass_kg * a * a), 2, 1)
    (slow, pol_slow), (fast, pol_fast) = acoustic_modes(lat, 0.0)
    assert fast == pytest.approx(long_wave_speed(chain), rel=1e-5)
    assert abs(pol_fast) < 1e-4 and abs(abs(pol_slow) - 90.0) < 1e-4
    assert slow < fast


@pytest.mark.parametrize("deg", [10.0, 26.565, 40.0])
def test_square_symmetry_mirrors_the_modes(deg):
    """The lattice is symmetric under x ↔ y: directions φ and 90° − φ have the same speeds and
    mirror-image polarisations."""
    lat = _lattice(0.35)
    a = acoustic_modes(lat, math.radians(deg))
    b = acoustic_modes(lat, math.radians(90.0 - deg))
    for (ca, pa), (cb, pb) in zip(a, b):
        assert ca == pytest.approx(cb, rel=1e-6)
        assert pa == pytest.approx(-pb, abs=1e-4)


def test_oblique_modes_are_mixed_and_bloch_is_periodic():
    lat = _lattice(0.35)
    (_, pol_slow), (_, pol_fast) = acoustic_modes(lat, math.radians(26.565))
    assert 10.0 < abs(pol_fast) < 80.0 and 10.0 < abs(pol_slow) < 80.0  # neither purely L nor T
    assert abs(abs(pol_fast - pol_slow) - 90.0) < 1.0  # the two polarisations are orthogonal
    h = math.cos(0.35)
    k = [0.7, 0.3]
    cell = squares_cell(lat)
    w1 = bloch_frequencies(cell, k)
    w2 = bloch_frequencies(cell, [k[0] + 2 * math.pi / h, k[1] + 2 * math.pi / h])  # reciprocal lattice of the 2-unit cell
    assert w2 == pytest.approx(w1, rel=1e-8)
