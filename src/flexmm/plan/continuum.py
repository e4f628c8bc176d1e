"""Continuum predictions reported next to a discrete run, and the ``continuum`` fidelity.

Where a pulse spans many units (FWHM ≥ ``MIN_SITES``) the long-wave theory of ``flexmm.theory``
predicts its speed and profile:

- rotating-squares chain (and a sheet run as its planar chain): the exact vector soliton
  (PHYSICS.md §1.3) — speed c(A) from the exact speed law, profile from the first integral;
  the amplitude A is given by a ``soliton`` excitation, else it must be measured;
- chain of masses with a linear bond and a cubic bistable on-site term, damped: the steady
  transition front u = (L/2)(1 − tanh((x − x0 − vt)/w)) (PHYSICS.md §2), fully determined.

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

    return ContinuumPrediction("vector soliton (PHYSICS.md §1.3, exact speed law)", "theta",
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
        gamma = 2.0 * vis.damping_ratio * system.meta.get("omega_ref", 1.0)
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

    pred = ContinuumPrediction("steady transition front (PHYSICS.md §2, phase-plane shooting)", "u",
                               fr.v * a / ts, (fr.behind - fr.ahead) * a, "m", fr.width_10_90 * a,
                               lat.spacing_m, True, sample)
    pred.notes.append("width is the 10-90 % distance; the front starts at the excited end at t = 0 "
                      "(its formation delay is not modelled)")
    return pred


PILOT_CHUNKS = 400  # state checks per duration in the formation pilot
PLATEAU_SITES = 40  # passed sites whose peak θ must agree for the pulse to count as formed
PLATEAU_SPREAD = 0.02


def _plateau(peaks: np.ndarray) -> float | None:
    """Median of the last PLATEAU_SITES peaks if they agree within PLATEAU_SPREAD, else None."""
    if peaks.size < PLATEAU_SITES + 5:
        return None
    tail = peaks[-PLATEAU_SITES:]
    med = float(np.median(tail))
    half = PLATEAU_SITES // 2
    drift = abs(np.median(tail[half:]) - np.median(tail[:half]))
    return med if drift <= PLATEAU_SPREAD * abs(med) else None


def formation_pilot(scene, log=None):
    """Discrete run until the θ pulse has formed; (prediction at its amplitude, pilot record).

    Advances the scene in short chunks keeping each site's largest |θ| so far. The pulse is the
    largest |θ| feature; sites it has passed (behind its current peak) carry its peak amplitude.
    Once the last ``PLATEAU_SITES`` passed sites agree (median of their halves within
    ``PLATEAU_SPREAD``), the amplitude is their median and the continuum soliton of that
    amplitude, placed at the pulse's current position, replaces the rest of the run.
    """
    import time

    from flexmm.assemble import build_problem
    from flexmm.integrators import INTEGRATORS
    from flexmm.integrators.common import apply_prescribed

    problem = build_problem(scene)
    s, spec = problem.system, INTEGRATORS[scene.solver.integrator]
    n, k = s.n_sites, s.field_index("theta") * s.n_sites
    q, v = s.q0.copy(), s.v0.copy()
    from flexmm.plan.accuracy import new_acc

    f, acc = np.zeros_like(q), new_acc(spec, q.size)
    terms = problem.terms_tuple()
    apply_prescribed(q, v, 0.0, *terms[4:])
    spec.init(s.force, s.args, q, v, 0.0, f, terms)
    spec.advance(s.force, s.args, q.copy(), v.copy(), f.copy(), s.inv_mass, problem.damp, terms, 0.0,
                 problem.dt, 0, acc.copy())  # compile before timing
    steps = max(1, int(problem.duration / problem.dt / PILOT_CHUNKS))
    h = problem.dt
    hi, lo = q[k : k + n].copy(), q[k : k + n].copy()
    exc = scene.excitation
    direction = -1 if getattr(exc, "end", "left") == "right" else 1
    t, n_steps, amp, t0 = 0.0, 0, None, time.perf_counter()
    while t < 0.5 * problem.duration:
        t = spec.advance(s.force, s.args, q, v, f, s.inv_mass, problem.damp, terms, t, h, steps, acc)
        n_steps += steps
        th = q[k : k + n]
        np.maximum(hi, th, out=hi)
        np.minimum(lo, th, out=lo)
        pos = int(np.argmax(np.abs(th)))
        top = np.abs(hi if th[pos] > 0 else lo)  # peaks of the current pulse's polarity
        passed = top[: max(pos - 3, 0)] if direction == 1 else top[min(pos + 4, n) :][::-1]
        weak = np.flatnonzero(passed < 0.6 * abs(th[pos]))
        amp = _plateau(passed[weak[-1] + 1 :] if weak.size else passed)
        if amp is not None:
            break
    wall = time.perf_counter() - t0
    if amp is None:
        raise NoContinuum(f"no θ pulse formed within half the duration ({t * s.scales.time_s:.3g} s)")
    amp *= float(np.sign(th[pos]))
    ts = s.scales.time_s
    pred = rotating_soliton(scene.lattice, amp)
    centre = pos - direction * pred.speed_m_s * t * ts / pred.spacing_m
    pred = rotating_soliton(scene.lattice, amp, centre, direction)
    pred.notes.append(f"amplitude {amp:.4g} rad from a formation pilot of {t * ts:.3g} s "
                      f"({n_steps} steps, {wall:.3g} s)")
    return pred, {"n_steps": n_steps, "wall_s": wall, "duration_s": t * ts}


PREDICTORS: dict[str, Callable] = {
    "rotating_squares_chain": _rotating,
    "mass_chain": _mass_front,
}


def predict(scene) -> ContinuumPrediction:
    """The continuum prediction of a scene, or NoContinuum with the reason."""
    fn = PREDICTORS.get(scene.lattice.kind)
    if fn is None:
        raise NoContinuum(f"{scene.lattice.kind}: no continuum theory registered")
    return fn(scene)


def predict_from_measurement(scene, amplitude: float) -> ContinuumPrediction:
    """Continuum wave at a measured amplitude (for pulses whose amplitude the run decides)."""
    if scene.lattice.kind == "rotating_squares_chain":
        return rotating_soliton(scene.lattice, amplitude)
    return predict(scene)


def run_continuum(scene, pred: ContinuumPrediction, run_dir, *, extra_attrs: dict | None = None,
                  log: Callable[[str], None] | None = None):
    """Write ``run_dir/dataset.nc`` sampling the continuum wave at the output frames (no discrete run).

    Same layout as a discrete run (time, site, rest positions, the predicted fields), energies
    omitted; returns a controller ``RunResult`` with zero steps.
    """
    import time
    from pathlib import Path

    from flexmm.controller import RunResult
    from flexmm.io.dataset import DatasetWriter
    from flexmm.io.provenance import provenance_attrs
    from flexmm.models import MODELS

    t0 = time.perf_counter()
    pilot = None
    if pred is None:
        pred, pilot = formation_pilot(scene, log)
    setup = time.perf_counter() - t0 - (pilot["wall_s"] if pilot else 0.0)
    system = MODELS[scene.lattice.kind].build(scene.lattice)
    out = scene.output
    duration = scene.solver.duration_s
    every = out.every_s or duration / (out.n_frames - 1)
    times = np.append(np.arange(0.0, duration - 1e-9 * every, every), duration)
    sites = np.arange(0, system.n_sites, out.site_stride)
    x = np.asarray(system.site_coords["x"], float)[sites]
    probe = pred.sample(x, 0.0)
    units = {f.name: f for f in system.fields}
    site_vars = {}
    for name in probe:
        base = name[:-4] if name.endswith("_dot") else name
        if out.fields is not None and base not in out.fields or (name.endswith("_dot") and not out.velocities):
            continue
        kind = units[base].kind
        unit = {"length": "m", "angle": "rad"}[kind] + ("/s" if name.endswith("_dot") else "")
        site_vars[name] = (unit, ("rate of " if name.endswith("_dot") else "") + units[base].long_name
                           + " (continuum prediction)")
    coords = {k: (np.asarray(v)[sites], "m", f"rest {k} position") for k, v in system.site_coords.items()
              if k in ("x", "y")}
    writer = DatasetWriter(Path(run_dir) / "dataset.nc", sites.size, site_vars, {}, coords)
    for t in times:
        vals = pred.sample(x, float(t))
        writer.append(float(t), {k: vals[k] for k in site_vars}, {})
    wall = time.perf_counter() - t0 - setup  # pilot solve + sampling; build and compile apart
    lines = [f"continuum: {pred.summary()}", *[f"continuum: {n}" for n in pred.notes],
             f"continuum: {times.size} frames sampled in {wall:.3f} s"
             + (f" (including the pilot's solve, {pilot['wall_s']:.3g} s)" if pilot else ", no discrete run")]
    for line in lines:
        if log:
            log(line)
    attrs = {**provenance_attrs(scene), "title": scene.name, "description": scene.description,
             "model": system.model, "integrator": "none (continuum)", "status": "finished",
             "status_reason": "", "wall_time_s": wall, "compile_time_s": 0.0, "n_steps": 0,
             "spacing_m": system.spacing_m, "log": "\n".join(lines), **(extra_attrs or {})}
    path = writer.close(attrs)
    n_steps = pilot["n_steps"] if pilot else 0
    return RunResult("finished", "", path, n_steps, times.size, duration, 0.0, 0.0, setup, wall, lines,
                     n_units=system.n_sites)


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
