"""Measured stability limits: raise dt for each method until the run actually goes unstable.

For a fixed-step explicit method the predicted limit is h* = stability_limit/ω_max, with
ω_max at rest and (for softening or contact laws) the largest along a pilot run
(``stability.trajectory_omega_max``). The scan starts at ``start`` × h*, multiplies h by
``factor`` until a trial is unstable, then bisects the bracket to ``rel_tol``. The measured
limit is the largest step whose trial was stable. On the way up the bracket also tries
h* (1 ∓ ``PROBE``): a method's first unstable band can be far narrower than the bracket's
factor — splitting methods have resonance bands near hω = kπ, and Blanes–Moan's starts at
hω = 3.14144 and is 9e-4 wide (growth ≤ 4.4e-4 per step), with stable steps again above it —
and a blind factor would step over it. Every method is judged by the same criterion:

- ``growth_threshold=None`` (a scene, ``flexmm stability CONFIG``): unstable = the run blows up
  (non-finite state or energy × 1e4, ``runner.integrate``) before the scene's end;
- ``growth_threshold=g`` (the linear limit, ``--linear``): the chain's fastest mode alone is
  excited at amplitude ``MODE_AMPLITUDE`` (linear dynamics) and run for ``GROWTH_SPAN``/g steps;
  unstable = the run blows up, or the growth rate of its amplitude, half the least-squares slope
  of log energy against step number, exceeds g per step. A method whose amplification factor on
  that mode is |R| then counts as unstable once ln|R| > g, so the measured limit estimates the
  first hω with |R(ihω)| > e^g — not the first with |R| > 1 (``stability.harmonic_limit`` with
  ``growth_per_step=g`` gives that threshold limit; the difference only matters for methods whose
  |R| creeps past 1, such as dopri5 at fixed steps: +1.8 % for g = 1e-5).

Waiting for overflow instead misses weak instabilities: past its |R| = 1 limit (hω = 0.9972)
dopri5 grows by less than 1e-4 per step up to hω ≈ 1.1, so a run of a few thousand steps only
overflows far above the limit. Adaptive methods are scanned in fixed-step mode (the tableau's
own limit; with error control they do not blow up). A-stable methods are run at a ladder of
steps up to ``implicit_max`` × the Verlet limit and reported as "no instability up to ...".
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from flexmm.integrators import INTEGRATORS
from flexmm.integrators.runner import energy, integrate

GROWTH_THRESHOLD = 1e-5  # default detection threshold: amplitude growth per step, ln|R|
GROWTH_SPAN = 1.0  # trial length = GROWTH_SPAN / threshold steps (amplitude × e at the threshold)
GROWTH_FRAMES = 401  # energy samples fitted per trial
DECAY_FLOOR = 1e-8  # frames after the energy fell below this × initial are not fitted (decayed mode)
MODE_AMPLITUDE = 1e-6  # max |q| of the excited mode: linear to ~1e-12
PROBE = 1e-4  # the bracket also tries h_pred (1 ∓ PROBE)


@dataclass
class LimitRow:
    """One method's predicted and measured step limits (nondimensional and SI)."""

    method: str
    kind: str  # 'explicit', 'adaptive (fixed-step scan)', 'implicit'
    stability_limit: float  # h·ω_max where |R| first exceeds 1
    predicted_dt_s: float  # from ω_max at rest
    predicted_peak_dt_s: float  # from the largest ω_max along the pilot run
    measured_dt_s: float  # largest dt judged stable (inf: none unstable)
    ratio: float  # measured / predicted (rest)
    trials: list[tuple[float, bool, float]] = field(default_factory=list)  # (dt_s, stable, growth/step)
    note: str = ""
    criterion: str = "blow-up"  # what counted as unstable (see ``criterion_text``)
    threshold_limit: float = math.nan  # h·ω_max where ln|R| first exceeds the growth threshold

    @property
    def ratio_to_threshold(self) -> float:
        """Measured over the limit the detection threshold implies (≈ 1 if the method is linear)."""
        return self.ratio * self.stability_limit / self.threshold_limit

    def as_dict(self) -> dict:
        return {**asdict(self), "ratio_to_threshold": self.ratio_to_threshold}


def criterion_text(growth_threshold: float | None, t_end_s: float | None = None) -> str:
    """One line saying what the scan counted as unstable."""
    if growth_threshold is None:
        span = f" within {t_end_s:.4g} s" if t_end_s is not None else ""
        return f"unstable = the scene blows up (non-finite, or energy x 1e4){span}"
    n = math.ceil(GROWTH_SPAN / growth_threshold)
    return (f"unstable = fitted amplitude growth above {growth_threshold:g} per step (log energy over "
            f"{n} steps, fastest mode excited) or a blow-up: the measured limit estimates the first "
            f"h*omega with |R| > exp({growth_threshold:g}), not |R| > 1 (column 'at g')")


