"""Planar sheets on the 2-row strip (exact) or the n_v = 2 chain (flexmm.plan.dimension)."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import LEGO_SHEET

from flexmm.accuracy import integrate
from flexmm.assemble import build_problem
from flexmm.config import scene_from_dict
from flexmm.integrators import INTEGRATORS
from flexmm.plan.dimension import reduce_dimension

SHEET = dict(LEGO_SHEET, n_rows=6, n_cols=40, k_shear_n_per_m=14338,  # a stiffer shear spring (0.2 k_l)
             left="driven", bottom="periodic", top="periodic")
IMPACT = {"kind": "impact", "end": "left", "velocity_m_s": 3.0, "angular_velocity_rad_s": 300.0}


def sheet_scene(excitation=IMPACT, imperfection=None, **lattice):
    data = {"name": "s", "lattice": {**SHEET, **lattice}, "excitation": excitation,
            "solver": {"duration_s": 0.004}}
    if imperfection:
        data["imperfection"] = imperfection
    return scene_from_dict(data)


def test_strip_reproduces_the_sheet():
    sc = sheet_scene(imperfection={"kind": "rotation_seed", "theta_rad": 1e-3,
                                   "sites": [r * 40 + 5 for r in range(6)]})
    strip, note = reduce_dimension(sc, "strip")
    assert strip.lattice.n_rows == 2 and "exact" in note
    assert strip.imperfection.sites == [5, 45]
    full, red = build_problem(sc), build_problem(strip)
    spec = INTEGRATORS["velocity_verlet"]
    h = 0.2 / full.omega_max
    q, *_ = integrate(full, spec, h, full.duration)
    qs, *_ = integrate(red, spec, h, full.duration)
    n, m = full.system.n_sites, red.system.n_sites
    for f in range(3):  # u, v, θ of rows 0 and 1 equal the strip's, every other row repeats them
        rows = q[f * n : (f + 1) * n].reshape(6, 40)
        strip_rows = qs[f * m : (f + 1) * m].reshape(2, 40)
        assert np.allclose(rows[0::2], strip_rows[0], atol=1e-12, rtol=0)
        assert np.allclose(rows[1::2], strip_rows[1], atol=1e-12, rtol=0)
    assert np.max(np.abs(q[2 * n :])) > 1e-3  # something happened


def test_chain_reduction_is_the_n_v_2_chain():
    chain, note = reduce_dimension(sheet_scene(), "chain")
    lat = chain.lattice
    assert lat.kind == "rotating_squares_chain" and lat.n_units == 40
    assert lat.n_lateral == 2 and lat.lateral_stretch and "approximate" in note
    assert chain.excitation.velocity_m_s == 3.0


@pytest.mark.parametrize("change,why", [
    (dict(bottom="free", top="free"), "not periodic"),
    (dict(excitation={**IMPACT, "sites": [0]}), "single units"),
    (dict(excitation={"kind": "impact", "end": "bottom", "velocity_m_s": 1.0}), "not a wave along x"),
    (dict(imperfection={"kind": "random_rotation", "std_rad": 1e-3}), "not uniform across rows"),
    (dict(imperfection={"kind": "rotation_seed", "theta_rad": 1e-3, "sites": [5]}), "whole columns"),
])
def test_not_planar(change, why):
    kw = dict(change)
    exc = kw.pop("excitation", IMPACT)
    imp = kw.pop("imperfection", None)
    if exc.get("end") == "bottom":
        kw["bottom"] = "driven"
        kw["top"] = "driven"
        kw["left"] = "free"
    try:
        sc = sheet_scene(exc, imp, **kw)
    except Exception:  # the combination is rejected by the schema itself
        return
    reduced, note = reduce_dimension(sc)
    assert reduced is None and why in note


def initial_scene(fields, pinned=()):
    data = sheet_scene().model_dump(mode="json")
    data["excitation"] = {"kind": "none"}
    data["lattice"]["left"] = "free"
    data["initial"] = {"fields": fields, "pinned": list(pinned)}
    return scene_from_dict(data)


def test_initial_fields_not_uniform_across_rows_keep_the_sheet():
    """A 2D initial disturbance (issue #32, item 1) is not silently run as the strip."""
    bump = "0.01 * exp(-((x - 0.2)**2 + (y - 0.05)**2) / 0.0004)"
    for fields in ([{"field": "theta", "value": bump}], [{"field": "u", "rate": "0.1 * cos(pi * j / 3)"}]):
        reduced, note = reduce_dimension(initial_scene(fields), "strip")
        assert reduced is None and "initial.fields.0" in note


def test_initial_fields_with_period_two_run_on_the_strip():
    fields = [{"field": "theta", "value": "0.01 * exp(-(x - 0.2)**2 / 0.0004)"},
              {"field": "v", "value": "1e-5 * cos(pi * j) * exp(-(x - 0.2)**2 / 0.0004)"}]
    sc = initial_scene(fields, pinned=[{"field": "u", "sites": [r * 40 + 39 for r in range(6)]}])
    strip, note = reduce_dimension(sc, "strip")
    assert strip is not None and strip.lattice.n_rows == 2, note
    assert strip.initial.pinned[0].sites == [39, 79]
    full, red = build_problem(sc), build_problem(strip)
    spec = INTEGRATORS["velocity_verlet"]
    h = 0.2 / full.omega_max
    q, *_ = integrate(full, spec, h, 0.002)
    qs, *_ = integrate(red, spec, h, 0.002)
    n, m = full.system.n_sites, red.system.n_sites
    for f in range(3):
        rows = q[f * n : (f + 1) * n].reshape(6, 40)
        strip_rows = qs[f * m : (f + 1) * m].reshape(2, 40)
        assert np.allclose(rows[0::2], strip_rows[0], atol=1e-12, rtol=0)
        assert np.allclose(rows[1::2], strip_rows[1], atol=1e-12, rtol=0)
    chain, note = reduce_dimension(sc, "chain")
    assert chain is None and "no lateral displacement" in note


def test_initial_from_elsewhere_keeps_the_sheet():
    sc = initial_scene([], pinned=[{"field": "u", "sites": [39]}])
    reduced, note = reduce_dimension(sc, "strip")
    assert reduced is None and "whole columns" in note
