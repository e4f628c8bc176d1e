"""Pick the cheapest integrator and step that meet ``solver.accuracy``, and check it afterwards.

Accuracy is the relative error of the final state,

    err = max_f  max_i |q_f,i(T) − q*_f,i(T)| / max_{i,t} |q_f,i(t)|,

over the lattice fields f (u, θ, ...) that move, q* the exact solution. For a method of order
p and step h the error behaves like err ≈ C h^p g(T), g the growth of errors in time: linear for
the phase error of travelling waves, exponential where the dynamics amplify perturbations
(many interacting waves: an impact's wave field after several reflections is chaotic). A pilot
over a short time T_p runs each candidate at h₁ = ½ h_stab, h₁/2 and h₁/4; the observed order
p (≤ the method's: a kink in a drive reduces it) and Richardson give
err(h₁, t) ≈ |q_{h₁} − q_{h₁/2}| 2^p/(2^p − 1) at t = T_p/2 and T_p, whose ratio fixes the growth
(``extrapolate``), and

    h = h₁ (S · accuracy / err(h₁, T))^{1/p},   S = SAFETY,

between FLOOR × the stable step h_stab = stability_limit/ω_max and h₁ (no extrapolation to steps
larger than the pilot's: a sixth-order method's error grows faster than h^6 there). When that h is so small
that a pilot over the whole duration costs at most LONG_PILOT_SHARE of the run, the pilot is
repeated over all of T (late error growth — chaos setting in after several reflections — is
then seen, not extrapolated). If even FLOOR·h_stab is predicted to miss, the plan says the
accuracy is out of reach; if the pilot's error is O(1) (no h^p regime) it says the prediction
is uncertain. The cost of a method is its force evaluations per step × T/h; the cheapest wins.
After the run a companion run at 2h (or h/2 if 2h is not stable) gives the step-doubling
estimate err(h) ≈ |q_h − q_{2h}|/(2^p − 1) (p as observed in the pilot), recorded in the
dataset attrs (``accuracy_estimate``, ``accuracy_met``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from flexmm.integrators import INTEGRATORS
from flexmm.integrators.stepper import make_stepper
from flexmm.errors import PlanError

SAFETY = 0.3
CAP = 0.8  # largest step as a fraction of the linear stability limit
FLOOR = 1e-3  # smallest step as a fraction of it (an accuracy out of reach is reported, not chased)
GROWTH_POWER = 2.0  # pilot error growth t^β beyond this is taken as exponential (chaotic dynamics)
LONG_PILOT_SHARE = 0.1  # a pilot over the whole duration is run when it costs at most this share of the run
SATURATED = 0.1  # a pilot error this large is outside the h^p regime: the prediction is uncertain
PILOT_FRACTION = 0.1
PILOT_MIN_STEPS = 400
#: force evaluations per step for methods whose registry entry does not say
FORCE_EVALS = {"velocity_verlet": 1, "rk4": 4, "pefrl": 4, "forest_ruth": 3, "yoshida4": 3,
               "suzuki5": 5, "omelyan_pefrl": 4}


def force_evals(spec) -> float | None:
    """Force evaluations per step of an integrator (registry metadata, else the table above)."""
    val = getattr(spec, "force_evals", None)
    if isinstance(val, (int, float)) and math.isfinite(val) and val > 0:
        return float(val)
    return FORCE_EVALS.get(spec.name)


def allowed_integrators() -> tuple[str, ...] | None:
    """Integrator names the scene schema accepts (None: any registered name)."""
    from typing import get_args

    from flexmm.config.scene import Solver

    names = tuple(a for a in get_args(Solver.model_fields["integrator"].annotation) if isinstance(a, str))
    return names or None


def candidates(problem, only: str | None = None) -> list:
    """Registered explicit fixed-step methods usable for this problem (damping needs support)."""
    damped = bool(np.any(problem.damp > 0) or problem.terms.dash_c.size)
    allowed = allowed_integrators()
    out = []
    for name, spec in INTEGRATORS.items():
        if only is not None and name != only or allowed is not None and name not in allowed:
            continue
        lim = getattr(spec, "stability_limit", None)
        if lim is None or not math.isfinite(lim) or lim <= 0:
            continue  # implicit or unconditionally stable: not costed here
        if getattr(spec, "adaptive", False) or getattr(spec, "implicit", False):
            continue
        if damped and not getattr(spec, "velocity_dependent_forces", False):
            continue
        if force_evals(spec) is None:
            continue
        out.append(spec)
    return out


def integrate(problem, spec, h: float, t_end: float, n_samples: int = 32, checkpoints=()):
    """Advance the problem's initial state to ``t_end`` with steps ≈ h (no output).

    Returns (q, v, peaks, steps): final state, per-field max |q| over ``n_samples`` sample
    times (n_fields,), and the number of steps. With ``checkpoints`` (fractions of ``t_end``),
    returns (states, peaks, steps) instead: the states q at those times.
    """
    n_steps = max(1, int(math.ceil(t_end / h - 1e-9)))
    st = make_stepper(problem, spec, h=t_end / n_steps, threads=1, check_energy=False)
    marks = sorted({*np.linspace(0, n_steps, min(n_samples, n_steps) + 1).round().astype(int)[1:],
                    *(int(round(c * n_steps)) for c in checkpoints)})
    chunks = [k - j for j, k in zip([0, *marks[:-1]], marks) if k > j]
    peaks = _peaks(st.system, st.q)
    states = {}

    def sample(s) -> None:
        nonlocal peaks
        peaks = np.maximum(peaks, _peaks(s.system, s.q))
        states[int(round(s.t / s.h))] = s.q.copy()

    st.run(chunks, sample)
    if checkpoints:
        return [states[int(round(c * n_steps))] for c in checkpoints], peaks, n_steps
    return st.q, st.v, peaks, n_steps


def _peaks(system, q) -> np.ndarray:
    n = system.n_sites
    return np.array([np.max(np.abs(q[k * n : (k + 1) * n])) for k in range(len(system.fields))])


def state_error(system, q: np.ndarray, q_ref: np.ndarray, peaks: np.ndarray) -> float:
    """Relative error of a final state (module docstring); fields that never move are skipped."""
    n = system.n_sites
    top = float(np.max(peaks)) if peaks.size else 0.0
    err = 0.0
    for k in range(len(system.fields)):
        if peaks[k] <= 1e-12 * top or not np.isfinite(peaks[k]):
            continue
        d = np.max(np.abs(q[k * n : (k + 1) * n] - q_ref[k * n : (k + 1) * n]))
        err = max(err, float(d / peaks[k]))
    return err if np.all(np.isfinite(q)) else math.inf


@dataclass
class Choice:
    """The integrator and step chosen for a requested accuracy, with the pilot's evidence."""

    integrator: str
    dt: float  # nondimensional
    predicted_error: float
    cost: float  # force evaluations for the whole run
    pilot_time: float  # nondimensional duration of the pilot
    table: list[dict] = field(default_factory=list)  # one row per candidate
    reachable: bool = True  # False: even the smallest step allowed is predicted to miss
    order: float = 2.0  # order observed in the pilot (≤ the method's; used by the check)


