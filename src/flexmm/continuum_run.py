"""Runs that answer from the continuum theory instead of (or after) a discrete simulation.

``run_continuum`` writes a dataset sampling the continuum wave a plan predicted (fidelity
``continuum``), with the same layout as ``controller.run_problem``'s. When the plan has no
amplitude (an impact), ``formation_pilot`` first runs the discrete scene only until its pulse
has formed, reads the amplitude and places the continuum soliton there.
"""

from __future__ import annotations

import errno
import time
from pathlib import Path
from typing import Callable

import numpy as np

from flexmm.assemble import build_problem
from flexmm.controller import RunResult
from flexmm.integrators.stepper import make_stepper
from flexmm.io.run_dataset import DatasetWriter, add_state
from flexmm.io.provenance import provenance_attrs
from flexmm.models import MODELS
from flexmm.plan.continuum import (
    PILOT_CHUNKS,
    ContinuumPrediction,
    NoContinuum,
    plateau,
    rotating_soliton,
)


def formation_pilot(scene, log=None):
    """Discrete run until the θ pulse has formed; (prediction at its amplitude, pilot record).

    Advances the scene in short chunks keeping each site's largest |θ| so far. The pulse is the
    largest |θ| feature; sites it has passed (behind its current peak) carry its peak amplitude.
    Once the last ``PLATEAU_SITES`` passed sites agree (median of their halves within
    ``PLATEAU_SPREAD``), the amplitude is their median and the continuum soliton of that
    amplitude, placed at the pulse's current position, replaces the rest of the run.
    """
    problem = build_problem(scene)
    st = make_stepper(problem, check_energy=False).bounded_calls()
    s = st.system
    n, k = s.n_sites, s.field_index("theta") * s.n_sites
    steps = max(1, int(problem.duration / problem.dt / PILOT_CHUNKS))
    hi, lo = st.q[k : k + n].copy(), st.q[k : k + n].copy()
    exc = scene.excitation
    direction = -1 if getattr(exc, "end", "left") == "right" else 1
    found: dict = {}

    def watch(st) -> bool:
        th = st.q[k : k + n]
        np.maximum(hi, th, out=hi)
        np.minimum(lo, th, out=lo)
        pos = int(np.argmax(np.abs(th)))
        top = np.abs(hi if th[pos] > 0 else lo)  # peaks of the current pulse's polarity
        passed = top[: max(pos - 3, 0)] if direction == 1 else top[min(pos + 4, n) :][::-1]
        weak = np.flatnonzero(passed < 0.6 * abs(th[pos]))
        amp = plateau(passed[weak[-1] + 1 :] if weak.size else passed)
        found.update(amp=amp, pos=pos, sign=float(np.sign(th[pos])))
        return amp is not None or st.t >= 0.5 * problem.duration

    st.run(iter(lambda: steps, None), watch, reraise=True)  # a signal stops the pilot, never ends it early
    t, n_steps, amp, pos = st.t, st.steps, found.get("amp"), found.get("pos", 0)
    wall = st.wall_s
    if amp is None:
        raise NoContinuum(f"no θ pulse formed within half the duration ({t * s.scales.time_s:.3g} s)")
    amp *= found["sign"]
    ts = s.scales.time_s
    pred = rotating_soliton(scene.lattice, amp)
    centre = pos - direction * pred.speed_m_s * t * ts / pred.spacing_m
    pred = rotating_soliton(scene.lattice, amp, centre, direction)
    pred.notes.append(f"amplitude {amp:.4g} rad from a formation pilot of {t * ts:.3g} s "
                      f"({n_steps} steps, {wall:.3g} s)")
    return pred, {"n_steps": n_steps, "wall_s": wall, "duration_s": t * ts}


def run_continuum(scene, pred: ContinuumPrediction, run_dir, *, extra_attrs: dict | None = None,
                  log: Callable[[str], None] | None = None):
    """Write ``run_dir/dataset.nc`` sampling the continuum wave at the output frames (no discrete run).

    Same layout as a discrete run (time, site, rest positions, the predicted fields), energies
    omitted; returns a controller ``RunResult`` with zero steps.
    """
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
    coords = {k: (np.asarray(v)[sites], "m", f"{k} position in the reference configuration")
              for k, v in system.site_coords.items() if k in ("x", "y")}
    add_state(system, sites, site_vars, coords, initial=probe)
    writer = DatasetWriter(Path(run_dir) / "dataset.nc", sites.size, site_vars, {}, coords, times.size)
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
    writer.flush()  # a full disk here is an error (nothing kept), never a 'finished' file short of frames
    path = writer.close(attrs)
    if path is None:  # HDF5 could not complete the file: nothing is kept
        raise OSError(errno.EIO, f"{writer.closed_why}; nothing was kept", str(run_dir))
    n_steps = pilot["n_steps"] if pilot else 0
    return RunResult("finished", "", path, n_steps, times.size, duration, 0.0, 0.0, setup, wall, lines,
                     n_units=system.n_sites)
