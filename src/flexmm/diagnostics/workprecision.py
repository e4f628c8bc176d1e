"""Work–precision: error against cost for every integrator, and for scipy's solve_ivp.

Each method runs over a ladder of fixed steps (fractions of its stable step; for A-stable
methods multiples of 2/ω_max) or tolerances (adaptive), from the scene's initial state to its
end, with ``n_frames`` frames. Errors are against a tight reference (dopri5 at ``ref_rtol``):

- ``quantity_error``: the relative error of what the run reports — the wave amplitudes and
  arrival-time speeds of ``flexmm.accuracy.quantity_error`` over the frames, the quantities the
  run's printed error estimate covers. The chart, the speed-ups and the ladders' stop use it: it
  stays meaningful when the late wave field is chaotic and the final state is not;
- ``final_error``: max |q − q_ref| over the lattice DOFs at the end (lengths in units of the
  model's length scale, angles in rad — "displacement units");
- ``frame_error``: the same, max over all frames;
- ``speed_error``, ``amplitude_error``: relative errors of the leading pulse's speed and
  amplitude (``analysis.leading_pulse`` on the rotation field, or the longitudinal one).

Cost: the minimum wall time of ``repeats`` runs after a compile warm-up (integration only), and
model-force evaluations. ``speedups`` compares the cheapest flexmm run with the cheapest
solve_ivp run that reach the same error.

Reading the charts: the final-state error is a max over every DOF, and a wave scene carries
small-amplitude dispersive radiation besides its pulse (on the LEGO soliton bench, shed by the
launched continuum profile: ~3e-4 in the top of the spectrum by the end). A method's phase error
on a wave of frequency ω grows like ω T (hω)^p; once it exceeds ~1 rad for the radiation, the
error saturates near the radiation's amplitude whatever h, and only below that step does the
error fall at the method's order. For second-order methods over T ≈ 2000 that takes
hω_max ≲ 0.1 (velocity Verlet: ω_max T (hω_max)²/24 = 1 rad at hω_max = 0.08), hence the long
ladders; high-order methods get there at large steps.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import asdict, dataclass

import numpy as np

from flexmm.diagnostics import baseline
from flexmm.errors import FlexmmError
from flexmm.integrators import INTEGRATORS
from flexmm.integrators.runner import integrate

#: down to small enough steps that second-order methods leave the saturated regime (docstring)
FIXED_FRACTIONS = (0.9, 0.63, 0.4, 0.25, 0.16, 0.1, 0.063, 0.04, 0.025, 0.016, 0.01)
IMPLICIT_MULTIPLES = (4.0, 2.0, 1.0, 0.5, 0.25, 0.12, 0.06, 0.03, 0.015)
RTOLS = (1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10)
ATOL_RATIO = 1e-2  # atol = ATOL_RATIO × rtol (nondimensional states are O(0.01–1))
FLOOR = 1e-10  # a ladder stops below this: the reference (rtol 1e-12) is good to ~2e-11 (LEGO soliton)


@dataclass
class Row:
    """One run of the benchmark."""

    method: str
    family: str  # 'flexmm' or 'solve_ivp'
    parameter: str  # 'dt' (nondimensional step), 'dt_fraction', 'rtol'
    value: float
    status: str
    final_error: float
    quantity_error: float
    frame_error: float
    speed_error: float
    amplitude_error: float
    wall_s: float  # min over repeats
    cpu_s: float  # process CPU time of the same run (less sensitive to a busy machine)
    force_evaluations: int
    steps: int

    def as_dict(self) -> dict:
        return asdict(self)


#: long_name of each Row column in workprecision.nc
ROW_LONG_NAMES = {
    "method": "integrator or solve_ivp method", "family": "flexmm or solve_ivp",
    "parameter": "name of the accuracy parameter varied", "value": "value of the accuracy parameter",
    "status": "run status", "final_error": "relative error of the final state against the reference",
    "quantity_error": "relative error of the reported wave amplitudes and speeds against the reference",
    "frame_error": "largest relative error over the frames", "speed_error": "relative error of the pulse speed",
    "amplitude_error": "relative error of the pulse amplitude", "wall_s": "wall time, minimum over repeats",
    "cpu_s": "process CPU time", "force_evaluations": "force evaluations", "steps": "time steps",
}


def lattice_dofs(system) -> np.ndarray:
    """Indices of the lattice DOFs (every field of every site; extra DOFs such as a striker excluded)."""
    return np.arange(len(system.fields) * system.n_sites)


def pulse_field(system) -> str:
    return system.rotation_field or system.longitudinal_field


def pulse(problem, t: np.ndarray, q: np.ndarray) -> tuple[float, float]:
    """(speed m/s, amplitude) of the leading pulse in frames q (F, ndof); nan if none is found."""
    import xarray as xr

    from flexmm.analysis import PulseNotFound, leading_pulse

    s = problem.system
    name = pulse_field(s)
    k = s.field_index(name) * s.n_sites
    sites = np.arange(s.n_sites)
    if s.grid_shape is not None:  # a sheet or grid: the middle row
        nr, nc = s.grid_shape
        sites = (nr // 2) * nc + np.arange(nc)
    x = s.site_coords["x"][sites]
    ds = xr.Dataset({name: (("time", "site"), q[:, k + sites])},
                    coords={"time": t * s.scales.time_s, "x": ("site", x)})
    try:
        p = leading_pulse(ds, name)
    except (PulseNotFound, ValueError, np.linalg.LinAlgError):
        return math.nan, math.nan
    return p.speed_m_s, p.amplitude


@dataclass
class Reference:
    t: np.ndarray
    q: np.ndarray
    speed: float
    amplitude: float
    rtol: float
    wall_s: float
    quantities: object = None  # accuracy.Trace of its frames


def quantities(problem, t: np.ndarray, q: np.ndarray):
    """The ``accuracy.Trace`` of frames q at times t (nondimensional)."""
    from flexmm.accuracy import frames_trace

    dt = float(t[1] - t[0]) if t.size > 1 else 1.0
    return frames_trace(problem.system, q, dt)


def quantity_error(problem, ref: Reference, t: np.ndarray, q: np.ndarray) -> float:
    """Relative error of the reported amplitudes and speeds of frames q against the reference's."""
    from flexmm.accuracy import quantity_error as error

    return error(quantities(problem, t, q), ref.quantities).total


