"""Every scalar law of flexmm.models.laws: compiled == numpy reference, force == −dE/dz."""

import numpy as np
import pytest

from flexmm.models import laws as lw

RNG = np.random.default_rng(7)
X_TABLE = np.linspace(-1.5, 2.0, 15)
TAB = lw.spline_table(X_TABLE, np.sin(2 * X_TABLE) + 0.3 * X_TABLE**2)

#: a few parameter rows per law (shift first) and the z range where the law is smooth
CASES = {
    "poly": ([lw.poly_row(RNG.normal(size=8) / np.arange(1, 9), shift=0.1),
              lw.poly_row([0.0, 0.5, -0.4, 0.25])], (-1.5, 1.5)),
    "hertz": ([lw.row(1.0, 1.5, 0.0), lw.row(2.5, 1.5, 0.2, shift=0.05), lw.row(0.7, 2.0, 0.1)],
              (-1.0, 1.0)),
    "toda": ([lw.row(1.0, 1.0), lw.row(0.5, 3.0, shift=-0.1)], (-1.0, 2.0)),
    "dipole": ([lw.row(0.8, 1.0, 3.0), lw.row(0.1, 1.5, 4.0, shift=0.2)], (-0.7, 2.0)),
    "table": ([lw.row(0.0, X_TABLE.size), lw.row(0.0, X_TABLE.size, shift=0.3)], (-2.5, 3.0)),
    "sine": ([lw.row(0.3, 2 * np.pi), lw.row(1.2, 1.3, shift=0.5)], (-3.0, 3.0)),
}


def test_every_law_has_cases():
    assert set(CASES) == set(lw.LAWS)


@pytest.mark.parametrize("name", sorted(lw.LAWS))
def test_mass_chain_law_compiled_matches_reference(name):
    code = lw.LAWS[name].code
    rows, (lo, hi) = CASES[name]
    z = np.linspace(lo, hi, 401)
    for prm in rows:
        tab = TAB if name == "table" else np.zeros(1)
        got = np.array([lw.law(code, zz, prm, tab) for zz in z])
        e_ref, d_ref = lw.reference(code, z, prm, tab)
        scale = 1.0 + np.abs(e_ref).max()
        np.testing.assert_allclose(got[:, 0], e_ref, atol=1e-11 * scale, rtol=1e-10)
        np.testing.assert_allclose(got[:, 1], d_ref, atol=1e-10 * (1 + np.abs(d_ref).max()), rtol=1e-9)


@pytest.mark.parametrize("name", sorted(lw.LAWS))
def test_mass_chain_law_force_is_energy_gradient(name):
    code = lw.LAWS[name].code
    rows, (lo, hi) = CASES[name]
    h = 1e-6
    z = np.linspace(lo, hi, 97) + 1e-3  # avoid landing exactly on a kink
    for prm in rows:
        tab = TAB if name == "table" else np.zeros(1)
        for zz in z:
            ep, _ = lw.law(code, zz + h, prm, tab)
            em, _ = lw.law(code, zz - h, prm, tab)
            _, d = lw.law(code, zz, prm, tab)
            assert d == pytest.approx((ep - em) / (2 * h), rel=1e-6, abs=1e-7)


def test_mass_chain_table_interpolates_and_extends_linearly():
    x = np.linspace(0.0, 3.0, 7)
    f = 2.0 * x - 1.0  # a straight line is reproduced exactly by the spline
    tab = lw.spline_table(x, f)
    prm = lw.row(0.0, x.size)
    for z in (-2.0, 0.4, 1.7, 5.0):
        e, d = lw.law(lw.TABLE, z, prm, tab)
        assert d == pytest.approx(2.0 * z - 1.0, abs=1e-12)
        assert e == pytest.approx(z * z - z, abs=1e-12)  # energy zero at z = 0


def test_mass_chain_hertz_has_no_tension():
    prm = lw.row(3.0, 1.5, 0.1)
    assert lw.law(lw.HERTZ, 0.2, prm, np.zeros(1)) == (0.0, 0.0)
    e, t = lw.law(lw.HERTZ, 0.0, prm, np.zeros(1))
    assert t == pytest.approx(-3.0 * 0.1**1.5) and e > 0


#: parameter columns with a derivative (the table's start and length are indices, not parameters)
SMOOTH_COLUMNS = {"poly": range(9), "hertz": range(4), "toda": range(3), "dipole": range(4), "table": (0,),
                  "sine": range(3)}


@pytest.mark.parametrize("name", sorted(lw.LAWS))
def test_law_second_is_the_derivative_of_the_law(name):
    """``law_second``'s E'' and ∂E'/∂prm against central differences of ``law``'s E' (the one
    definition both the engine and the gradients use)."""
    code = lw.LAWS[name].code
    rows, (lo, hi) = CASES[name]
    h = 1e-6
    z = np.linspace(lo, hi, 41) + 1e-3
    dprm = np.empty(lw.N_LAW_PRM)
    for prm in rows:
        tab = TAB if name == "table" else np.zeros(1)
        for zz in z:
            d2 = lw.law_second(code, zz, prm, tab, dprm)
            fd = (lw.law(code, zz + h, prm, tab)[1] - lw.law(code, zz - h, prm, tab)[1]) / (2 * h)
            assert d2 == pytest.approx(fd, rel=1e-5, abs=1e-6)
            for c in SMOOTH_COLUMNS[name]:
                up, dn = prm.copy(), prm.copy()
                up[c] += h
                dn[c] -= h
                fd = (lw.law(code, zz, up, tab)[1] - lw.law(code, zz, dn, tab)[1]) / (2 * h)
                assert dprm[c] == pytest.approx(fd, rel=1e-5, abs=1e-6), (name, c, zz)
