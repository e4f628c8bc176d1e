"""Pick the cheapest integrator and step that meet ``solver.accuracy``, and estimate the error reached.

Accuracy is the relative error of the quantities a run reports — how fast waves travel and how
large they are — not of the final state (whose error grows without bound once a wave field turns
chaotic after reflections, while the speeds and amplitudes a run measures stay good). Over a
window [0, T_w] the lattice fields q_f,i(t) − q_f,i(0) — and, for models without rotations, whose
runs report the strain, the strain q_{i+1} − q_i of the displacement — are sampled on a fixed
time grid (``Trace``); against a reference trace q* (a finer step), for each field f

    amplitude error  e_A = max_i |P_i − P*_i| / max_i P*_i,   P_i = max_t |q_f,i(t) − q_f,i(0)|,
                     over the sites a wave has passed (peak before the window's last tenth, and
                     |q − q0| fallen below ``PASSED`` of it by the end: at a site a wave is still
                     reaching, the peak measures its timing, not its size),
    speed error      e_c = Σ_i |t_i − t*_i| t*_i / Σ_i t*_i²,

t_i the first time site i reaches half its peak P*_i (linear interpolation between samples, the
same grid for both traces, so the interpolation cancels to first order): a wave whose speed is
off by δc/c arrives at every site late by t δc/c, and e_c = δc/c. Sites below ``SITE_FLOOR`` of
the field's largest peak (tails ahead of the waves) and sites already displaced at t = 0 are left
out, and so is the ``TRIM`` tenth of the sites with the largest deviation (a site at a collision
or at a snapping threshold has an ill-conditioned timing; an integration error moves every site
alike). err = max_f max(e_A, e_c). For a steady pulse both are intensive — its speed error does
not grow along the run — so the step is chosen on a pilot of ``PILOT_FRACTION`` of the run (at
least ``PILOT_MIN_STEPS`` steps and past the drives). They are not intensive for a breathing
pulse or a standing wave, whose phase error keeps growing: the estimate a run reports
(``run_estimate``) is therefore measured over the whole run when that is cheap (step doubling,
with a trace at h/4 that tells whether the quantities converge in the step at all), and
otherwise extrapolated from the pilot with the error's growth measured over its window.

For a method of order p, err(h) ≈ C h^p. A pilot runs each candidate at h₁ = h_stab/3 (``PILOT_STEP``) and h₁/2
over the window; Richardson gives err(h₁) ≈ d(h₁, h₁/2) 2^p/(2^p − 1), d the error of one trace
against the other (``estimate``), and

    h = h₁ (S · accuracy / err(h₁))^{1/p},   S = SAFETY,

between FLOOR × the stable step h_stab = stability_limit/ω_max and min(2 h₁, CAP × h_stab),
at most 1/``DRIVE_STEPS`` of the fastest drive's period (``drive_step``), shortened so that it
divides the frame interval. The cost of a method
is its force evaluations per step × T/h; the cheapest wins. At h₁ the error is often not
yet in its h^p regime (a kink in a drive lowers the order, high-frequency content raises the
apparent one), so a step other than h₁ is measured again by the same step doubling (``verify``)
and shortened until the measurement meets the target: the estimate every dataset stores is the one
measured at the step used. If even FLOOR·h_stab misses, the plan says the accuracy is out of
reach. With ``solver.error_check: run`` the estimate covers the whole run instead of the window.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from flexmm.errors import PlanError
from flexmm.integrators import INTEGRATORS
from flexmm.integrators.stepper import make_stepper
from flexmm.io.pause import pause_point

SAFETY = 0.3
PILOT_STEP = 1 / 3  # the pilot's step as a fraction of the stable step (near where a 4th-order method lands)
CAP = 0.8  # largest step as a fraction of the linear stability limit
FLOOR = 1e-3  # smallest step as a fraction of it (an accuracy out of reach is reported, not chased)
SATURATED = 0.1  # a pilot error this large is outside the h^p regime: the prediction is uncertain
PILOT_FRACTION = 0.1
PILOT_MIN_STEPS = 400
SAMPLES = 512  # samples of a trace over its window (fewer when the window has fewer steps)
MAX_SITES = 2048  # sites a trace keeps per field (a larger lattice is sampled at a stride)
PASSED = 0.9  # a wave has passed a site once the site's |q − q0| is below this fraction of its peak
TRIM = 0.1  # fraction of sites with the largest deviations left out (``_kept``)
#: largest motion (nondimensional: of the lattice's length scale, or rad) below which a field
#: carries no wave: round-off about a static (e.g. relaxed) state, whose relative errors are noise
MOTION_FLOOR = 1e-10
SITE_FLOOR = 0.2  # sites whose peak is below this fraction of the field's largest are left out


def force_evals(spec) -> float | None:
    """Force evaluations per step of an integrator (its registry entry; None if not known)."""
    val = getattr(spec, "force_evals", None)
    if isinstance(val, (int, float)) and math.isfinite(val) and val > 0:
        return float(val)
    return None


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
        if not spec.explicit_limit or spec.stability_limit <= 0:
            continue  # adaptive, implicit or unconditionally stable: not costed here
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
    st = make_stepper(problem, spec, h=t_end / n_steps, threads=1, check_energy=False).bounded_calls()
    marks = sorted({*np.linspace(0, n_steps, min(n_samples, n_steps) + 1).round().astype(int)[1:],
                    *(int(round(c * n_steps)) for c in checkpoints)})
    chunks = [k - j for j, k in zip([0, *marks[:-1]], marks) if k > j]
    peaks = _peaks(st.system, st.q)
    states = {}

    def sample(s) -> None:
        nonlocal peaks
        peaks = np.maximum(peaks, _peaks(s.system, s.q))
        states[int(round(s.t / s.h))] = s.q.copy()

    st.run(chunks, sample, reraise=True)  # a signal stops the pilot, never shortens it
    if checkpoints:
        return [states[int(round(c * n_steps))] for c in checkpoints], peaks, n_steps
    return st.q, st.v, peaks, n_steps


def _peaks(system, q) -> np.ndarray:
    n = system.n_sites
    return np.array([np.max(np.abs(q[k * n : (k + 1) * n])) for k in range(len(system.fields))])


def state_error(system, q: np.ndarray, q_ref: np.ndarray, peaks: np.ndarray) -> float:
    """Relative error of a state: max over moving fields of max_i |q − q_ref| / the field's peak."""
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
class Trace:
    """The lattice fields' change from t = 0, |q(t) − q(0)| (and the strain's, for models whose
    runs report it), at ``SAMPLES`` + 1 uniform times of a window: ``x`` (n_samples + 1, fields,
    n_kept_sites), ``dt`` the sample interval."""

    x: np.ndarray
    dt: float
    steps: int
    finite: bool = True


