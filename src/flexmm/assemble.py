"""Turn a validated Scene into everything the solver needs: system, drives, damping, dt.

Config objects stop here; what comes out is arrays (nondimensional) and compiled kernels.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from flexmm.config.base import resolve
from flexmm.config.excitation import EXCITATIONS
from flexmm.config.scene import RandomRotation, RotationSeed, Scene
from flexmm.errors import FlexmmError
from flexmm.integrators import INTEGRATORS
from flexmm.io.pause import pause_point
from flexmm.integrators.common import MODE_DISPLACEMENT, MODE_FORCE, MODE_FRICTION, SHAPES, Terms, empty_terms
from flexmm.models import MODELS, System
from flexmm.models.predeform import INWARD
from flexmm.stability import omega_max, reached_state, resolve_dt


@dataclass
class Problem:
    """A built scene: system + external terms + damping + time grid (all nondimensional)."""

    scene: Scene
    system: System
    terms: Terms
    damp: np.ndarray
    dt: float
    duration: float
    omega_max: float
    stable_dt: float
    notes: list[str] = field(default_factory=list)



class SceneError(FlexmmError, ValueError):
    """A scene that validates but cannot be built (a user error; the CLI exits with status 2)."""


def _end_dofs(system: System, end: str, field_name: str | None = None,
              sites: list[int] | None = None) -> list[int]:
    """DOFs of ``field_name`` (default: the end's normal field) at an end's units (or ``sites``)."""
    fname = field_name or system.end_field(end)
    return [system.dof(fname, s) for s in (system.ends[end] if sites is None else sites)]


def _targets(system: System, exc) -> list[int] | None:
    """The units an excitation (or kick) lists: its ``sites``, or the named unit set ``units``
    (``System.site_groups``); None: its end's units."""
    name = getattr(exc, "units", None)
    if name is None:
        return exc.sites
    if name not in system.site_groups:
        raise SceneError(f"excitation units {name!r}: model {system.model!r} has no such unit set "
                         f"({', '.join(system.site_groups) or 'none'})")
    return system.site_groups[name]


def _launch_solitons(system: System, scene: Scene, pulses) -> None:
    """Superpose launched solitons (each launcher overwrites q0, v0; their states are added).

    On a predeformed lattice the launchers write displacements from the rest state, added to it.
    """
    entry = MODELS[scene.lattice.kind]
    launch = entry.launch_soliton
    if launch is None:
        raise SceneError(f"model {scene.lattice.kind} has no soliton launcher")
    rest = system.rest_state
    if rest is not None and not entry.soliton_on_predeformed:
        raise SceneError(f"model {scene.lattice.kind} launches solitons on an undeformed lattice only; "
                         "remove lattice.predeform or use another excitation")
    q = np.zeros_like(system.q0) if rest is None else rest.copy()
    v = np.zeros_like(system.v0)
    for p in pulses:
        system.q0[:], system.v0[:] = 0.0, 0.0
        try:
            launch(system, scene.lattice, p.amplitude_rad, p.center_site, p.direction)
        except ValueError as err:  # e.g. no soliton of that amplitude for these parameters
            raise SceneError(f"excitation.amplitude_rad = {p.amplitude_rad}: {err}") from None
        q += system.q0
        v += system.v0
    system.q0[:], system.v0[:] = q, v


def apply_kicks(system: System, scene: Scene, exc, terms: dict) -> None:
    """Add initial velocities (x, y, rotation) to the kicked units."""
    sc, axes = system.scales, system.axis_fields
    for kick in exc.kicks:
        sites = _targets(system, kick)
        sites = system.ends[kick.end] if sites is None else sites
        for axis, value in (("x", kick.velocity_x_m_s), ("y", kick.velocity_y_m_s)):
            if value:
                if axis not in axes:
                    raise SceneError(f"kick velocity along {axis}: model {system.model!r} has no {axis} motion")
                system.v0[[system.dof(axes[axis], s) for s in sites]] += value / sc.velocity
        if kick.angular_velocity_rad_s:
            rot = _rotation_field(system, "angular_velocity_rad_s")
            system.v0[[system.dof(rot, s) for s in sites]] += kick.angular_velocity_rad_s * sc.time_s


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
    _apply(system, scene, scene.excitation, terms)


def _apply(system: System, scene: Scene, exc, terms: dict) -> None:
    """One excitation, by its registry hook; drive rows are appended to ``terms`` (several may act
    together)."""
    resolve(EXCITATIONS[exc.kind].apply)(system, scene, exc, terms)


def apply_parts(system: System, scene: Scene, exc, terms: dict) -> None:
    """A combined excitation: each part in turn."""
    for part in exc.parts:
        _apply(system, scene, part, terms)


def apply_nothing(system: System, scene: Scene, exc, terms: dict) -> None:
    """No excitation: the system keeps its initial state."""


def apply_solitons(system: System, scene: Scene, exc, terms: dict) -> None:
    """Launched solitons (one or several)."""
    _launch_solitons(system, scene, exc.launches())


def apply_impact(system: System, scene: Scene, exc, terms: dict) -> None:
    """An initial velocity of the end units, or a striker DOF with its contact."""
    sc = system.scales
    direction = INWARD[exc.end]
    dofs = _end_dofs(system, exc.end, sites=_targets(system, exc))
    if exc.striker is not None:
        ij, prm = _add_striker(system, exc, dofs[0], direction)
        terms["con_ij"], terms["con_prm"] = ij, prm
    else:
        system.v0[dofs] += direction * exc.velocity_m_s / sc.velocity
    if exc.angular_velocity_rad_s:
        rot = _end_dofs(system, exc.end, _rotation_field(system, "angular_velocity_rad_s"), _targets(system, exc))
        system.v0[rot] += exc.angular_velocity_rad_s * sc.time_s


def apply_shaker(system: System, scene: Scene, exc, terms: dict) -> None:
    """A harmonic drive row (displacement, force or prescribed rotation) with its ramps."""
    sc = system.scales
    direction = INWARD[exc.end]
    dofs = _end_dofs(system, exc.end, sites=_targets(system, exc))
    if exc.amplitude_rad is not None:  # a prescribed harmonic rotation of the end units
        dofs = _end_dofs(system, exc.end, _rotation_field(system, "amplitude_rad"), _targets(system, exc))
        amp, mode = exc.amplitude_rad, MODE_DISPLACEMENT
    elif exc.mode == "displacement":
        amp, mode = direction * exc.amplitude_m / sc.length_m, MODE_DISPLACEMENT
    else:
        amp, mode = direction * exc.amplitude_n / sc.force, MODE_FORCE
    omega = 2 * math.pi * exc.frequency_hz * sc.time_s
    ramp = exc.ramp_cycles / exc.frequency_hz / sc.time_s
    stop = exc.duration_s / sc.time_s if exc.duration_s else np.inf
    _drive(system, exc, terms, dofs, mode, SHAPES["harmonic"], [amp, omega, ramp, stop])


def apply_boundary_displacement(system: System, scene: Scene, exc, terms: dict) -> None:
    """A prescribed displacement (or rotation) pulse of the end units."""
    sc = system.scales
    direction = INWARD[exc.end]
    dofs = _end_dofs(system, exc.end, sites=_targets(system, exc))
    if exc.amplitude_rad is not None:  # a prescribed rotation of the end units
        rot = _rotation_field(system, "amplitude_rad")
        dofs = _end_dofs(system, exc.end, rot, _targets(system, exc))
        amp = exc.amplitude_rad
    else:
        amp = direction * exc.amplitude_m / sc.length_m
    _drive(system, exc, terms, dofs, MODE_DISPLACEMENT, SHAPES[exc.shape], _pulse_row(system, exc, amp))


def _pulse_row(system: System, exc, amp: float) -> list[float]:
    """The waveform row of a pulse of ``exc.shape`` and ``exc.duration_s`` (a gaussian's FWHM,
    centred at twice it)."""
    dur = exc.duration_s / system.scales.time_s
    if exc.shape == "gaussian":
        return [amp, dur / (2.0 * math.sqrt(2.0 * math.log(2.0))), 2.0 * dur, 0.0]
    return [amp, dur, 0.0, 0.0]


def apply_boundary_force(system: System, scene: Scene, exc, terms: dict) -> None:
    """An applied force (or moment) pulse on the end units; no DOF is held."""
    sc = system.scales
    if exc.amplitude_n_m is not None:  # a moment on the staggered rotation of the end units
        dofs = _end_dofs(system, exc.end, _rotation_field(system, "amplitude_n_m"), _targets(system, exc))
        amp = exc.amplitude_n_m / sc.generalised_force("angle")
    else:
        dofs = _end_dofs(system, exc.end, sites=_targets(system, exc))
        amp = INWARD[exc.end] * exc.amplitude_n / sc.force
    _drive(system, exc, terms, dofs, MODE_FORCE, SHAPES[exc.shape], _pulse_row(system, exc, amp))


def _drive(system: System, exc, terms: dict, dofs: list[int], mode: int, shape: int, row: list) -> None:
    """Append the drive rows of ``exc`` (its direction split over the axes if tilted)."""
    for dof_list, factor in _drive_components(system, exc, dofs):
        _append_drive(system, exc, terms, dof_list, mode, shape, [row[0] * factor] + row[1:])


#: inward normal of each end in the (x, y) plane
_INWARD_XY = {"left": (1.0, 0.0), "right": (-1.0, 0.0), "bottom": (0.0, 1.0), "top": (0.0, -1.0)}


def _drive_components(system: System, exc, dofs: list[int]) -> list[tuple[list[int], float]]:
    """The drive's DOF lists and amplitude factors: the end's normal field, or (angle_deg ≠ 0) x and y.

    The amplitude was signed along the normal; a tilt rotates the inward normal counter-clockwise
    by ``angle_deg`` and drives u and v with the components of that direction.
    """
    angle = getattr(exc, "angle_deg", 0.0)
    if not angle or getattr(exc, "amplitude_rad", None) is not None:
        return [(dofs, 1.0)]
    axes = system.axis_fields
    if "y" not in axes:
        raise SceneError(f"excitation.angle_deg = {angle}: model {system.model!r} has no y motion "
                         "(a tilted drive needs a 2D lattice)")
    nx, ny = _INWARD_XY[exc.end]
    a = math.radians(angle)
    dx, dy = nx * math.cos(a) - ny * math.sin(a), nx * math.sin(a) + ny * math.cos(a)
    sites = _targets(system, exc)
    sites = system.ends[exc.end] if sites is None else sites
    sign = INWARD[exc.end]  # undo the normal's sign already in the amplitude
    return [([system.dof(axes[f], s) for s in sites], sign * comp)
            for f, comp in (("x", dx), ("y", dy)) if abs(comp) > 1e-15]


def _append_drive(system: System, exc, terms: dict, dofs: list[int], mode: int, shape: int, row: list) -> None:
    """Append one drive row per DOF; a prescribed displacement holds those DOFs (infinite mass)."""
    k = len(dofs)
    terms["drv_dof"] = np.concatenate([terms["drv_dof"], np.asarray(dofs, np.int64)])
    terms["drv_mode"] = np.concatenate([terms["drv_mode"], np.full(k, mode, np.int64)])
    terms["drv_shape"] = np.concatenate([terms["drv_shape"], np.full(k, shape, np.int64)])
    terms["drv_prm"] = np.concatenate([terms["drv_prm"], np.tile(np.asarray(row, float), (k, 1))])
    if mode == MODE_DISPLACEMENT:
        if np.any(np.abs(system.q0[dofs]) > 1e-12):
            raise SceneError(f"a prescribed displacement drives the {exc.end} end from 0, but the "
                             "initial (predeformed) state displaces it; drive it with a force instead")
        system.inv_mass[dofs] = 0.0


def _rotation_field(system: System, what: str) -> str:
    """The model's rotation field, or a clear error for models without one."""
    rot = system.rotation_field
    if rot is None:
        raise SceneError(f"{what} needs a rotation field; model {system.model!r} has none")
    return rot


def friction_rate_of(system: System) -> float:
    """The largest rate F/(m v_ε) of the model's ground friction (0 without): explicit regularised
    friction needs h F/(m v_ε) ≤ 1."""
    fr = system.friction
    if fr is None or fr.sites.size == 0:
        return 0.0
    dofs = fr.sites + system.field_index(system.longitudinal_field) * system.n_sites
    return float(np.max(np.maximum(fr.forward, fr.backward) * system.inv_mass[dofs]) / fr.velocity)


def apply_friction(system: System, terms: dict) -> None:
    """Append the model's ground friction as drive rows (mode 2)."""
    fr = system.friction
    if fr is None:
        return
    k = system.field_index(system.longitudinal_field) * system.n_sites
    dofs = fr.sites + k
    n = dofs.size
    prm = np.zeros((n, 4))
    prm[:, 0], prm[:, 1], prm[:, 2] = fr.forward, fr.velocity, fr.backward
    terms["drv_dof"] = np.concatenate([terms["drv_dof"], dofs]).astype(np.int64)
    terms["drv_mode"] = np.concatenate([terms["drv_mode"], np.full(n, MODE_FRICTION)]).astype(np.int64)
    terms["drv_shape"] = np.concatenate([terms["drv_shape"], np.zeros(n, np.int64)]).astype(np.int64)
    terms["drv_prm"] = np.concatenate([terms["drv_prm"], prm])


def apply_imperfection(system: System, scene: Scene) -> None:
    imp = scene.imperfection
    if imp is None:
        return
    rot = _rotation_field(system, f"imperfection {imp.kind!r}")
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
            damp = 2.0 * vis.damping_ratio * system.omega_ref * system.mass
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
        k = system.field_index(system.longitudinal_field) * system.n_sites
        pairs = system.neighbour_pairs
        if pairs is None:
            idx = np.arange(system.n_sites - 1, dtype=np.int64)
            pairs = np.stack([idx, idx + 1], axis=1)
        terms["dash_ij"] = np.asarray(pairs, np.int64) + k
        terms["dash_c"] = np.full(len(pairs), scene.damping.dashpot_n_s_per_m * sc.time_s / sc.mass_kg)
    if scene.damping.absorbing is not None:
        damp = damp + absorbing_damping(system, scene.damping.absorbing)
    return damp


def overdamping(scene: Scene, system: System, w_max: float) -> list[str]:
    """A warning when ``damping.viscous.damping_ratio`` damps every wave of the scene more than it
    says: the ratio is relative to the model's reference frequency ω_ref (docs/physics.md §3), and
    when ω_ref exceeds the scene's highest frequency ω_max (a sonic-vacuum Hertz chain's ω_ref is
    its contact stiffness at 100 % strain) each wave has a ratio of at least ζ ω_ref/ω_max."""
    vis = scene.damping.viscous
    w_ref = system.omega_ref
    if vis is None or not vis.damping_ratio or not w_max > 0 or w_ref <= w_max:
        return []
    zeta, ts = vis.damping_ratio, system.scales.time_s
    return [f"WARNING: damping.viscous.damping_ratio = {zeta:g} is relative to the model's reference frequency "
            f"ω_ref = {w_ref / ts:.4g} rad/s, above the highest frequency of this scene ω_max = {w_max / ts:.4g} rad/s: "
            f"every wave decays at γ = 2ζω_ref = {2 * zeta * w_ref / ts:.4g} 1/s, a damping ratio of at least "
            f"{zeta * w_ref / w_max:.3g} for each ({w_ref / w_max:.3g}x the ratio given); give "
            "damping.viscous.coefficient_n_s_per_m, or a ratio scaled by ω_max/ω_ref"]


def absorbing_damping(system: System, layer) -> np.ndarray:
    """Extra per-DOF damping coefficients (nondimensional, (ndof,)) of an absorbing layer.

    ζ(d) = max_ratio (d/n)^power on units at depth d = n − (distance to the end in sites),
    γ = 2 ζ ω_ref, c = γ m for every lattice DOF of the unit (config/absorbing.py).
    """
    ix, _ = system.site_grid()
    n_x = int(ix.max()) + 1
    if layer.n_units >= n_x:
        raise SceneError(f"damping.absorbing.n_units = {layer.n_units} must be below the {n_x} units along x")
    zeta = np.zeros(system.n_sites)
    ends = ("left", "right") if layer.end == "both" else (layer.end,)
    for end in ends:
        dist = ix if end == "left" else (n_x - 1 - ix)
        depth = np.clip(layer.n_units - dist, 0, None) / layer.n_units
        zeta = np.maximum(zeta, layer.max_ratio * depth**layer.power)
    out = np.zeros(system.ndof)
    w_ref = system.omega_ref
    for f in range(len(system.fields)):
        sl = slice(f * system.n_sites, (f + 1) * system.n_sites)
        out[sl] = 2.0 * zeta * w_ref * system.mass[sl]
    return out


def build_system(scene: Scene) -> tuple[System, Terms]:
    """The scene's system with its imperfection, excitation and friction applied (no dt analysis)."""
    pause_point("build")
    try:
        system = MODELS[scene.lattice.kind].build(scene.lattice)
    except SceneError:
        raise
    except ValueError as err:  # the lattice cannot be built as described (e.g. unbalanced loads)
        raise SceneError(f"lattice: {err}") from None
    terms = empty_terms()._asdict()
    apply_imperfection(system, scene)
    apply_excitation(system, scene, terms)
    if scene.initial is not None:
        from flexmm.initial_state import apply_initial

        apply_initial(system, scene)
    apply_friction(system, terms)
    return system, Terms(**terms)


def build_problem(scene: Scene, built: tuple[System, Terms] | None = None) -> Problem:
    """Build the system of a scene and resolve its time step against the stable limit.

    ``built``: the (system, terms) of ``scene`` with imperfection and excitation already applied
    (``build_system``; planning makes it): used instead of building again.
    """
    try:
        return _build_problem(scene, built)
    except FlexmmError:
        raise
    except (ArithmeticError, np.linalg.LinAlgError) as err:  # e.g. a_m = 1e-300 with mass_kg = 1e300
        raise SceneError(f"the scene's parameters are out of floating-point range "
                         f"({type(err).__name__}: {err})") from None
    except ValueError as err:
        if "inf" not in str(err) and "NaN" not in str(err):
            raise
        raise SceneError(f"the scene's parameters are out of floating-point range (non-finite "
                         f"stiffness or frequency: {err})") from None


def check_velocity_forces(spec, damp: np.ndarray, terms: Terms, friction_rate: float) -> None:
    """Refuse velocity-dependent forces for a method that assumes forces depend on q only."""
    if spec.velocity_dependent_forces:
        return
    found = [name for name, present in (("viscous damping", bool(np.any(damp > 0))),
                                        ("dashpots", terms.dash_c.size > 0),
                                        ("ground friction", friction_rate > 0)) if present]
    if found:
        ok = ", ".join(k for k, v in INTEGRATORS.items() if v.velocity_dependent_forces)
        raise SceneError(f"{spec.name} assumes forces that depend on positions only (a Runge-Kutta-"
                         f"Nystrom-type scheme: its order conditions fail otherwise), but this scene has "
                         f"{' and '.join(found)}, which depend on velocity; use one of: {ok}")


def _build_problem(scene: Scene, built: tuple[System, Terms] | None = None) -> Problem:
    if built is None:
        system, terms = build_system(scene)
    else:
        system, terms = built
    terms = terms._asdict()  # damping adds dashpots below
    friction_rate = friction_rate_of(system)
    damp = damping_arrays(system, scene, terms)
    terms = Terms(**terms)
    spec = INTEGRATORS[scene.solver.integrator]
    check_velocity_forces(spec, damp, terms, friction_rate)
    rest = system.rest_state  # predeformed equilibrium: linearise about it
    q_ref = None if rest is None else np.concatenate([rest, system.q0[rest.size:]])
    w_max = omega_max(system, terms, q_ref)
    q_hit = reached_state(system, terms, q_ref)  # a striker compresses the lattice: its stiffness there
    if q_hit is not None:
        w_max = max(w_max, omega_max(system, terms, q_hit))
    if not math.isfinite(w_max):
        raise SceneError(f"ω_max = {w_max} is not finite: lattice parameters out of floating-point range")
    sc = system.scales
    if scene.solver.dt_s is None and not w_max > 0 and not spec.adaptive:
        raise SceneError("cannot pick dt: no stiffness at rest (ω_max = 0, e.g. an uncompressed "
                         "Hertz chain); set solver.dt_s")
    # explicit regularised friction: keep h F/(m v_ε) <= 1
    dt, stable, notes = resolve_dt(spec, w_max, scene.solver, sc.time_s, friction_rate)
    duration = scene.solver.duration_s / sc.time_s
    return Problem(scene, system, terms, damp, dt, duration, w_max, stable, [*notes, *scene_notes(scene, system, w_max)])


def scene_notes(scene: Scene, system: System, w_max: float) -> list[str]:
    """The notes of a problem that do not depend on its step: damping that overdamps the scene's
    waves, and the run this one continues (provenance)."""
    notes = list(overdamping(scene, system, w_max))
    if scene.initial is not None and scene.initial.from_run:
        notes.append(f"initial state: the last frame of {scene.initial.from_run}")
    return notes