def mode_state(problem, amplitude: float = MODE_AMPLITUDE) -> tuple[np.ndarray, np.ndarray]:
    """The chain's fastest linear mode at rest, max |q| = ``amplitude``, zero velocity."""
    from flexmm.stability import top_mode

    _, shape = top_mode(problem.system, problem.terms)
    return amplitude * shape, np.zeros_like(shape)


def growth_rate(e: np.ndarray, steps_per_frame: int) -> float:
    """Amplitude growth per step: half the least-squares slope of ln e against step number.

    ``e`` (F,) is the energy above rest at equally spaced frames. Frames after it first falls
    below ``DECAY_FLOOR`` × e[0] (a strongly damped mode, now at round-off) are left out.
    """
    keep = np.flatnonzero(e < DECAY_FLOOR * e[0])
    n = max(2, int(keep[0]) if keep.size else e.size)
    steps = steps_per_frame * np.arange(n)
    slope = np.polyfit(steps, np.log(np.maximum(e[:n], 1e-300)), 1)[0]
    return 0.5 * float(slope)


def trial(problem, spec, h: float, *, t_end: float | None = None, growth_threshold: float | None = None,
          q0=None, v0=None) -> tuple[bool, float]:
    """(stable, growth per step) of one fixed-step run at step ``h`` (see the module docstring)."""
    if growth_threshold is None:
        tr = integrate(problem, spec, h=h, t_end=t_end, n_frames=11, q0=q0, v0=v0, ledger=False)
        return tr.ok, math.nan
    per_frame = math.ceil(GROWTH_SPAN / growth_threshold / (GROWTH_FRAMES - 1))
    tr = integrate(problem, spec, h=h, t_end=h * per_frame * (GROWTH_FRAMES - 1), n_frames=GROWTH_FRAMES,
                   q0=q0, v0=v0, ledger=False)
    if not tr.ok:
        return False, math.inf
    rest = energy(problem, np.zeros_like(tr.q[0]), np.zeros_like(tr.v[0]))
    e = np.array([energy(problem, q, v) for q, v in zip(tr.q, tr.v)]) - rest
    g = growth_rate(e, per_frame)
    return g <= growth_threshold, g


def measure_limit(problem, spec, h_pred: float, t_end: float | None = None, *, growth_threshold: float | None = None,
                  start: float = 0.7, factor: float = 1.15, rel_tol: float = 0.005, max_factor: float = 8.0,
                  q0=None, v0=None) -> tuple[float, list]:
    """Largest fixed step (nondimensional) judged stable; with the trials (h, stable, growth).

    The upward bracket never steps over h_pred (1 ∓ ``PROBE``): a prediction right to that
    precision is confirmed by a stable trial just below it and an unstable one just above, even
    when the first unstable band is narrow (module docstring).
    """
    trials = []
    probes = (h_pred * (1.0 - PROBE), h_pred * (1.0 + PROBE))

    def ok(h):
        good, g = trial(problem, spec, h, t_end=t_end, growth_threshold=growth_threshold, q0=q0, v0=v0)
        trials.append((h, good, g))
        return good

    h = start * h_pred
    while not ok(h):  # even the starting step fails: walk down
        h /= 2.0
        if h < 1e-6 * h_pred:
            return 0.0, trials
    lo = h
    while True:
        hi = lo * factor
        hi = next((p for p in probes if lo < p < hi), hi)
        if not ok(hi):
            break
        lo = hi
        if hi > max_factor * h_pred:
            return math.inf, trials
    while hi - lo > rel_tol * lo:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if ok(mid) else (lo, mid)
    return lo, trials


def _implicit_row(problem, name, spec, implicit_max, kw, ts) -> LimitRow:
    """A-stable method: a ladder of steps up to ``implicit_max`` × the Verlet limit."""
    ladder = [f * 2.0 / problem.omega_max for f in (1, 2, 5, 10, implicit_max)]
    trials = [(h, *trial(problem, spec, h, **kw)) for h in ladder]
    good = [h for h, g, _ in trials if g]
    measured = math.inf if all(g for _, g, _ in trials) else (max(good) if good else 0.0)
    note = (f"A-stable: stable at every step up to {implicit_max:g} x the Verlet limit" if math.isinf(measured)
            else "unstable (or Newton failed, even in substeps) at a step below the ladder's top")
    return LimitRow(name, "implicit", spec.stability_limit, math.inf, math.inf, measured * ts, math.inf,
                    [(h * ts, g, r) for h, g, r in trials], note)