def reference(problem, n_frames: int, rtol: float = 1e-12) -> Reference:
    """dopri5 at ``rtol`` (atol = ATOL_RATIO × rtol): the accuracy reference."""
    tr = integrate(problem, "dopri5", rtol=rtol, atol=ATOL_RATIO * rtol, n_frames=n_frames)
    if not tr.ok:
        raise RuntimeError("the reference run (dopri5) failed")
    speed, amp = pulse(problem, tr.t, tr.q)
    return Reference(tr.t, tr.q, speed, amp, rtol, tr.wall_s, quantities(problem, tr.t, tr.q))


FAILED = (math.inf, math.inf, math.inf, math.nan, math.nan)


def _errors(problem, ref: Reference, t, q) -> tuple[float, float, float, float, float]:
    """(final, quantity, frame, speed, amplitude) errors of frames q against the reference."""
    dofs = lattice_dofs(problem.system)
    if q.shape[0] != ref.q.shape[0] or not np.all(np.isfinite(q)):
        return FAILED
    diff = np.abs(q[:, dofs] - ref.q[:, dofs])
    speed, amp = pulse(problem, t, q)
    rel = lambda a, b: abs(a / b - 1.0) if math.isfinite(a) and math.isfinite(b) and b != 0 else math.nan
    return (float(diff[-1].max()), quantity_error(problem, ref, t, q), float(diff.max()), rel(speed, ref.speed),
            rel(amp, ref.amplitude))


def ladder(name: str, problem) -> list[tuple[str, float, dict]]:
    """(parameter name, value, integrate() keywords) for one method."""
    spec = INTEGRATORS[name]
    if spec.adaptive:
        return [("rtol", r, {"rtol": r, "atol": ATOL_RATIO * r}) for r in RTOLS]
    if not math.isfinite(spec.stability_limit):
        return [("dt_x_2/omega", m, {"h": m * 2.0 / problem.omega_max}) for m in IMPLICIT_MULTIPLES]
    h_stable = spec.stability_limit / problem.omega_max
    return [("dt_fraction", f, {"h": f * h_stable}) for f in FIXED_FRACTIONS]