def _drive_end(problem) -> float:
    """Time after which prescribed/applied drives are smooth (end of pulses, ramps)."""
    prm, shape = problem.terms.drv_prm, problem.terms.drv_shape
    end = 0.0
    for row, sh in zip(prm, shape):
        if sh in (0, 1):
            end = max(end, row[1])
        elif sh == 2:
            end = max(end, row[2] + 4 * row[1])
        elif sh == 3:
            end = max(end, row[2])
    return end


def stable_step(problem, spec) -> float:
    """Largest stable step of ``spec`` for the problem: its limit / ω_max, and any other bound
    the build put on the step (explicit friction), rescaled from the problem's own method."""
    own = INTEGRATORS[problem.scene.solver.integrator].stability_limit
    h = spec.stability_limit / problem.omega_max if problem.omega_max > 0 else math.inf
    return min(h, problem.stable_dt * spec.stability_limit / own)


def extrapolate(errors: tuple[float, float], t_p: float, T: float) -> tuple[float, float]:
    """Error at T from the pilot's errors at t_p/2 and t_p: (error, growth exponent β).

    β = log2(e(t_p)/e(t_p/2)); up to GROWTH_POWER the error is taken to grow like t^max(β, 1),
    beyond it (errors amplified by the dynamics) exponentially, e(t_p) exp(λ (T − t_p)),
    λ = ln(e(t_p)/e(t_p/2)) / (t_p/2).
    """
    e_half, e_full = errors
    if e_full <= 0:
        return 0.0, 1.0
    beta = math.log2(e_full / e_half) if e_half > 0 else 1.0
    if T <= t_p:
        return e_full, beta
    if beta <= GROWTH_POWER:
        return e_full * (T / t_p) ** max(beta, 1.0), beta
    lam = math.log(e_full / e_half) / (0.5 * t_p)
    return e_full * math.exp(min(lam * (T - t_p), 700.0)), beta


