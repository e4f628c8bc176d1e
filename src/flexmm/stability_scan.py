"""Measured stability limits: raise dt for each method until the run actually blows up.

For a fixed-step explicit method the predicted limit is h* = stability_limit/ω_max, with
ω_max at rest and (for softening or contact laws) the largest along a pilot run
(``stability.trajectory_omega_max``). The scan starts at ``start`` × h*, multiplies h by
``growth`` until a run of the scene fails (non-finite state or energy × 1e4), then bisects the
bracket to ``rel_tol``. The measured limit is the largest step that still finished.

Adaptive methods are scanned in fixed-step mode (the tableau's own limit; with error control
they do not blow up). A-stable methods are run at a ladder of steps up to ``implicit_max`` × the
Verlet limit and reported as "no blow-up up to ...".
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from flexmm.integrators import INTEGRATORS
from flexmm.integrators.runner import integrate


@dataclass
class LimitRow:
    """One method's predicted and measured step limits (nondimensional and SI)."""

    method: str
    kind: str  # 'explicit', 'adaptive (fixed-step scan)', 'implicit'
    stability_limit: float  # h·ω_max
    predicted_dt_s: float  # from ω_max at rest
    predicted_peak_dt_s: float  # from the largest ω_max along the pilot run
    measured_dt_s: float  # largest dt that finished (inf: none failed)
    ratio: float  # measured / predicted (rest)
    trials: list[tuple[float, bool]] = field(default_factory=list)  # (dt_s, finished)
    note: str = ""

    def as_dict(self) -> dict:
        return asdict(self)


def _finishes(problem, spec, h: float, t_end: float, q0=None, v0=None) -> bool:
    traj = integrate(problem, spec, h=h, t_end=t_end, n_frames=11, q0=q0, v0=v0)
    return traj.ok


def measure_limit(problem, spec, h_pred: float, t_end: float, *, start: float = 0.7, growth: float = 1.15,
                  rel_tol: float = 0.005, max_factor: float = 8.0, q0=None, v0=None) -> tuple[float, list]:
    """Largest fixed step (nondimensional) for which ``spec`` finishes the scene; with trials."""
    trials = []

    def ok(h):
        good = _finishes(problem, spec, h, t_end, q0, v0)
        trials.append((h, good))
        return good

    h = start * h_pred
    while not ok(h):  # even the starting step fails: walk down
        h /= 2.0
        if h < 1e-6 * h_pred:
            return 0.0, trials
    lo = h
    hi = lo * growth
    while ok(hi):
        lo, hi = hi, hi * growth
        if hi > max_factor * h_pred:
            return math.inf, trials
    while hi - lo > rel_tol * lo:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if ok(mid) else (lo, mid)
    return lo, trials


def scan(problem, methods: list[str] | None = None, *, t_end: float | None = None, peak: bool = True,
         implicit_max: float = 20.0, q0=None, v0=None, log=None) -> list[LimitRow]:
    """Predicted vs measured limits for ``methods`` (default: every registered method)."""
    from flexmm.stability import trajectory_omega_max

    say = log or (lambda msg: None)
    ts = problem.system.scales.time_s
    t_end = problem.duration if t_end is None else t_end
    w_rest = problem.omega_max
    w_peak = trajectory_omega_max(problem)[0] if peak else w_rest
    say(f"ω_max at rest {w_rest / ts:.6g} rad/s, along a pilot run up to {w_peak / ts:.6g} rad/s")
    rows = []
    for name in methods or list(INTEGRATORS):
        spec = INTEGRATORS[name]
        lim = spec.stability_limit
        if not math.isfinite(lim):
            ladder = [f * 2.0 / w_rest for f in (1, 2, 5, 10, implicit_max)]
            trials = [(h, _finishes(problem, spec, h, t_end, q0, v0)) for h in ladder]
            good = [h for h, g in trials if g]
            measured = math.inf if all(g for _, g in trials) else (max(good) if good else 0.0)
            note = (f"A-stable: finished at every step up to {implicit_max:g} x the Verlet limit"
                    if math.isinf(measured) else "failed at a step below the ladder's top (Newton, even in substeps)")
            rows.append(LimitRow(name, "implicit", lim, math.inf, math.inf, measured * ts, math.inf,
                                 [(h * ts, g) for h, g in trials], note))
            say(f"{name}: {note}")
            continue
        h_pred, h_peak = lim / w_rest, lim / w_peak
        measured, trials = measure_limit(problem, spec, h_pred, t_end, q0=q0, v0=v0)
        kind = "adaptive (fixed-step scan)" if spec.adaptive else "explicit"
        note = ""
        if spec.adaptive:
            note = "error control keeps adaptive runs stable; the scan uses fixed steps"
        rows.append(LimitRow(name, kind, lim, h_pred * ts, h_peak * ts, measured * ts,
                             measured / h_pred, [(h * ts, g) for h, g in trials], note))
        say(f"{name}: predicted {h_pred * ts:.5g} s (peak state {h_peak * ts:.5g} s), "
            f"measured {measured * ts:.5g} s, ratio {measured / h_pred:.3f}")
    return rows


def table(rows: list[LimitRow]) -> str:
    """Plain-text table of the scan."""
    head = f"{'method':18s} {'h·ω_max':>8s} {'predicted dt':>13s} {'at peak':>12s} {'measured dt':>12s} {'ratio':>7s}"
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(f"{r.method:18s} {r.stability_limit:8.4g} {r.predicted_dt_s:13.5g} "
                     f"{r.predicted_peak_dt_s:12.5g} {r.measured_dt_s:12.5g} {r.ratio:7.3f}"
                     + (f"  ({r.note})" if r.note else ""))
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
            ok = [dt for dt, good in r.trials if good]
            text = f"A-stable:\nfinished up to\ndt = {max(ok):.3g} s" if ok else "A-stable:\nNewton failed"
            ax.annotate(text, (k, 1.0), ha="center", va="center", fontsize=7)
            continue
        for dt, good in r.trials:
            ax.plot(k, dt / r.predicted_dt_s, "o" if good else "x", color="tab:green" if good else "tab:red",
                    ms=4, alpha=0.6)
        ax.plot(k, r.ratio, "D", color="k", ms=6)
    ax.set_xticks(range(len(rows)), [r.method for r in rows], rotation=20, fontsize=8)
    ax.set_ylabel("dt / predicted limit")
    ax.set_title(title or "measured stability limits (◆ largest stable dt; o finished, x blew up)", fontsize=9)
    ax.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def linear_chain_state(problem, amplitude: float = 1e-7, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A tiny random state (all modes present, dynamics linear) for the acceptance test."""
    rng = np.random.default_rng(seed)
    free = problem.system.inv_mass > 0
    q = np.where(free, amplitude * rng.standard_normal(problem.system.ndof), 0.0)
    v = np.where(free, amplitude * rng.standard_normal(problem.system.ndof), 0.0)
    return q, v