def _sampled(system) -> tuple[np.ndarray, np.ndarray | None]:
    """Indices into q of the sampled sites of every field (fields × sites), and for a model
    without rotations — whose runs report the strain of the displacement — the (i, i + 1) pairs
    of the first field's strain (2 × sites), as ``analysis.features.fields`` takes it, else None."""
    n, nf = system.n_sites, len(system.fields)
    stride = max(1, math.ceil(n / MAX_SITES))
    sites = np.arange(0, n, stride)
    idx = np.arange(nf)[:, None] * n + sites[None, :]
    if any(f.name == "theta" for f in system.fields) or n < 2:
        return idx, None
    i = np.minimum(sites, n - 2)
    return idx, np.stack([i, i + 1])


def sampler(system):
    """The function q -> the values a ``Trace`` keeps of state q (fields × sites, with the strain
    where runs report it, ``_sampled``)."""
    idx, pairs = _sampled(system)

    def values(q: np.ndarray) -> np.ndarray:
        v = q[idx]
        return v if pairs is None else np.vstack([v, (q[pairs[1]] - q[pairs[0]])[None, :]])

    return values


def frames_trace(system, q: np.ndarray, dt: float) -> Trace:
    """The ``Trace`` of saved states q (n_frames, ndof) ``dt`` apart (nondimensional): what a run's
    frames give for ``quantity_error`` (the work–precision chart measures methods on it)."""
    values = sampler(system)
    x = np.abs(np.stack([values(row) for row in q]) - values(q[0]))
    return Trace(x, dt, 0, bool(np.all(np.isfinite(x))))