def scan(problem, methods: list[str] | None = None, *, t_end: float | None = None, peak: bool = True,
         implicit_max: float = 20.0, growth_threshold: float | None = None, threshold_limits: bool = True,
         q0=None, v0=None, log=None) -> list[LimitRow]:
    """Predicted vs measured limits for ``methods`` (default: every registered method).

    ``growth_threshold`` selects the criterion (module docstring); with it and
    ``threshold_limits``, each row also gets the limit that threshold implies for the method
    (``stability.harmonic_limit``, compiled per method).
    """
    from flexmm.stability import harmonic_limit, trajectory_omega_max

    say = log or (lambda msg: None)
    ts = problem.system.scales.time_s
    t_end = problem.duration if t_end is None else t_end
    w_rest = problem.omega_max
    w_peak = trajectory_omega_max(problem)[0] if peak else w_rest
    say(f"ω_max at rest {w_rest / ts:.6g} rad/s, along a pilot run up to {w_peak / ts:.6g} rad/s")
    crit = criterion_text(growth_threshold, None if growth_threshold else t_end * ts)
    say(crit)
    kw = {"t_end": t_end, "growth_threshold": growth_threshold, "q0": q0, "v0": v0}
    rows = []
    for name in methods or list(INTEGRATORS):
        spec = INTEGRATORS[name]
        lim = spec.stability_limit
        if not math.isfinite(lim):
            rows.append(_implicit_row(problem, name, spec, implicit_max, kw, ts))
            rows[-1].criterion = crit
            say(f"{name}: {rows[-1].note}")
            continue
        h_pred, h_peak = lim / w_rest, lim / w_peak
        measured, trials = measure_limit(problem, spec, h_pred, **kw)
        kind = "adaptive (fixed-step scan)" if spec.adaptive else "explicit"
        note = "error control keeps adaptive runs stable; the scan uses fixed steps" if spec.adaptive else ""
        at_g = lim
        if growth_threshold is not None and threshold_limits:
            at_g = harmonic_limit(spec, growth_per_step=growth_threshold, hi=1.5 * lim)
        rows.append(LimitRow(name, kind, lim, h_pred * ts, h_peak * ts, measured * ts, measured / h_pred,
                             [(h * ts, g, r) for h, g, r in trials], note, crit, at_g))
        say(f"{name}: predicted {h_pred * ts:.5g} s (peak state {h_peak * ts:.5g} s), "
            f"measured {measured * ts:.5g} s, ratio {measured / h_pred:.3f}")
    return rows


def table(rows: list[LimitRow]) -> str:
    """Plain-text table of the scan, with the criterion it used."""
    head = (f"{'method':18s} {'h·ω_max':>8s} {'at g':>8s} {'predicted dt':>13s} {'at peak':>12s} "
            f"{'measured dt':>12s} {'ratio':>7s} {'ratio/g':>8s}")
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(f"{r.method:18s} {r.stability_limit:8.4g} {r.threshold_limit:8.4g} {r.predicted_dt_s:13.5g} "
                     f"{r.predicted_peak_dt_s:12.5g} {r.measured_dt_s:12.5g} {r.ratio:7.3f} "
                     f"{r.ratio_to_threshold:8.3f}" + (f"  ({r.note})" if r.note else ""))
    if rows:
        lines += ["", f"criterion: {rows[0].criterion}",
                  "ratio = measured / predicted (first h*omega_max with |R| > 1); "
                  "ratio/g = measured / the limit the threshold implies ('at g')"]
    return "\n".join(lines)


def figure(rows: list[LimitRow], path, title: str = "") -> None:
    """PNG: measured/predicted dt per method (band ±10 %), and every trial run."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 3.6), dpi=110)
    ax.axhspan(0.9, 1.1, color="0.9", label="±10 % of predicted")
    ax.axhline(1.0, color="0.5", lw=0.8)
    for k, r in enumerate(rows):
        if not math.isfinite(r.predicted_dt_s):
            ok = [dt for dt, good, _ in r.trials if good]
            text = f"A-stable:\nstable up to\ndt = {max(ok):.3g} s" if ok else "A-stable:\nNewton failed"
            ax.annotate(text, (k, 1.0), ha="center", va="center", fontsize=7)
            continue
        for dt, good, _ in r.trials:
            ax.plot(k, dt / r.predicted_dt_s, "o" if good else "x", color="tab:green" if good else "tab:red",
                    ms=4, alpha=0.6)
        ax.plot(k, r.ratio, "D", color="k", ms=6)
    ax.set_xticks(range(len(rows)), [r.method for r in rows], rotation=20, fontsize=8)
    ax.set_ylabel("dt / predicted limit (|R| = 1)")
    ax.set_title(title or "measured stability limits (◆ largest stable dt; o stable, x unstable)", fontsize=9)
    ax.legend(fontsize=7, loc="upper left")
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    if rows:
        fig.text(0.01, 0.01, rows[0].criterion.split(":")[0], ha="left", va="bottom", fontsize=6, color="0.3")
    fig.savefig(path)
    plt.close(fig)
