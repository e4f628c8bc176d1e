"""Turn a validated Scene into everything the solver needs: system, drives, damping, dt.

Config objects stop here; what comes out is arrays (nondimensional) and compiled kernels.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from flexmm.config.scene import RandomRotation, RotationSeed, Scene
from flexmm.integrators import INTEGRATORS
from flexmm.integrators.common import MODE_DISPLACEMENT, MODE_FORCE, SHAPES, empty_terms
from flexmm.models import MODELS, System
from flexmm.stability import omega_max


@dataclass
class Problem:
    """A built scene: system + external terms + damping + time grid (all nondimensional)."""

    scene: Scene
    system: System
    terms: dict[str, np.ndarray]
    damp: np.ndarray
    dt: float
    duration: float
    omega_max: float
    stable_dt: float
    notes: list[str] = field(default_factory=list)

    def terms_tuple(self) -> tuple:
        t = self.terms
        return (t["con_ij"], t["con_prm"], t["dash_ij"], t["dash_c"],
                t["drv_dof"], t["drv_mode"], t["drv_shape"], t["drv_prm"])


class UnstableStepError(Exception):
    """dt is above the integrator's stable limit (a user error unless forced)."""


def _end_dofs(system: System, end: str, field_name: str | None = None) -> list[int]:
    fname = field_name or system.meta["longitudinal_field"]
    return [system.dof(fname, s) for s in system.meta["ends"][end]]


def _add_striker(system: System, exc, dof: int, direction: float) -> tuple[np.ndarray, np.ndarray]:
    """Append a striker DOF touching the end unit; return its contact arrays."""
    sc = system.scales
    st = exc.striker
    idx = system.ndof
    m_nd = st.mass_kg / sc.mass_kg
    system.mass = np.append(system.mass, m_nd)
    system.inv_mass = np.append(system.inv_mass, 1.0 / m_nd)
    system.q0 = np.append(system.q0, system.q0[dof])
    system.v0 = np.append(system.v0, direction * exc.velocity_m_s / sc.velocity)
    system.extra_dofs["striker"] = (idx, "length")
    p = st.exponent
    k_nd = st.contact_stiffness_n_per_m * sc.length_m ** (p + 1) / sc.energy
    return np.array([[idx, dof]], np.int64), np.array([[k_nd, p, direction]])


def apply_excitation(system: System, scene: Scene, terms: dict) -> None:
    """Initial conditions, striker or drive tables for the scene's excitation."""
    exc = scene.excitation
    sc = system.scales
    if exc.kind == "none":
        return
    if exc.kind == "soliton":
        launch = MODELS[scene.lattice.kind].launch_soliton
        if launch is None:
            raise ValueError(f"model {scene.lattice.kind} has no soliton launcher")
        launch(system, exc.amplitude_rad, exc.center_site, exc.direction)
        return
    direction = 1.0 if exc.end == "left" else -1.0
    dofs = _end_dofs(system, exc.end)
    if exc.kind == "impact":
        if exc.striker is not None:
            ij, prm = _add_striker(system, exc, dofs[0], direction)
            terms["con_ij"], terms["con_prm"] = ij, prm
        else:
            system.v0[dofs] += direction * exc.velocity_m_s / sc.velocity
        if exc.angular_velocity_rad_s:
            rot = _end_dofs(system, exc.end, system.meta["rotation_field"])
            system.v0[rot] += exc.angular_velocity_rad_s * sc.time_s
        return
    if exc.kind == "shaker":
        if exc.mode == "displacement":
            amp, mode = direction * exc.amplitude_m / sc.length_m, MODE_DISPLACEMENT
        else:
            amp, mode = direction * exc.amplitude_n / sc.force, MODE_FORCE
        omega = 2 * math.pi * exc.frequency_hz * sc.time_s
        ramp = exc.ramp_cycles / exc.frequency_hz / sc.time_s
        stop = exc.duration_s / sc.time_s if exc.duration_s else np.inf
        row, shape = [amp, omega, ramp, stop], SHAPES["harmonic"]
    else:  # boundary_displacement
        amp, mode = direction * exc.amplitude_m / sc.length_m, MODE_DISPLACEMENT
        dur = exc.duration_s / sc.time_s
        shape = SHAPES[exc.shape]
        if exc.shape == "gaussian":
            sigma = dur / (2.0 * math.sqrt(2.0 * math.log(2.0)))
            row = [amp, sigma, 2.0 * dur, 0.0]
        else:
            row = [amp, dur, 0.0, 0.0]
    k = len(dofs)
    terms["drv_dof"] = np.asarray(dofs, np.int64)
    terms["drv_mode"] = np.full(k, mode, np.int64)
    terms["drv_shape"] = np.full(k, shape, np.int64)
    terms["drv_prm"] = np.tile(np.asarray(row, float), (k, 1))
    if mode == MODE_DISPLACEMENT:
        system.inv_mass[dofs] = 0.0