def run_flexmm(problem, ref: Reference, name: str, *, repeats: int = 3, threads: int = 1,
               budget_s: float = 30.0, log=None) -> list[Row]:
    """Every rung of ``name``'s ladder (stops below FLOOR or past ``budget_s`` per run)."""
    rows = []
    n_frames = ref.t.size
    for pname, value, kw in ladder(name, problem):
        walls, cpus, tr = [], [], None
        for _ in range(repeats):
            tr = integrate(problem, name, n_frames=n_frames, threads=threads, **kw)
            walls.append(tr.wall_s)
            cpus.append(tr.cpu_s)
            if not tr.ok or tr.wall_s > budget_s:
                break
        fe, qe, fr, se, ae = _errors(problem, ref, tr.t, tr.q) if tr.ok else FAILED
        c = tr.counters
        rows.append(Row(name, "flexmm", pname, value, tr.status, fe, qe, fr, se, ae, min(walls), min(cpus),
                        c.get("force_evaluations", 0), c.get("steps", 0)))
        if log:
            log(f"{name:18s} {pname}={value:<8.3g} error {qe:9.3g} (final state {fe:9.3g})  wall {min(walls):9.4g} s  "
                f"{c.get('force_evaluations', 0)} force evaluations")
        if tr.ok and qe < FLOOR or min(walls) > budget_s:
            break
    return rows


def run_ivp(problem, ref: Reference, method: str, *, repeats: int = 1, budget_s: float = 60.0,
            rtols=RTOLS, log=None) -> list[Row]:
    rows = []
    for r in rtols:
        walls, cpus, run = [], [], None
        for _ in range(repeats):
            run = baseline.run(problem, method, r, ATOL_RATIO * r, ref.t)
            walls.append(run.wall_s)
            cpus.append(run.cpu_s)
            if run.wall_s > 1.0:
                break
        fe, qe, fr, se, ae = _errors(problem, ref, run.t, run.q)
        rows.append(Row(method, "solve_ivp", "rtol", r, run.status, fe, qe, fr, se, ae, min(walls), min(cpus),
                        run.force_evaluations, 0))
        if log:
            log(f"{method:18s} rtol={r:<8.3g} error {qe:9.3g} (final state {fe:9.3g})  wall {min(walls):9.4g} s  "
                f"{run.force_evaluations} force evaluations")
        if min(walls) > budget_s or qe < FLOOR:
            break
    return rows


def cheapest(rows: list[Row], error: float, key: str = "wall_s") -> float:
    """Cost of the cheapest run with quantity_error ≤ ``error`` (inf if none)."""
    costs = [getattr(r, key) for r in rows if r.quantity_error <= error]
    return min(costs) if costs else math.inf


def speedups(rows: list[Row], errors=(1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8), key: str = "wall_s") -> list[dict]:
    """Best solve_ivp cost over best flexmm cost (``key``: wall_s or cpu_s) at equal error of the
    reported quantities."""
    ours = [r for r in rows if r.family == "flexmm" and r.status == "finished"]
    theirs = [r for r in rows if r.family == "solve_ivp" and r.status == "finished"]
    out = []
    for e in errors:
        a, b = cheapest(ours, e, key), cheapest(theirs, e, key)
        if math.isfinite(a) and math.isfinite(b):
            best_ours = min((r for r in ours if r.quantity_error <= e), key=lambda r: getattr(r, key))
            best_theirs = min((r for r in theirs if r.quantity_error <= e), key=lambda r: getattr(r, key))
            out.append({"error": e, "key": key, "flexmm_s": a, "flexmm_method": best_ours.method,
                        "solve_ivp_s": b, "solve_ivp_method": best_theirs.method, "speedup": b / a})
    return out


def to_dataset(rows: list[Row], attrs: dict):
    """xarray Dataset with one entry per run (dimension ``run``)."""
    import xarray as xr

    cols = {k: [getattr(r, k) for r in rows] for k in Row.__dataclass_fields__}
    units = {"wall_s": "s", "cpu_s": "s"}
    data = {k: ("run", np.asarray(v), {"units": units.get(k, "1"), "long_name": ROW_LONG_NAMES[k]})
            for k, v in cols.items()}
    return xr.Dataset(data, attrs={**attrs, "load_average": str(os.getloadavg()),
                                   "created": time.strftime("%Y-%m-%dT%H:%M:%S")})