def _pilot_errors(problem, spec, h1: float, t_p: float) -> tuple[tuple[float, float], float, int]:
    """Errors of steps h1 at t_p/2 and t_p, the observed order, and the steps taken.

    Runs at h1, h1/2 and h1/4: the observed order p_obs = log2(|q₁ − q₂| / |q₂ − q₄|) (clipped to
    [1, p]) catches order reduction — a kink in a prescribed drive, a contact opening — and the
    Richardson error is |q₁ − q₂| 2^p_obs/(2^p_obs − 1).
    """
    runs = [integrate(problem, spec, h1 / 2**k, t_p, checkpoints=(0.5, 1.0)) for k in range(3)]
    pk = np.maximum.reduce([r[1] for r in runs])
    s = problem.system
    d = [[state_error(s, runs[k][0][j], runs[k + 1][0][j], pk) for j in (0, 1)] for k in (0, 1)]
    p = spec.order
    p_obs = math.log2(d[0][1] / d[1][1]) if d[1][1] > 0 and d[0][1] > 0 else p
    p_obs = min(max(p_obs, 1.0), p)
    rich = 2**p_obs / (2**p_obs - 1)
    return (d[0][0] * rich, d[0][1] * rich), p_obs, sum(r[2] for r in runs)


def _step_for(accuracy: float, err1: float, h1: float, p: int, h_stab: float, T: float) -> float:
    """The step for ``accuracy``, never above the pilot's largest step h1: the h^p law was only
    observed below it (above it a high-order method's error grows faster than h^p)."""
    h = h1 * (SAFETY * accuracy / err1) ** (1.0 / p) if err1 > 0 else CAP * h_stab
    return min(max(h, FLOOR * h_stab), CAP * h_stab, h1, T)


def choose(problem, accuracy: float, only: str | None = None) -> Choice:
    """Cheapest (integrator, dt) expected to meet ``accuracy`` (see module docstring)."""
    if problem.omega_max <= 0:
        raise PlanError("cannot choose a step: the system has no linear frequency (ω_max = 0)")
    T = problem.duration
    rows, best = [], None
    for spec in candidates(problem, only):
        p = spec.order
        h_stab = stable_step(problem, spec)
        h1 = min(0.5 * h_stab, T / 8)
        t_p = min(T, max(PILOT_FRACTION * T, PILOT_MIN_STEPS * h1, 1.5 * _drive_end(problem)))
        errs, p, n_pilot = _pilot_errors(problem, spec, h1, t_p)
        err1, beta = extrapolate(errs, t_p, T)
        h = _step_for(accuracy, err1, h1, p, h_stab, T)
        h_long = 7 * h / LONG_PILOT_SHARE
        if t_p < T and h_long <= h1:  # a pilot over all of T costs ≤ LONG_PILOT_SHARE of the run
            t_p, h1 = T, h_long
            errs, p, n_long = _pilot_errors(problem, spec, h1, T)
            n_pilot += n_long
            err1, beta = errs[1], math.log2(errs[1] / errs[0]) if errs[0] > 0 else 1.0
            h = _step_for(accuracy, err1, h1, p, h_stab, T)
        predicted = err1 * (h / h1) ** p
        why = "" if predicted <= accuracy else f"even {FLOOR:g} x the stable step is predicted to give {predicted:.2g}"
        uncertain = (f"pilot error {err1:.2g} at {h1 / h:.0f}x the chosen step is outside the h^{p:.1f} regime"
                     if err1 >= SATURATED else "")
        cost = force_evals(spec) * math.ceil(T / h)
        rows.append(dict(integrator=spec.name, order=spec.order, observed_order=p, dt=h, stable_dt=h_stab, pilot_error=errs[1],
                         growth=beta, predicted_error=predicted, cost=cost,
                         pilot_cost=force_evals(spec) * n_pilot,
                         reachable=not why, why=why, uncertain=uncertain))
        better = best is None or (rows[-1]["reachable"], -cost) > (best_row["reachable"], -best.cost)
        if better:
            best, best_row = Choice(spec.name, h, rows[-1]["predicted_error"], cost, t_p, order=p), rows[-1]
    if best is None:
        raise PlanError("no registered integrator can be costed for this scene")
    best.table = rows
    best.reachable = best_row["reachable"]
    return best