def trace(problem, spec, n_steps: int, t_end: float, n_samples: int) -> Trace:
    """Run ``n_steps`` equal steps to ``t_end`` (a multiple of ``n_samples``) and sample every
    ``n_steps/n_samples`` steps (``Trace``: the fields, and the strain where runs report it)."""
    pause_point("pilot")
    st = make_stepper(problem, spec, h=t_end / n_steps, threads=1, check_energy=False).bounded_calls()
    values = sampler(st.system)
    x0 = values(st.q)
    x = np.zeros((n_samples + 1, *x0.shape))
    k = [0]

    def sample(s) -> None:
        k[0] += 1
        x[k[0]] = np.abs(values(s.q) - x0)

    out = st.run([n_steps // n_samples] * n_samples, sample, reraise=True)  # a signal stops the pilot
    ok = out.ok and k[0] == n_samples and bool(np.all(np.isfinite(x)))
    return Trace(x, t_end / n_samples, n_steps, ok)


def _kept(dev: np.ndarray) -> np.ndarray:
    """The sites a measurement keeps: all but the ``TRIM`` fraction with the largest deviation
    (sites at a collision or a threshold whose timing is ill-conditioned; an integration error
    moves every site alike, and a measured speed or amplitude is a fit over many sites)."""
    if dev.size < 1 / TRIM:
        return np.ones(dev.size, bool)
    return dev <= np.quantile(dev, 1.0 - TRIM)


def _crossings(x: np.ndarray, level: np.ndarray, dt: float) -> np.ndarray:
    """First time each column of ``x`` (samples × sites) reaches ``level`` (NaN: never, or at t = 0)."""
    above = x >= level[None, :]
    k = np.argmax(above, axis=0)
    cols = np.arange(x.shape[1])
    hit = above[k, cols] & (k > 0)
    k = np.maximum(k, 1)
    lo, hi = x[k - 1, cols], x[k, cols]
    frac = np.clip((level - lo) / np.where(hi > lo, hi - lo, 1.0), 0.0, 1.0)
    return np.where(hit, (k - 1 + frac) * dt, np.nan)


def _peak(x: np.ndarray) -> np.ndarray:
    """Largest value along axis 0, refined by the parabola through the largest sample and its
    neighbours (a crest's sampled height would otherwise depend on where the samples fall)."""
    k = np.clip(np.argmax(x, axis=0), 1, max(x.shape[0] - 2, 1))
    y0, y1, y2 = (np.take_along_axis(x, (k + j)[None], axis=0)[0] for j in (-1, 0, 1))
    curv = 2 * y1 - y0 - y2
    vertex = y1 + (y0 - y2) ** 2 / (8 * np.where(curv > 0, curv, 1.0))
    return np.maximum(x.max(axis=0), np.where((curv > 0) & (y1 >= y0) & (y1 >= y2), vertex, 0.0))


@dataclass(frozen=True)
class QuantityError:
    """Error of the reported quantities of one trace against a reference (module docstring)."""

    amplitude: float
    speed: float

    @property
    def total(self) -> float:
        return max(self.amplitude, self.speed)


def quantity_error(a: Trace, ref: Trace) -> QuantityError:
    """Amplitude and speed error of ``a`` against ``ref`` (same window and sample grid)."""
    if not (a.finite and ref.finite):
        return QuantityError(math.inf, math.inf)
    peak_a, peak_r = _peak(a.x), _peak(ref.x)  # (fields, sites)
    top_all = float(peak_r.max()) if peak_r.size else 0.0
    e_amp = e_c = 0.0
    for f in range(peak_r.shape[0]):
        top = float(peak_r[f].max())
        if top <= 1e-12 * top_all or top <= MOTION_FLOOR:
            continue  # a field that does not move (round-off about a static state is no wave)
        sel = peak_r[f] >= SITE_FLOOR * top
        # amplitudes of the waves that have passed: the peak before the window's last tenth and
        # fallen from since (at a site a wave is still reaching, the peak measures the timing)
        x_r = ref.x[:, f, :]
        done = sel & (np.argmax(x_r, axis=0) <= 0.9 * (x_r.shape[0] - 1)) & (x_r[-1] <= PASSED * peak_r[f])
        if np.any(done):
            dev = np.abs(peak_a[f, done] - peak_r[f, done]) / top
            e_amp = max(e_amp, float(np.max(dev[_kept(dev)])))
        level = 0.5 * peak_r[f, sel]
        t_a = _crossings(a.x[:, f, sel], level, a.dt)
        t_r = _crossings(ref.x[:, f, sel], level, ref.dt)
        ok = np.isfinite(t_a) & np.isfinite(t_r) & (t_r > 0)
        if np.any(ok):
            dt, tr = np.abs(t_a[ok] - t_r[ok]), t_r[ok]
            keep = _kept(dt / tr)
            e_c = max(e_c, float(np.sum(dt[keep] * tr[keep]) / np.sum(tr[keep] ** 2)))
        elif np.any(np.isfinite(t_a) != np.isfinite(t_r)):
            e_c = math.inf  # a wave that reaches sites in one run and not in the other
    return QuantityError(e_amp, e_c)


def window_grid(t_end: float, h: float) -> tuple[int, int, float]:
    """(steps, samples, window) for steps of exactly h covering at least ``t_end``: at most
    SAMPLES samples, every ``steps/samples`` steps (the window is rounded up to whole samples)."""
    n = max(1, math.ceil(t_end / h - 1e-9))
    per = max(1, math.ceil(n / SAMPLES))
    n_samples = max(1, math.ceil(n / per))
    return per * n_samples, n_samples, per * n_samples * h


def richardson(d: float, p: float) -> float:
    """Error of the coarser of two steps h, h/2 from their difference d (order p)."""
    return d * 2**p / (2**p - 1)


def _step_for(accuracy: float, err1: float, h1: float, p: float, h_stab: float, T: float) -> float:
    """The step for ``accuracy`` by the h^p law from the pilot's error at h1: at most 2 h1 (the law
    is trusted over a small ratio only, and ``verify`` measures the result) and CAP × h_stab."""
    h = h1 * (SAFETY * accuracy / err1) ** (1.0 / p) if err1 > 0 else 2 * h1
    return min(max(h, FLOOR * h_stab), CAP * h_stab, 2 * h1, T)


@dataclass
class Choice:
    """The integrator and step chosen for a requested accuracy, with the pilot's evidence."""

    integrator: str
    dt: float  # nondimensional
    predicted_error: float
    cost: float  # force evaluations for the whole run
    pilot_time: float  # nondimensional duration of the pilot
    table: list[dict] = field(default_factory=list)  # one row per candidate
    reachable: bool = True  # False: even the smallest step allowed misses
    order: float = 2.0  # the method's order
    estimate: Estimate | None = None  # step doubling measured at ``dt`` (``verify``)


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


#: steps per period of a harmonic drive, or per duration (per width, for a gaussian) of a pulse
DRIVE_STEPS = 16


def drive_step(problem) -> float:
    """Largest step that resolves the drives: ``DRIVE_STEPS`` per period of the fastest harmonic
    drive, per duration of a half-sine or smooth step, per width of a gaussian (inf without
    drives). The pilot's measure leaves the driven sites' own prescribed motion out, so a drive
    sampled by a few steps would otherwise go unnoticed."""
    scales = []
    for row, sh in zip(problem.terms.drv_prm, problem.terms.drv_shape):
        if sh == 3 and row[1] > 0:
            scales.append(2 * math.pi / row[1])
        elif sh in (0, 1, 2) and row[1] > 0:
            scales.append(row[1])
    return min(scales) / DRIVE_STEPS if scales else math.inf


def stable_step(problem, spec) -> float:
    """Largest stable step of ``spec`` for the problem: its limit / ω_max, and any other bound
    the build put on the step (explicit friction), rescaled from the problem's own method."""
    own = INTEGRATORS[problem.scene.solver.integrator].stability_limit
    h = spec.stability_limit / problem.omega_max if problem.omega_max > 0 else math.inf
    return min(h, problem.stable_dt * spec.stability_limit / own)


def pilot_window(problem, h: float) -> float:
    """Duration of a pilot: PILOT_FRACTION of the run, at least PILOT_MIN_STEPS steps and past the drives."""
    T = problem.duration
    return min(T, max(PILOT_FRACTION * T, PILOT_MIN_STEPS * h, 1.5 * _drive_end(problem)))


def divides(h: float, every: float | None) -> float:
    """The largest step ≤ h that divides the frame interval ``every`` (h itself without one)."""
    return every / math.ceil(every / h - 1e-9) if every is not None and every > h else h


def choose(problem, accuracy: float, only: str | None = None, every: float | None = None) -> Choice:
    """Cheapest (integrator, dt) that meets ``accuracy`` (module docstring); ``every`` the frame
    interval the step must divide (nondimensional; None: any step)."""
    if problem.omega_max <= 0:
        raise PlanError("cannot choose a step: the system has no linear frequency (ω_max = 0)")
    T = problem.duration
    rows, best, best_row, pilots = [], None, None, {}
    for spec in candidates(problem, only):
        h_stab = stable_step(problem, spec)
        h1 = divides(min(PILOT_STEP * h_stab, T / 8, drive_step(problem)), every)
        t_p = pilot_window(problem, h1)
        t0 = time.perf_counter()
        est1 = estimate(problem, spec, h1, window=t_p)
        p = spec.order
        h = divides(min(_step_for(accuracy, est1.error, h1, p, h_stab, T), drive_step(problem)), every)
        predicted = est1.error * (h / h1) ** p
        cost = force_evals(spec) * math.ceil(T / h)
        pilots[spec.name] = est1
        rows.append(dict(integrator=spec.name, order=p, dt=h, stable_dt=h_stab, pilot_dt=h1, pilot_error=est1.error,
                         amplitude_error=est1.amplitude, speed_error=est1.speed, predicted_error=predicted,
                         cost=cost, pilot_cost=force_evals(spec) * 3 * math.ceil(t_p / h1),
                         pilot_wall_s=time.perf_counter() - t0, reachable=True, why="",
                         uncertain=(f"pilot error {est1.error:.2g} at {h1 / h:.0f}x the chosen step is outside "
                                    f"the h^{p} regime" if est1.error >= SATURATED else "")))
        if best is None or cost < best.cost:
            best, best_row = Choice(spec.name, h, predicted, cost, t_p, order=p), rows[-1]
    if best is None:
        raise PlanError("no registered integrator can be costed for this scene")
    if best.dt == best_row["pilot_dt"]:
        best.estimate = pilots[best.integrator]  # measured at the step itself
    else:
        verify(problem, accuracy, best, best_row, every, pilots[best.integrator])
    best.predicted_error = best.estimate.error
    best.reachable = best.estimate.error <= accuracy
    if not best.reachable:
        best_row.update(reachable=False, why=best_row["why"] or f"the error measured at the step used is "
                        f"{best.estimate.error:.2g}")
    best.table = rows
    return best


#: steps tried by ``verify`` before the accuracy is reported out of reach
VERIFY_TRIES = 3


def verify(problem, accuracy: float, choice: Choice, row: dict, every: float | None, pilot: Estimate) -> None:
    """Measure the error at the chosen step by step doubling over the pilot window and shorten the
    step until the measurement meets ``accuracy`` (at most ``VERIFY_TRIES`` steps, each as the h^p
    law asks but between 1.2× and 4× shorter than the last, never below FLOOR × the stable step).
    The pilot's error at h₁ is often pre-asymptotic, so its h^p extrapolation can be off either
    way; the estimate stored is the one measured at the step used.

    An error that does not halve when the step shrinks is not the integrator's: the measured
    quantities do not converge (a timing at a threshold or collision that step doubling cannot
    resolve). Then the longer of the two steps is kept, and the plan says so (``row['why']``),
    rather than paying for ever smaller steps."""
    spec = INTEGRATORS[choice.integrator]
    p, h = spec.order, choice.dt
    floor = FLOOR * row["stable_dt"]
    t0 = time.perf_counter()
    prev = (row["pilot_dt"], pilot)
    for k in range(VERIFY_TRIES):
        est = estimate(problem, spec, h, window=choice.pilot_time)
        if prev[0] > h and est.error > 0.5 * prev[1].error and est.error > accuracy:
            row["converges"] = False  # the estimate measures a threshold's timing, not the step's error
            row["why"] = (f"the error estimate does not shrink with the step ({prev[1].error:.2g} at "
                          f"{prev[0]:.3g}, {est.error:.2g} at {h:.3g}, nondimensional): what the run reports "
                          "is not converging in the step (a threshold or a collision)")
            h, est = prev
            break
        if est.error <= accuracy or h <= floor or k == VERIFY_TRIES - 1:
            break
        prev = (h, est)
        law = h * (SAFETY * accuracy / est.error) ** (1.0 / p)
        h = divides(max(min(h / 1.2, law), h / 4, floor), every)
    choice.dt, choice.estimate = h, est
    choice.cost = force_evals(spec) * math.ceil(problem.duration / h)
    row.update(dt=h, cost=choice.cost, predicted_error=est.error, verified_error=est.error,
               verify_tries=k + 1, pilot_wall_s=row["pilot_wall_s"] + time.perf_counter() - t0)


@dataclass
class Estimate:
    """Step-doubling estimate of the error of the reported quantities of a run with step h.

    ``growth``: the exponent γ of the error's growth over the window, err(t) ∝ t^γ (from its
    first half to the whole, clipped to [0, MAX_GROWTH]); ``converges``: False when a whole-run
    check found the difference of h/2 and h/4 not below half that of h and h/2 (the quantities do
    not converge in the step: a chaotic field, a threshold's timing), None when not checked."""

    error: float
    amplitude: float
    speed: float
    window: float  # nondimensional duration the estimate covers
    method: str  # 'step doubling on a pilot', '... extrapolated to the run', '... over the whole run'
    wall_s: float
    growth: float = 0.0
    converges: bool | None = None


#: largest growth exponent of the error in time taken from a pilot (a phase error grows like t,
#: its effect on a breathing pulse's sampled peaks like t²)
MAX_GROWTH = 2.0
#: a whole-run check (traces at h, h/2 and h/4: 7 runs' worth of steps) is made instead of an
#: extrapolation when it costs at most this many unit force evaluations (~1–5 s on one core)
WHOLE_RUN_WORK = 5e7
#: ... or at most this many times more when the pilot's growth reached MAX_GROWTH: the error grows
#: at least that fast, so the extrapolation is only a lower bound (a cnoidal shaker's amplitudes:
#: extrapolated 3.5e-5 as t², measured 3.5e-4 over the whole run)
SATURATED_WORK = 4.0


def _growth(a: Trace, b: Trace, order: float, err: float) -> float:
    """γ of err(t) ∝ t^γ from the error over the first half of the traces' window and the whole."""
    half = a.x.shape[0] // 2
    if half < 8 or not err > 0:
        return 0.0
    cut = [Trace(t.x[: half + 1], t.dt, t.steps, t.finite) for t in (a, b)]
    d = quantity_error(*cut)
    e_half = max(richardson(d.amplitude, order), richardson(d.speed, order))
    if not (e_half > 0 and math.isfinite(e_half)):
        return MAX_GROWTH if math.isfinite(err) else 0.0
    return float(min(max(math.log(err / e_half) / math.log(2.0), 0.0), MAX_GROWTH))


def estimate(problem, spec, h: float, whole_run: bool = False, window: float | None = None) -> Estimate:
    """Step doubling at h: traces at h and h/2 over ``pilot_window`` (or the whole run, or
    ``window``), Richardson with the method's order (module docstring), and the error's growth
    over the window (``Estimate.growth``). Costs 3 × window/h steps."""
    t0 = time.perf_counter()
    t_w = problem.duration if whole_run else window if window is not None else pilot_window(problem, h)
    n, n_samples, t_w = window_grid(t_w, h)
    a, b = trace(problem, spec, n, t_w, n_samples), trace(problem, spec, 2 * n, t_w, n_samples)
    d = quantity_error(a, b)
    amp, speed = richardson(d.amplitude, spec.order), richardson(d.speed, spec.order)
    how = "step doubling over the whole run" if whole_run else "step doubling on a pilot"
    err = max(amp, speed)
    return Estimate(err, amp, speed, t_w, how, time.perf_counter() - t0, _growth(a, b, spec.order, err))


def whole_run_cheap(problem, spec, h: float, budget: float = WHOLE_RUN_WORK) -> bool:
    """Whether a whole-run check at h (``run_estimate``) costs at most ``budget`` unit force evaluations."""
    evals = force_evals(spec) or 1.0
    return 7 * math.ceil(problem.duration / h) * evals * problem.system.n_sites <= budget


def run_estimate(problem, spec, h: float, pilot: Estimate) -> Estimate:
    """The error of the reported quantities over the whole run at step h (issue: a pilot covers a
    tenth of the run, and a phase error keeps growing after it).

    When cheap (``whole_run_cheap``), measured: step doubling over the whole run, plus a trace at
    h/4 that tells whether the difference shrinks with the step (``converges``). Otherwise the
    pilot's estimate extrapolated to the run's duration T: err · (T / T_w)^γ with the growth γ
    measured over the pilot window (γ = 0 for an intensive error: a steady pulse's speed). A growth
    at the cap MAX_GROWTH makes the extrapolation a lower bound: the whole run is then measured up
    to SATURATED_WORK times the usual cost, and an extrapolation beyond it says "at least"."""
    T = problem.duration
    if pilot.window >= T * (1 - 1e-9):
        return pilot
    saturated = pilot.growth >= MAX_GROWTH
    if whole_run_cheap(problem, spec, h, WHOLE_RUN_WORK * (SATURATED_WORK if saturated else 1.0)):
        return _whole_run(problem, spec, h, pilot)
    f = (T / pilot.window) ** pilot.growth
    how = (f"{pilot.method}, extrapolated to the whole run as t^{pilot.growth:.2g} (at least: its growth "
           f"over the pilot reached the cap)," if saturated
           else f"{pilot.method}, extrapolated to the whole run as t^{pilot.growth:.2g}," if pilot.growth > 0
           else f"{pilot.method}, an error that does not grow along it,")
    return Estimate(pilot.error * f, pilot.amplitude * f, pilot.speed * f, pilot.window, how,
                    pilot.wall_s, pilot.growth)


def observed_order(d1: float, d2: float, order: float) -> float:
    """The order the differences d1 = |q(h) − q(h/2)| and d2 = |q(h/2) − q(h/4)| show, log2(d1/d2),
    when it is below the method's ``order`` (a non-smooth force — a Hertz contact opening, a
    friction's regularised switch — lowers it), else ``order``; at least 1."""
    if not (d1 > 0 and d2 > 0 and math.isfinite(d1 / d2)):
        return order
    return float(min(order, max(1.0, math.log2(d1 / d2))))


def _whole_run(problem, spec, h: float, pilot: Estimate) -> Estimate:
    """Step doubling over the whole run at h, with the h/4 trace for ``converges`` and for the order
    Richardson uses (``observed_order``: an error that converges slower than the method's order is
    underestimated by it — a Hertz chain's impact, 1.4x)."""
    t0 = time.perf_counter()
    n, n_samples, t_w = window_grid(problem.duration, h)
    a, b, c = (trace(problem, spec, k * n, t_w, n_samples) for k in (1, 2, 4))
    d, d2 = quantity_error(a, b), quantity_error(b, c)
    amp = richardson(d.amplitude, observed_order(d.amplitude, d2.amplitude, spec.order))
    speed = richardson(d.speed, observed_order(d.speed, d2.speed, spec.order))
    converges = not (d.total > 0 and d2.total > 0.5 * d.total)
    return Estimate(max(amp, speed), amp, speed, t_w, "step doubling over the whole run (cheap enough to check)",
                    pilot.wall_s + time.perf_counter() - t0, pilot.growth, converges)


def shorten_for_run(problem, choice: Choice, est: Estimate, accuracy: float, every: float | None) -> Estimate:
    """Shorten the chosen step while the whole-run estimate (``run_estimate``) misses ``accuracy``
    and is measured (cheap) and converging: at most VERIFY_TRIES steps, each as the h^p law asks
    but between 1.2× and 4× shorter, never below FLOOR × the stable step. Updates ``choice``
    (dt, cost, estimate, predicted error); returns the estimate at the step kept."""
    spec = INTEGRATORS[choice.integrator]
    p, h = spec.order, choice.dt
    floor = FLOOR * stable_step(problem, spec)
    for _ in range(VERIFY_TRIES):
        if est.error <= accuracy or est.converges is not True or h <= floor:
            break
        law = h * (SAFETY * accuracy / est.error) ** (1.0 / p)
        h_new = divides(max(min(h / 1.2, law), h / 4, floor), every)
        if not whole_run_cheap(problem, spec, h_new, 4 * WHOLE_RUN_WORK):
            break
        h, est = h_new, _whole_run(problem, spec, h_new, choice.estimate)
    if h != choice.dt:
        choice.dt, choice.predicted_error = h, est.error
        choice.cost = force_evals(spec) * math.ceil(problem.duration / h)
        choice.reachable = est.error <= accuracy
        for row in choice.table:
            if row["integrator"] == choice.integrator:
                row.update(dt=h, cost=choice.cost, predicted_error=est.error)
                if not choice.reachable:
                    row["why"] = (f"over the whole run the error at the shortest step tried, {h:.3g} "
                                  f"(nondimensional), is {est.error:.2g}")
    return est