def apply_imperfection(system: System, scene: Scene) -> None:
    imp = scene.imperfection
    if imp is None:
        return
    rot = system.meta["rotation_field"]
    if isinstance(imp, RotationSeed):
        for s in imp.sites:
            system.q0[system.dof(rot, s)] += imp.theta_rad
    elif isinstance(imp, RandomRotation):
        rng = np.random.default_rng(imp.seed)
        k = system.field_index(rot) * system.n_sites
        system.q0[k : k + system.n_sites] += rng.normal(0.0, imp.std_rad, system.n_sites)


def damping_arrays(system: System, scene: Scene, terms: dict) -> np.ndarray:
    """Per-DOF viscous coefficients (nondimensional) and neighbour dashpots."""
    sc = system.scales
    damp = np.zeros(system.ndof)
    vis = scene.damping.viscous
    if vis is not None:
        if vis.damping_ratio is not None:
            damp = 2.0 * vis.damping_ratio * system.meta["omega_ref"] * system.mass
        else:
            rate = vis.coefficient_n_s_per_m / sc.mass_kg * sc.time_s
            for k, f in enumerate(system.fields):
                sl = slice(k * system.n_sites, (k + 1) * system.n_sites)
                if f.kind == "length":
                    damp[sl] = vis.coefficient_n_s_per_m * sc.time_s / sc.mass_kg
                elif vis.rotational_coefficient_n_m_s is not None:
                    damp[sl] = vis.rotational_coefficient_n_m_s * sc.time_s / sc.inertia
                else:
                    damp[sl] = rate * system.mass[sl]
    if scene.damping.dashpot_n_s_per_m > 0:
        k = system.field_index(system.meta["longitudinal_field"]) * system.n_sites
        idx = np.arange(system.n_sites - 1, dtype=np.int64) + k
        terms["dash_ij"] = np.stack([idx, idx + 1], axis=1)
        terms["dash_c"] = np.full(idx.size, scene.damping.dashpot_n_s_per_m * sc.time_s / sc.mass_kg)
    return damp


def build_problem(scene: Scene) -> Problem:
    """Build the system of a scene and resolve its time step against the stable limit."""
    system = MODELS[scene.lattice.kind].build(scene.lattice)
    terms = empty_terms()
    apply_imperfection(system, scene)
    apply_excitation(system, scene, terms)
    damp = damping_arrays(system, scene, terms)
    spec = INTEGRATORS[scene.solver.integrator]
    w_max = omega_max(system, terms)
    stable = spec.stability_limit / w_max if w_max > 0 else math.inf
    sc = system.scales
    notes = []
    if scene.solver.dt_s is None:
        dt = scene.solver.dt_fraction * stable
        notes.append(f"dt chosen as {scene.solver.dt_fraction} x stable limit = {dt * sc.time_s:.4g} s")
    else:
        dt = scene.solver.dt_s / sc.time_s
        if dt > stable:
            msg = (
                f"solver.dt_s = {scene.solver.dt_s:.4g} s exceeds the stable limit of {spec.name} "
                f"({spec.stability_limit:g}/ω_max = {stable * sc.time_s:.4g} s, "
                f"ω_max = {w_max / sc.time_s:.4g} rad/s)"
            )
            if not scene.solver.allow_unstable:
                raise UnstableStepError(msg + "; lower dt or set solver.allow_unstable: true")
            notes.append("WARNING: " + msg)
    duration = scene.solver.duration_s / sc.time_s
    return Problem(scene, system, terms, damp, dt, duration, w_max, stable, notes)