def chart(rows: list[Row], path, title: str = "") -> None:
    """Two log–log panels: the error of the reported quantities against wall time and against force
    evaluations."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(9.0, 3.8), dpi=100, sharey=True)
    methods = list(dict.fromkeys(r.method for r in rows))
    for m in methods:
        sel = [r for r in rows if r.method == m and r.status == "finished" and math.isfinite(r.quantity_error)]
        if not sel:
            continue
        ivp = sel[0].family == "solve_ivp"
        style = dict(ls="--" if ivp else "-", marker="s" if ivp else "o", ms=3.5, lw=1.2,
                     label=f"solve_ivp {m}" if ivp else m)
        err = [max(r.quantity_error, 1e-16) for r in sel]
        axes[0].loglog([r.wall_s for r in sel], err, **style)
        axes[1].loglog([max(r.force_evaluations, 1) for r in sel], err, **style)
    axes[0].set_xlabel("wall time (s, min of repeats, compile excluded)")
    axes[1].set_xlabel("model-force evaluations")
    axes[0].set_ylabel("relative error of the wave amplitudes and speeds")
    for ax in axes:
        ax.grid(True, which="major", lw=0.4, alpha=0.5)
    axes[1].legend(fontsize=7, loc="upper right")
    fig.suptitle(title or "work-precision", fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


#: a second reference at CHECK_RTOL_FACTOR × the reference's rtol whose reported quantities (the
#: wave amplitudes and speeds, ``quantity_error``) differ from the reference's by more than
#: CHAOS_RATIO: even what the run reports is chaotic, and no step or tolerance of any method reaches
#: a chart worth drawing (a chaotic late field alone does not stop the chart: its final state is
#: not what the chart measures)
CHECK_RTOL_FACTOR = 1e3
CHAOS_RATIO = 1e-4


class ChaoticReference(FlexmmError):
    """The reference cannot be trusted: a looser reference reports other amplitudes and speeds (chaotic dynamics)."""


def reference_spread(problem, ref: Reference, n_frames: int) -> tuple[float, float, float]:
    """(error of the reported quantities of a reference at CHECK_RTOL_FACTOR × its rtol against the
    reference, the relative difference of its final state (of the field's largest |q|), the check's
    wall time)."""
    check = reference(problem, n_frames, ref.rtol * CHECK_RTOL_FACTOR)
    dofs = lattice_dofs(problem.system)
    scale = float(np.max(np.abs(ref.q[:, dofs])))
    final = float(np.max(np.abs(check.q[-1, dofs] - ref.q[-1, dofs]))) / scale if scale else math.inf
    return quantity_error(problem, ref, check.t, check.q), final, check.wall_s


def benchmark(problem, methods=None, ivp_methods=baseline.METHODS, *, n_frames: int = 101,
              repeats: int = 3, ref_rtol: float = 1e-12, budget_s: float = 30.0, threads: int = 1,
              log=None, force: bool = False) -> tuple[list[Row], Reference]:
    """Run the whole comparison; returns the rows and the reference. ChaoticReference (unless
    ``force``: a warning) when a reference at 1000× the tolerance reports amplitudes and speeds more
    than CHAOS_RATIO away from its: every method's error would measure the chaos, not the method."""
    say = log or (lambda m: None)
    ref = reference(problem, n_frames, ref_rtol)
    say(f"reference: dopri5 rtol {ref_rtol:g} in {ref.wall_s:.3g} s, {n_frames} frames; pulse speed "
        f"{ref.speed:.6g} m/s, amplitude {ref.amplitude:.6g}; load average {os.getloadavg()[0]:.2f}")
    spread, final, wall = reference_spread(problem, ref, n_frames)
    msg = (f"a reference at rtol {ref_rtol * CHECK_RTOL_FACTOR:g} reports wave amplitudes and speeds {spread:.2g} "
           f"from the one at {ref_rtol:g} (its final state {final:.2g} of the field's largest value; checked in "
           f"{wall:.3g} s)")
    if not spread <= CHAOS_RATIO:
        text = (f"{msg}: even the reported quantities are chaotic, so every method's error would measure the "
                f"chaos, not the method; bench a shorter run (solver.duration_s=...)")
        if not force:
            raise ChaoticReference(text + " or pass --force")
        say(f"warning: {text}")
    else:
        say(f"reference check: {msg}")
    rows: list[Row] = []
    for name in methods or list(INTEGRATORS):
        rows += run_flexmm(problem, ref, name, repeats=repeats, threads=threads, budget_s=budget_s, log=say)
    for m in ivp_methods:
        rows += run_ivp(problem, ref, m, budget_s=4 * budget_s, log=say)
    return rows, ref
