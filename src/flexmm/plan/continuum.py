"""Continuum predictions reported next to a discrete run, and the ``continuum`` fidelity.

Where a pulse spans many units (FWHM ≥ ``MIN_SITES``) the long-wave theory of ``flexmm.theory``
predicts its speed and profile:

- rotating-squares chain (and a sheet run as its planar chain): the exact vector soliton
  (docs/physics.md §1.3) — speed c(A) from the exact speed law, profile from the first integral;
  the amplitude A is given by a ``soliton`` excitation, else it must be measured;
- chain of masses with a linear bond and a cubic bistable on-site term, damped: the steady
  transition front u = (L/2)(1 − tanh((x − x0 − vt)/w)) (docs/physics.md §2), fully determined.

A prediction is *complete* when the scene fixes every parameter of the travelling wave (then
``--fidelity continuum`` replaces the discrete run by sampling the profile); otherwise the
amplitude comes from the discrete run and the prediction is reported after it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

MIN_SITES = 5.0


class NoContinuum(Exception):
    """The scene has no continuum prediction (the message says why)."""


class NeedsAmplitude(NoContinuum):
    """The theory holds but the pulse amplitude is decided by the run (e.g. an impact)."""


@dataclass
class ContinuumPrediction:
    """A travelling wave of the long-wave theory, in SI units.

    ``sample(x_m (n,), t_s) -> {field: (n,) values}`` evaluates the wave (coordinates and rates)
    on rest positions at time t.
    """

    theory: str
    field: str
    speed_m_s: float
    amplitude: float
    amplitude_units: str
    fwhm_m: float
    spacing_m: float
    complete: bool
    sample: Callable[[np.ndarray, float], dict] | None = None
    notes: list[str] = field(default_factory=list)

    @property
    def width_sites(self) -> float:
        return self.fwhm_m / self.spacing_m

    @property
    def spans_many_units(self) -> bool:
        return self.width_sites >= MIN_SITES

    def summary(self) -> str:
        return (f"{self.theory}: speed {self.speed_m_s:.5g} m/s, {self.field} amplitude "
                f"{self.amplitude:.4g} {self.amplitude_units}, width {self.fwhm_m * 1e3:.4g} mm "
                f"({self.width_sites:.1f} sites)")

    def attrs(self, prefix: str = "continuum_") -> dict:
        return {prefix + "theory": self.theory, prefix + "field": self.field,
                prefix + "speed_m_s": self.speed_m_s, prefix + "amplitude": self.amplitude,
                prefix + "fwhm_m": self.fwhm_m, prefix + "complete": int(self.complete)}


# ---------------------------------------------------------------- rotating squares
def _rotating_params(lat):
    from flexmm.models.rotating_chain import nondimensional
    from flexmm.theory.rotating import RotatingChainND

    if getattr(lat, "variation", None):
        raise NoContinuum("parameters vary along the chain")
    if getattr(lat, "predeform", None) is not None:  # theory.prestressed needs the relaxed state
        raise NoContinuum("predeformed: the soliton rides on the relaxed, loaded state")
    nd = nondimensional(lat)
    p = RotatingChainND(lat.theta0_rad, nd["Ks"], nd["Ktheta"], nd["alpha2"], lat.n_lateral,
                        int(lat.lateral_stretch))
    return p, lat.a_m, math.sqrt(lat.mass_kg / lat.k_long_n_per_m)


def _fwhm(p, A: float) -> float:
    """FWHM of |θ| of the exact soliton of amplitude A, in X = x/a units."""
    from flexmm.theory.rotating import exact_soliton, soliton_speed, soliton_width

    W = soliton_width(p, float(soliton_speed(p, A)))
    z = np.linspace(0.0, 12 * W, 4001)
    th = np.abs(exact_soliton(p, A, z)[0])
    return 2.0 * float(np.interp(0.5 * abs(A), th[::-1], z[::-1]))


def _profile_table(p, A: float, half_span: float, step: float = 0.02):
    """θ, θ', U', U of the exact soliton on ζ ∈ [−half_span, half_span] (X units), U(+∞) = 0."""
    from scipy.integrate import cumulative_trapezoid

    from flexmm.theory.rotating import exact_soliton

    z = np.arange(-half_span, half_span + step, step)
    th, up = exact_soliton(p, A, z)
    U = cumulative_trapezoid(up[::-1], z[::-1], initial=0.0)[::-1]  # ∫_∞^ζ U′
    return z, th, np.gradient(th, z), up, U


def rotating_soliton(lat, amplitude_rad: float, center_site: float = 0.0, direction: int = 1,
                     complete: bool = False, span_sites: float | None = None) -> ContinuumPrediction:
    """Exact continuum vector soliton of amplitude A on a rotating-squares chain config.

    ``sample`` evaluates θ = Θ(ξ), u = direction·a·Ucal(ξ) and their rates θ_t = −c Θ'(ξ)/t0,
    u_t = −c·direction·a·Ucal'(ξ)/t0 with ξ = direction (X − X_c) − c T (theory.soliton_initial_state).
    """
    from flexmm.theory.rotating import soliton_exists, soliton_speed

    p, a, ts = _rotating_params(lat)
    if not soliton_exists(p, amplitude_rad):
        raise NoContinuum(f"no continuum soliton of amplitude {amplitude_rad:.4g} rad for these parameters")
    c = float(soliton_speed(p, amplitude_rad))
    h = a * p.eta
    span = (span_sites or getattr(lat, "n_units", 1000)) * p.eta * 2 + 10
    z, th, dth, up, U = _profile_table(p, amplitude_rad, span)

    def sample(x_m: np.ndarray, t_s: float) -> dict:
        X = np.asarray(x_m, float) / a
        xi = direction * (X - center_site * p.eta) - c * t_s / ts
        f = {k: np.interp(xi, z, v) for k, v in (("th", th), ("dth", dth), ("up", up), ("U", U))}
        f["U"] = np.where(xi < z[0], U[0], f["U"])
        return {"u": direction * f["U"] * a, "theta": f["th"], "u_dot": -c * direction * f["up"] * a / ts,
                "theta_dot": -c * f["dth"] / ts}

    return ContinuumPrediction("vector soliton (docs/physics.md §1.3, exact speed law)", "theta",
                               c * a / ts, amplitude_rad, "rad", _fwhm(p, amplitude_rad) * a, h,
                               complete, sample)


def _rotating(scene) -> ContinuumPrediction:
    exc = scene.excitation
    if exc.kind != "soliton":
        raise NeedsAmplitude(f"the amplitude of the pulse an {exc.kind!r} excitation makes is not "
                          "known before the run; the prediction is made from the measured amplitude")
    pred = rotating_soliton(scene.lattice, exc.amplitude_rad, exc.center_site, exc.direction, complete=True)
    if scene.damping.viscous is not None or scene.damping.dashpot_n_s_per_m > 0:
        pred.complete = False
        pred.notes.append("damped: the soliton slows and decays; the continuum gives its initial state only")
    return pred


# ---------------------------------------------------------------- chains of masses
def _mass_front(scene) -> ContinuumPrediction:
    """Steady transition front of a damped mass chain with a linear bond (plan.fronts)."""
    from flexmm.plan.fronts import NoFront, onsite_force, solve_front

    lat, exc = scene.lattice, scene.excitation
    if lat.bond.law != "linear" or lat.bond2 is not None or not lat.onsite:
        raise NoContinuum("the front theory needs a linear bond, no second neighbours, an on-site law")
    if lat.variation or lat.friction is not None or lat.bond.offset_m:
        raise NoContinuum("variation, friction or bond offsets are not in the front theory")
    if scene.damping.dashpot_n_s_per_m > 0 or scene.damping.absorbing is not None:
        raise NoContinuum("dashpots between units or an absorbing layer are not in the front theory")
    push = {"impact": "velocity_m_s", "boundary_displacement": "amplitude_m"}.get(exc.kind)
    if push is None:
        raise NoContinuum(f"a front is launched by an impact or a boundary displacement, not {exc.kind!r}")
    from flexmm.models import MODELS

    # uniform states: a short copy does (its middle must be clear of the ends' relaxed boundary layer)
    system = MODELS[lat.kind].build(lat.model_copy(update={"n_units": min(lat.n_units, 64)}))
    sc = system.scales
    vis = scene.damping.viscous
    if vis is None:
        gamma = 0.0
    elif vis.damping_ratio is not None:
        gamma = 2.0 * vis.damping_ratio * system.omega_ref
    else:
        gamma = vis.coefficient_n_s_per_m * sc.time_s / sc.mass_kg
    K = lat.bond.k_n_per_m * sc.time_s**2 / sc.mass_kg
    Vp = onsite_force(system)
    if abs(float(Vp(0.0))) > 1e-4 * max(abs(float(Vp(0.01))), 1e-300):
        raise NoContinuum("the chain does not start in a well (V'(0) != 0)")
    travel = 1 if exc.end == "left" else -1
    try:
        fr = solve_front(Vp, K, gamma, 0.0, math.copysign(1.0, getattr(exc, push)) * travel)
    except NoFront as why:
        raise NoContinuum(str(why)) from None
    a, ts = sc.length_m, sc.time_s
    x_start = 0.0 if travel == 1 else (lat.n_units - 1) * lat.spacing_m

    def sample(x_m: np.ndarray, t_s: float) -> dict:
        xi = travel * (np.asarray(x_m, float) - x_start) / a - fr.v * t_s / ts
        return {"u": fr.profile(xi) * a, "u_dot": -fr.v * fr.slope(xi) * a / ts}

    pred = ContinuumPrediction("steady transition front (docs/physics.md §2, phase-plane shooting)", "u",
                               fr.v * a / ts, (fr.behind - fr.ahead) * a, "m", fr.width_10_90 * a,
                               lat.spacing_m, True, sample)
    pred.notes.append("width is the 10-90 % distance; the front starts at the excited end at t = 0 "
                      "(its formation delay is not modelled)")
    return pred


PILOT_CHUNKS = 400  # state checks per duration in the formation pilot
PLATEAU_SITES = 40  # passed sites whose peak θ must agree for the pulse to count as formed
PLATEAU_SPREAD = 0.02


def plateau(peaks: np.ndarray) -> float | None:
    """Median of the last PLATEAU_SITES peaks if they agree within PLATEAU_SPREAD, else None."""
    if peaks.size < PLATEAU_SITES + 5:
        return None
    tail = peaks[-PLATEAU_SITES:]
    med = float(np.median(tail))
    half = PLATEAU_SITES // 2
    drift = abs(np.median(tail[half:]) - np.median(tail[:half]))
    return med if drift <= PLATEAU_SPREAD * abs(med) else None


@dataclass(frozen=True)
class ContinuumTheory:
    """A model kind's continuum wave (the ``continuum`` hook of its ``ModelSpec``).

    ``predict(scene)`` -> ContinuumPrediction (or NoContinuum/NeedsAmplitude with the reason);
    ``at_amplitude(scene, amplitude)``, if given, the wave at a measured amplitude.
    """

    predict: Callable
    at_amplitude: Callable | None = None


ROTATING_CHAIN = ContinuumTheory(_rotating, lambda scene, amplitude: rotating_soliton(scene.lattice, amplitude))
MASS_FRONT = ContinuumTheory(_mass_front)


def _theory(scene) -> ContinuumTheory | None:
    from flexmm.config.lattice import MODELS

    return MODELS[scene.lattice.kind].hook("continuum")


def predict(scene) -> ContinuumPrediction:
    """The continuum prediction of a scene, or NoContinuum with the reason."""
    theory = _theory(scene)
    if theory is None:
        raise NoContinuum(f"{scene.lattice.kind}: no continuum theory registered")
    return theory.predict(scene)


def predict_from_measurement(scene, amplitude: float) -> ContinuumPrediction:
    """Continuum wave at a measured amplitude (for pulses whose amplitude the run decides)."""
    theory = _theory(scene)
    if theory is not None and theory.at_amplitude is not None:
        return theory.at_amplitude(scene, amplitude)
    return predict(scene)


def alongside(ds, field: str, amplitude: float, fwhm_sites: float, speed_m_s: float) -> str | None:
    """One line comparing a measured pulse with the continuum at its amplitude, if it spans many units."""
    import yaml

    from flexmm.config import scene_from_dict

    if fwhm_sites < MIN_SITES or "config" not in ds.attrs:
        return None
    try:
        scene = scene_from_dict(yaml.safe_load(ds.attrs["config"]))
        pred = predict_from_measurement(scene, amplitude)
    except Exception:  # noqa: BLE001 - no theory for this scene or amplitude: nothing to report
        return None
    if pred.field != field:
        return None
    d = 100 * (pred.speed_m_s - speed_m_s) / speed_m_s
    return (f"continuum ({pred.theory}) at this amplitude: speed {pred.speed_m_s:.4g} m/s ({d:+.1f} %), "
            f"FWHM {pred.fwhm_m * 1e3:.4g} mm ({pred.width_sites:.1f} sites)")
