"""Group speeds from the Hessian, wave reach and trimming, absorbing layers (flexmm.plan.domain)."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import LEGO_PARAMETERS

from flexmm.accuracy import integrate
from flexmm.assemble import absorbing_damping, build_problem
from flexmm.config import scene_from_dict
from flexmm.integrators import INTEGRATORS
from flexmm.models.rotating_chain import theory_parameters
from flexmm.plan.domain import bloch_dispersion, trim_scene, wave_reach
from flexmm.theory.rotating import RotatingChainND, dispersion_chain

LEGO = dict(kind="rotating_squares_chain", **LEGO_PARAMETERS)


def chain_scene(n=60, duration=0.01, excitation=None, **lattice):
    lat = {**LEGO, "n_units": n, **lattice}
    exc = excitation or {"kind": "impact", "end": "left", "velocity_m_s": 1.0, "angular_velocity_rad_s": 100.0}
    return scene_from_dict({"name": "t", "lattice": lat, "excitation": exc,
                            "solver": {"duration_s": duration}})


@pytest.mark.parametrize("theta0,n_v,s_v", [(0.0, 1, 0), (0.3, 2, 1)])
def test_bloch_dispersion_matches_chain_theory(theta0, n_v, s_v):
    sc = chain_scene(40, theta0_rad=theta0, n_lateral=n_v, lateral_stretch=bool(s_v))
    p = build_problem(sc)
    d = bloch_dispersion(p.system, p.terms)
    m = theory_parameters(sc.lattice)
    assert (m.theta0, m.n_v, m.s_v) == (theta0, n_v, s_v)
    par = RotatingChainND(theta0, m.Ks, m.Ktheta, m.alpha2, n_v, s_v)
    lo, hi = dispersion_chain(par, d.k)
    lo2, hi2 = dispersion_chain(par, d.k + np.pi)  # the 2-site probe cell folds the zone
    ref = np.sort(np.stack([lo, hi, lo2, hi2], 1), 1)
    assert np.allclose(d.omega, ref, atol=1e-6)
    assert d.stable
    # fastest signal: the longitudinal branch at k -> 0, cos(theta0)-ish in sites per unit time
    assert 0.6 < d.max_group_speed <= 1.0 + 1e-6


def test_reach_trims_and_trimming_is_exact():
    """A lattice far longer than the waves reach is trimmed; kept sites move exactly alike."""
    sc = chain_scene(600, duration=0.012)
    p = build_problem(sc)
    reach = wave_reach(sc, p.system, p.terms, p.duration)
    assert reach.keep[0] == 0 and reach.keep[1] < 600
    assert reach.sites_reached == pytest.approx(reach.speed_sites * p.duration)
    small = trim_scene(sc, reach.keep)
    ps = build_problem(small)
    spec = INTEGRATORS["velocity_verlet"]
    h = 0.2 / p.omega_max
    q, *_ = integrate(p, spec, h, p.duration)
    qs, *_ = integrate(ps, spec, h, p.duration)
    n, m = 600, small.lattice.n_units
    assert np.max(np.abs(q[:m] - qs[:m])) < 1e-12 * np.max(np.abs(q[:m])) + 1e-15
    assert np.max(np.abs(q[n : n + m] - qs[m : 2 * m])) < 1e-12


def test_trim_shifts_sites_and_drops_unreached_layer():
    sc = chain_scene(500, excitation={"kind": "soliton", "amplitude_rad": 0.4, "center_site": 300})
    data = sc.model_dump(mode="json")
    data["imperfection"] = {"kind": "rotation_seed", "theta_rad": 1e-3, "sites": [250, 10]}
    data["damping"] = {"absorbing": {"end": "both", "n_units": 30}}
    t = trim_scene(scene_from_dict(data), (200, 499))
    assert t.lattice.n_units == 300
    assert t.excitation.center_site == 100
    assert t.imperfection.sites == [50]
    assert t.damping.absorbing.end == "right"


def test_random_imperfection_is_a_source_everywhere():
    data = chain_scene(400).model_dump(mode="json")
    data["imperfection"] = {"kind": "random_rotation", "std_rad": 1e-4}
    sc = scene_from_dict(data)
    p = build_problem(sc)
    assert wave_reach(sc, p.system, p.terms, p.duration).keep is None


def test_absorbing_profile():
    data = chain_scene(200).model_dump(mode="json")
    data["damping"] = {"absorbing": {"end": "right", "n_units": 50, "max_ratio": 0.1, "power": 2}}
    sc = scene_from_dict(data)
    p = build_problem(sc)
    n = 200
    extra = absorbing_damping(p.system, sc.damping.absorbing)
    zeta_u = extra[:n] / (2 * p.system.mass[:n])
    assert np.all(zeta_u[:150] == 0)
    assert zeta_u[-1] == pytest.approx(0.1)
    assert np.all(np.diff(zeta_u[150:]) > 0)
    assert zeta_u[150] == pytest.approx(0.1 * (1 / 50) ** 2)
    assert np.allclose(p.damp, extra)  # assembled into the problem's damping
    with pytest.raises(Exception):
        scene_from_dict({**data, "damping": {"absorbing": {"n_units": 1}}})


def test_right_end_excitation_trims_the_left():
    sc = chain_scene(800, duration=0.01, right="driven",
                     excitation={"kind": "impact", "end": "right", "velocity_m_s": 1.0})
    p = build_problem(sc)
    reach = wave_reach(sc, p.system, p.terms, p.duration)
    assert reach.keep[0] > 0 and reach.keep[1] == 799
    t = trim_scene(sc, reach.keep)
    assert t.lattice.n_units == 800 - reach.keep[0] and t.excitation.end == "right"


def test_pilots_of_a_full_fidelity_run_measure_the_units_the_waves_reach(make_scene, lego_config) -> None:
    """--fidelity full keeps a lattice the waves never cross; its accuracy pilots run on the units
    they reach, which is the lattice --fidelity auto trims to: the same estimate to the bit, while
    the run itself keeps every unit (issue 37: pilots whose cost scales with what they measure)."""
    from flexmm.prepare import resolve

    scene = make_scene(lego_config, {"lattice.n_units": 3000, "solver.dt_s": 1e-4, "solver.duration_s": 0.05,
                                     "output.n_frames": 11})
    full, auto = resolve(scene, "full"), resolve(scene, "auto")
    assert full.problem.system.n_sites == 3000 and auto.problem.system.n_sites < 1000
    dom = full.plan.step("domain").attrs
    assert (dom["plan_pilot_first"], dom["plan_pilot_last"]) == (0, auto.problem.system.n_sites - 1)
    est_full, est_auto = (p.plan.step("accuracy").attrs for p in (full, auto))
    assert est_full["accuracy_estimate"] == est_auto["accuracy_estimate"] > 0
    assert est_full["accuracy_check"] == est_auto["accuracy_check"]


def test_a_long_uniform_lattice_takes_its_signal_speed_from_a_short_copy(make_scene, lego_config) -> None:
    """The bands of a uniform chain do not depend on its length: the planner's 256-unit copy gives
    the speed the whole lattice gives (its Hessian columns then cost a few hundred sites)."""
    from flexmm.assemble import build_system
    from flexmm.plan.domain import wave_reach
    from flexmm.plan.planner import BANDS_COPY_SITES, _bands_copy

    scene = make_scene(lego_config, {"lattice.n_units": 4 * BANDS_COPY_SITES})
    system, terms = build_system(scene)
    copy = _bands_copy(scene, system)
    assert copy is not None and copy[0].n_sites == BANDS_COPY_SITES
    whole, short = (wave_reach(scene, system, terms, 100.0, b) for b in (None, copy))
    assert short.speed_sites == pytest.approx(whole.speed_sites, rel=1e-9)
    assert short.keep == whole.keep