@dataclass
class Estimate:
    """Pilot estimate of the error a run with step h reaches at its end (``estimate``)."""

    error: float
    growth: float  # exponent β of the pilot's error growth (``extrapolate``)
    pilot_time: float
    wall_s: float


def pilot_window(problem, h: float) -> float:
    """Duration of a pilot: PILOT_FRACTION of the run, at least PILOT_MIN_STEPS steps and past the drives."""
    T = problem.duration
    return min(T, max(PILOT_FRACTION * T, PILOT_MIN_STEPS * h, 1.5 * _drive_end(problem)))


def estimate(problem, spec, h: float) -> Estimate:
    """Step doubling on a pilot: the error of steps h at the end of the run.

    Runs of h and h/2 over ``pilot_window``; Richardson with the method's order gives the error of
    h at half the window and at its end, ``extrapolate`` carries it to the duration (exact when the
    window is the whole run). Costs 3 × window/h steps (a tenth of the run: 0.3 runs).
    """
    import time

    t0 = time.perf_counter()
    t_p = pilot_window(problem, h)
    runs = [integrate(problem, spec, h / 2**k, t_p, checkpoints=(0.5, 1.0)) for k in range(2)]
    pk = np.maximum(runs[0][1], runs[1][1])
    rich = 2**spec.order / (2**spec.order - 1)
    errs = tuple(state_error(problem.system, runs[0][0][j], runs[1][0][j], pk) * rich for j in (0, 1))
    err, beta = extrapolate(errs, t_p, problem.duration)
    return Estimate(err, beta, t_p, time.perf_counter() - t0)


@dataclass
class Check:
    """Step-doubling (or halving) estimate of the error of a finished run."""

    estimate: float
    companion_dt: float
    method: str
    wall_s: float


def check(problem, integrator: str, h: float, t_end: float, q: np.ndarray, order: float | None = None) -> Check:
    """Error estimate of the final state ``q`` of a run with steps h, from a companion run.

    ``order``: the order observed in the pilot (default: the method's).
    """
    import time

    spec = INTEGRATORS[integrator]
    p = spec.order if order is None else order
    h_stab = stable_step(problem, spec)
    t0 = time.perf_counter()
    if 2 * h <= CAP * h_stab:
        n2 = max(1, round(t_end / (2 * h)))
        h2, how = t_end / n2, "step doubling"
    else:
        n2 = max(1, round(t_end / (h / 2)))
        h2, how = t_end / n2, "step halving"
    q2, _, peaks, _ = integrate(problem, spec, h2, t_end)
    ratio = (h2 / h) ** p
    diff = state_error(problem.system, q, q2, peaks)
    est = diff / abs(ratio - 1.0)  # |q_h − q_h2| ≈ |ratio − 1| err(h)
    return Check(est, h2, how, time.perf_counter() - t0)
