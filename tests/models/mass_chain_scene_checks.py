"""Measurements on the shipped mass-chain scenes (used by the slow tests and the scenes note).

Every function runs one scene through the public API (``run_scene``, full fidelity), reads the
dataset and returns plain numbers; the tests assert on them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import xarray as xr
from mass_chain_helpers import crossing_times, peak_times

from flexmm.api import run_scene
from flexmm.config import load_scene

REPO = Path(__file__).resolve().parents[2]
CONFIGS = REPO / "configs"


def run(name: str, tmp: Path, overrides: list[str] | None = None, tag: str = ""):
    """Run configs/<name>.yaml; return (scene, dataset)."""
    scene = load_scene(CONFIGS / f"{name}.yaml", overrides or [])
    result = run_scene(scene, run_dir=tmp / f"{name}{tag}")
    assert result.status == "finished", result.reason
    return scene, xr.load_dataset(result.path)


def _speed(x: np.ndarray, times: np.ndarray) -> float:
    ok = np.isfinite(times)
    return 1.0 / np.polyfit(x[ok], times[ok], 1)[0]


def softening_pulse(name: str, tmp: Path, bonds=slice(40, 160), tension=None) -> dict:
    """Peak bond strain, its polarity and speed (m/s) and c0 for a softening-chain scene.

    ``tension(D)`` is the bond law (SI) used for the rest stiffness if not linear-polynomial.
    """
    scene, ds = run(name, tmp)
    lat = scene.lattice
    a, m = lat.spacing_m, lat.mass_kg
    u = ds.u.values
    t = ds.time.values
    strain = np.diff(u, axis=1) / a
    idx = np.arange(strain.shape[1])[bonds]
    k1 = lat.bond.k1_n_per_m if lat.bond.law == "polynomial" else tension
    c0 = a * np.sqrt(k1 / m)
    peaks = strain[:, idx].max(axis=0)
    v = _speed(idx * a, peak_times(t, strain[:, idx]))
    return {"c0": c0, "speed": v, "amp": float(np.median(peaks)), "min_strain": float(strain[:, idx].min()),
            "amp_first": float(peaks[:10].mean()), "amp_last": float(peaks[-10:].mean()), "scene": scene}


def origami_overtaking(tmp: Path) -> dict:
    """Wall force history and the speeds of the compressive and tensile peaks (d)."""
    scene, ds = run("d_origami_rarefaction_overtakes", tmp)
    lat = scene.lattice
    a, m, b = lat.spacing_m, lat.mass_kg, lat.bond
    t, u = ds.time.values, ds.u.values
    strain = np.diff(u, axis=1)  # elongation (m)
    force = b.k1_n_per_m * strain + b.k2_n_per_m2 * strain**2 + b.k3_n_per_m3 * strain**3
    wall = force[:, -1]
    big = np.flatnonzero(np.abs(wall) > 0.3 * np.abs(wall).max())[0]
    # bonds 15-50 before the tension reflected (doubled) at the wall comes back (t < 1.5 s)
    idx = np.arange(15, 50)
    early = t < 1.5
    t, force = t[early], force[early]
    c0 = a * np.sqrt(b.k1_n_per_m / m)
    return {
        "c0": c0,
        "first_big_wall_force_n": float(wall[big]),
        "t_first_tension_s": float(ds.time.values[np.argmax(wall > 0.3 * wall.max())]),
        "t_first_compression_s": float(ds.time.values[np.argmax(wall < 0.3 * wall.min())]),
        "max_tension_n": float(wall.max()), "max_compression_n": float(-wall.min()),
        "tension_speed": _speed(idx * a, peak_times(t, force[:, idx])),
        "compression_speed": _speed(idx * a, peak_times(t, -force[:, idx])),
    }


def slinky_steps(tmp: Path) -> dict:
    """Displacement of every coil after one actuator pulse, and the pulse speed (f)."""
    scene, ds = run("f_slinky_friction_locomotion", tmp)
    lat = scene.lattice
    a, m = lat.spacing_m, lat.mass_kg
    u, v, t = ds.u.values, ds.u_dot.values, ds.time.values
    strain = np.diff(u, axis=1) / a
    idx = np.arange(5, 40)
    return {
        "final_u_m": u[-1], "final_speed_max": float(np.abs(v[-1]).max()),
        "peak_strain_first": float(strain[:, 5].max()), "min_strain": float(strain.min()),
        "speed": _speed(idx * a, peak_times(t, strain[:, idx])),
        "c0": a * np.sqrt(lat.bond.k1_n_per_m / m),
        "kick_speed": -scene.excitation.velocity_m_s,
    }


def switched_mask(name: str, tmp: Path, overrides=None, tag: str = "", *, towards: float) -> tuple:
    """Sites whose final absolute position is closer to ``towards`` (m) than to where they started."""
    scene, ds = run(name, tmp, overrides, tag)
    from flexmm.models import MODELS

    x0 = MODELS[scene.lattice.kind].build(scene.lattice).initial_displacement_m
    x1 = ds.u.values[-1] + x0
    return np.abs(x1 - towards) < np.abs(x1 - x0), scene, ds


def raney_wave(tmp: Path) -> dict:
    """Speed over successive stretches and the kinetic-energy law for the Raney chain (h)."""
    from flexmm.models.mass_params import raney_coefficients

    scene, ds = run("h_raney_transition_wave", tmp)
    lat = scene.lattice
    a, m = lat.spacing_m, lat.mass_kg
    eta = scene.damping.viscous.coefficient_n_s_per_m
    t, u = ds.time.values, ds.u.values
    c = raney_coefficients(lat.onsite[0].d_mm)[0]
    psi = np.polynomial.Polynomial(np.concatenate([[0.0], c]))  # mJ, x in mm
    wells = sorted(r.real for r in psi.deriv().roots() if abs(r.imag) < 1e-9 and -1 < r.real < 9)
    hi, lo = wells[2], wells[0]
    jump = -(hi - lo) * 1e-3
    tc = crossing_times(t, u / jump)
    n = u.shape[1]
    x = np.arange(n) * a
    stretches = [np.arange(40, 120), np.arange(120, 200), np.arange(200, 280)]
    speeds = [_speed(x[s], tc[s]) for s in stretches]
    during = (t > tc[60]) & (t < tc[280])
    K = float(ds.kinetic_energy.values[during].mean())
    dpsi = (psi(hi) - psi(lo)) * 1e-3
    v = _speed(x[60:280], tc[60:280])
    return {"speeds": speeds, "n_switched": int(np.isfinite(tc).sum()), "n": n, "K": K,
            "K_law": m * v * dpsi / (2 * eta * a), "dpsi_j": dpsi, "speed": v,
            "width_sites": _width_10_90(u / jump, t, tc, n // 2)}


def _width_10_90(s: np.ndarray, t: np.ndarray, tc: np.ndarray, site: int) -> float:
    """Sites between the 10 % and 90 % progress levels when ``site`` crosses 50 %."""
    k = int(np.argmin(np.abs(t - tc[site])))
    prof = s[k]
    return float(np.count_nonzero((prof > 0.1) & (prof < 0.9)))


def grid_states(name: str, tmp: Path) -> dict:
    """Switched map (ny, nx) and 50 % crossing times (s) of a bistable-grid scene."""
    scene, ds = run(name, tmp)
    lat = scene.lattice
    jump = lat.onsite[0].jump_m
    t = ds.time.values
    s = ds.u.values / jump
    tc = crossing_times(t, s).reshape(lat.ny, lat.nx)
    return {"switched": (s[-1] > 0.5).reshape(lat.ny, lat.nx), "t_cross": tc}


def hertz_pulse(tmp: Path) -> dict:
    """Leading solitary wave of the granular scene: speed, peak force, FWHM (beads), tension."""
    from flexmm.theory.chains import nesterenko_speed_from_force

    scene, ds = run("hertz_granular_impact", tmp)
    lat = scene.lattice
    A, D, m = lat.bond.stiffness_n_per_m_p, lat.spacing_m, lat.mass_kg
    t, u = ds.time.values, ds.u.values
    overlap = -np.diff(u, axis=1)
    force = A * np.clip(overlap, 0.0, None) ** 1.5
    idx = np.arange(20, 90)
    v = _speed(idx * D, peak_times(t, force[:, idx]))
    f_m = float(np.median(force[:, idx].max(axis=0)))
    k = int(np.argmax(force[:, 55]))
    prof = force[k]
    fwhm = float(np.count_nonzero(prof > 0.5 * prof.max()))
    return {"speed": v, "force_peak_n": f_m, "nesterenko_speed": nesterenko_speed_from_force(A, m, D, f_m),
            "fwhm_beads": fwhm, "peak_spread": float(np.ptp(force[:, idx].max(axis=0)) / f_m),
            "max_gap_m": float(np.clip(-overlap, 0.0, None).max())}
