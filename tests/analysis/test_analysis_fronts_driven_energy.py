"""Transition fronts, driven response and energy budget on synthetic data with known answers."""

from __future__ import annotations

import math

import numpy as np
import pytest
import xarray as xr

from flexmm.analysis import FrontNotFound, energy_budget, field_view, measure_driven, measure_fronts
from flexmm.analysis.measure.driven import drive_frequency, lockin, pass_bands
from synthetic import driven_dataset, front_dataset, pulse_dataset


def test_front_speed_width_and_switched_sites():
    ds = front_dataset(speed_m_s=1.0, width_m=3.0, noise=0.002)
    fronts = measure_fronts(field_view(ds, "u"))
    assert len(fronts) == 1
    f = fronts[0]
    assert f.direction == 1 and not f.arrested
    assert f.speed_m_s == pytest.approx(1.0, rel=2e-3)
    # tanh profile: 10-90 % width = w ln 9 (the 1-site sampling costs ~1.5 %)
    assert f.width_10_90_m == pytest.approx(3.0 * math.log(9.0), rel=0.03)
    assert f.jump == pytest.approx(1.0, rel=0.01)
    assert f.n_switched > 130  # the front enters at x = −10 and stops at 140 m


def test_front_arrest_distance():
    ds = front_dataset(speed_m_s=1.0, width_m=3.0, arrest_m=120.0)
    f = measure_fronts(field_view(ds, "u"))[0]
    assert f.arrested
    assert f.stop_m == pytest.approx(120.0, abs=1.0)
    assert f.speed_m_s == pytest.approx(1.0, rel=5e-3)


def test_two_way_fronts_from_a_trigger():
    x = np.arange(200.0)
    t = np.linspace(0, 60, 241)
    left, right = 100 - 1.5 * t, 100 + 1.5 * t
    u = 0.5 * (np.tanh((x[None] - left[:, None]) / 2) - np.tanh((x[None] - right[:, None]) / 2))
    u = u - u[0]
    ds = xr.Dataset({"u": (("time", "site"), u, {"units": "m"})},
                    coords={"time": t, "x": ("site", x)}, attrs={"spacing_m": 1.0})
    fronts = measure_fronts(field_view(ds, "u"))
    assert sorted(f.direction for f in fronts) == [-1, 1]
    for f in fronts:
        assert f.speed_m_s == pytest.approx(1.5, rel=5e-3)


@pytest.mark.parametrize("width", [2.0, 6.0])
def test_a_front_present_at_the_start_is_one_front(width):
    """A launched kink: the front is already there at t = 0, its own sites part-way between the wells.
    Measured from where they started, those sites make a second edge that walks back to the kink's
    start (a spurious front); measured between their wells, the kink is the only front."""
    x = np.arange(200.0)
    t = np.linspace(0, 60, 241)
    centre = 40 + 1.5 * t
    u = 0.5 * (1 - np.tanh((x[None] - centre[:, None]) / width))
    ds = xr.Dataset({"u": (("time", "site"), u, {"units": "m"})},
                    coords={"time": t, "x": ("site", x)}, attrs={"spacing_m": 1.0})
    (f,) = measure_fronts(field_view(ds, "u"))
    assert f.direction == 1 and f.speed_m_s == pytest.approx(1.5, rel=5e-3)
    assert f.start_m == pytest.approx(40.0, abs=3.0)  # where a 3-site run has switched


def test_no_front():
    with pytest.raises(FrontNotFound):
        measure_fronts(field_view(pulse_dataset([], field="u", units="m"), "u"))


def test_driven_lockin_transmission_harmonics_and_decay():
    ds = driven_dataset(frequency_hz=1.0, decay_per_site=0.02, harmonic=0.1)
    import yaml

    f, end = drive_frequency(yaml.safe_load(ds.attrs["config"]))
    assert (f, end) == (1.0, "left")
    d = measure_driven(field_view(ds, "u"), f, end=end)
    assert d.amplitude_drive == pytest.approx(1.0, rel=1e-9)
    assert d.transmission == pytest.approx(math.exp(-0.02 * 59), rel=1e-9)
    assert d.decay_per_site == pytest.approx(0.02, rel=1e-9)
    assert d.scalars()["harmonic_2_ratio"] == pytest.approx(0.1, rel=1e-9)
    assert d.scalars()["harmonic_3_ratio"] < 1e-9
    assert d.dominant_far_hz == pytest.approx(1.0, rel=0.01)
    # the frequency is found from the drive end when not given
    assert measure_driven(field_view(ds, "u")).frequency_hz == pytest.approx(1.0, rel=0.01)


def test_lockin_is_exact_on_whole_periods_with_uneven_sampling():
    t = np.sort(np.random.default_rng(0).uniform(0, 5, 4000))
    t[0], t[-1] = 0.0, 5.0
    assert lockin(0.3 + 2.0 * np.sin(2 * np.pi * 2.0 * t + 0.4), t, 2.0) == pytest.approx(2.0, rel=1e-4)


def test_pass_bands():
    f = [100, 200, 300, 400, 500, 600]
    tr = [0.9, 1.0, 0.5, 1e-3, 1e-4, 0.8]
    assert pass_bands(f, tr, 0.1) == [(100, 300), (600, 600)]


def test_energy_budget_balance_and_inferred_work():
    t = np.linspace(0, 1, 11)
    kin = 1.0 + 0.5 * t
    ds = xr.Dataset({"kinetic_energy": ("time", kin), "potential_energy": ("time", 0.2 * np.ones(11)),
                     "applied_work": ("time", 0.7 * t), "dissipated_energy": ("time", 0.2 * t)},
                    coords={"time": t})
    e = energy_budget(ds)
    assert e.work_recorded and e.max_relative_balance_error < 1e-12 and e.work_j == pytest.approx(0.7)
    ds["applied_work"] = ds["applied_work"] * 0
    ds.attrs["config"] = "excitation: {kind: shaker, end: left, frequency_hz: 100, amplitude_m: 1.0e-5}\n"
    e = energy_budget(ds)
    assert not e.work_recorded and e.work_j == pytest.approx(0.7) and math.isnan(e.max_relative_balance_error)
