"""Periodic chains (rings): ``left: periodic, right: periodic`` on mass_chain and
rotating_squares_chain. A travelling linear Bloch wave u = A cos(qn − ωt), q = 2πm/N, set up
through ``initial.fields``, comes round the ring at the frequency of the lattice's dispersion
relation (closed form: docs/physics.md §1.4 for the squares, ω² = (4/m)(k₁ sin²(q/2) + k₂ sin² q)
for the masses), and the run conserves energy."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import LEGO_CHAIN

from flexmm.api import run_scene
from flexmm.config import ConfigError, scene_from_dict
from flexmm.theory import rotating as rt

N, MODE = 32, 3
Q = 2 * math.pi * MODE / N
A = 1e-6


def _run(tmp_path, lattice: dict, fields: list[dict], duration_s: float):
    sc = scene_from_dict({"name": "ring", "lattice": lattice, "initial": {"fields": fields},
                          "solver": {"duration_s": duration_s, "accuracy": 1e-8},
                          "output": {"n_frames": 11}})
    res = run_scene(sc, run_dir=tmp_path / "ring", fidelity="auto", in_memory=True)
    assert res.status == "finished", res.reason
    ds = res.dataset
    tot = np.asarray(ds["total_energy"].values)
    assert np.max(np.abs(tot - tot[0])) <= 1e-9 * tot[0]  # energy conserved on the ring
    assert ds.sizes["site"] == N  # the whole ring ran (nothing trimmed)
    return ds


def _wave(field: str, amplitude: float, omega: float, shape: str = "cos", rate_shape: str = "sin") -> dict:
    """``amplitude`` shape(qn − ωt) at t = 0 (value and rate)."""
    sign = 1.0 if shape == "cos" else -1.0  # d/dt cos(qn − ωt) = ω sin(qn − ωt), d/dt sin = −ω cos
    return {"field": field, "value": f"{amplitude} * {shape}({Q} * n)",
            "rate": f"{sign * amplitude * omega} * {rate_shape}({Q} * n)"}


def test_mass_ring_wave_follows_the_dispersion_relation(tmp_path):
    m, k1, k2, a = 0.01, 1e4, 2e3, 0.01
    lat = {"kind": "mass_chain", "n_units": N, "spacing_m": a, "mass_kg": m, "left": "periodic",
           "right": "periodic", "bond": {"law": "linear", "k_n_per_m": k1},
           "bond2": {"law": "linear", "k_n_per_m": k2}}
    w = math.sqrt(4 / m * (k1 * math.sin(Q / 2) ** 2 + k2 * math.sin(Q) ** 2))
    T = 2 * (2 * math.pi / w)
    ds = _run(tmp_path, lat, [_wave("u", A * a, w)], T)
    u = np.asarray(ds["u"].values)
    t = np.asarray(ds["time"].values)
    n = np.arange(N)
    exact = A * a * np.cos(Q * n[None, :] - w * t[:, None])
    assert np.max(np.abs(u - exact)) < 1e-5 * A * a


@pytest.mark.parametrize("branch", [0, 1])
def test_rotating_squares_ring_wave_follows_the_bloch_bands(tmp_path, branch):
    """θ = A cos(qn − Ωt), u = −c A sin(qn − Ωt) with c = s0 sin q / (4 sin²(q/2) − Ω²): the
    eigenvector of K(q) of docs/physics.md §1.4 on either branch (θ0 = 0.2: u and θ coupled)."""
    lat = {**LEGO_CHAIN, "n_units": N, "theta0_rad": 0.2, "left": "periodic", "right": "periodic"}
    p = rt.RotatingChainND.from_si(lat["a_m"], lat["theta0_rad"], lat["k_long_n_per_m"], lat["k_shear_n_per_m"],
                                   lat["k_rot_n_m_per_rad"], lat["mass_kg"], lat["inertia_kg_m2"], 1, 0)
    t0 = math.sqrt(lat["mass_kg"] / lat["k_long_n_per_m"])
    om = float(rt.dispersion_chain(p, np.array([Q]))[branch][0])
    w = om / t0
    c = p.s0 * math.sin(Q) / (4 * math.sin(Q / 2) ** 2 - om**2)
    T = 2 * (2 * math.pi / w)
    ds = _run(tmp_path, lat, [_wave("theta", A, w), _wave("u", -c * A * lat["a_m"], w, "sin", "cos")], T)
    t = np.asarray(ds["time"].values)[:, None]
    n = np.arange(N)[None, :]
    assert np.max(np.abs(ds["theta"].values - A * np.cos(Q * n - w * t))) < 1e-4 * A
    assert np.max(np.abs(ds["u"].values / lat["a_m"] + c * A * np.sin(Q * n - w * t))) < 1e-4 * A


@pytest.mark.parametrize("lattice,why", [
    ({**LEGO_CHAIN, "n_units": 31, "left": "periodic", "right": "periodic"}, "even n_units"),
    ({**LEGO_CHAIN, "n_units": 32, "left": "periodic", "right": "free"}, "both be periodic or neither"),
    ({"kind": "mass_chain", "n_units": 2, "spacing_m": 0.01, "mass_kg": 0.01, "left": "periodic",
      "right": "periodic", "bond": {"law": "linear", "k_n_per_m": 1.0}}, "n_units ≥ 3"),
])
def test_ring_mistakes(lattice, why):
    with pytest.raises(ConfigError, match=why):
        scene_from_dict({"name": "r", "lattice": lattice, "solver": {"duration_s": 1.0}})
