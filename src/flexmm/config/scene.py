"""The scene: the top-level config a user writes (``flexmm run scene.yaml``)."""

from __future__ import annotations

from typing import Annotated, Literal, Union

from pydantic import AliasChoices, Field, model_validator

from flexmm.config.absorbing import AbsorbingLayer
from flexmm.config.base import NonNegative, Positive, Strict, exactly_one
from flexmm.config.excitation import EXCITATIONS, ExcitationConfig, NoExcitation
from flexmm.config.initial import Initial
from flexmm.config.lattice import MODELS, LatticeConfig


class Viscous(Strict):
    """Viscous damping on every DOF: a coefficient, or a damping ratio ζ.

    A ratio gives the same decay rate γ = 2ζω_ref to every DOF, with ω_ref the model's
    reference frequency (sqrt(k_l/m) for rotating squares): c_u = γm, c_θ = γJ.
    """

    coefficient_n_s_per_m: NonNegative | None = None
    rotational_coefficient_n_m_s: NonNegative | None = Field(
        None, description="on θ DOFs (N m s/rad); defaults to the rate implied by the linear one"
    )
    damping_ratio: NonNegative | None = None

    @model_validator(mode="after")
    def _one_way(self):
        exactly_one(self, "coefficient_n_s_per_m", "damping_ratio")
        if self.damping_ratio is not None and self.rotational_coefficient_n_m_s is not None:
            raise ValueError("rotational_coefficient_n_m_s goes with coefficient_n_s_per_m, not damping_ratio")
        return self


class Damping(Strict):
    """On-site viscous damping and dashpots between neighbouring units."""

    viscous: Viscous | None = None
    dashpot_n_s_per_m: NonNegative = Field(0.0, description="between neighbours' u (N s/m)")
    absorbing: AbsorbingLayer | None = Field(None, description="graded damping layer at an end")


class RotationSeed(Strict):
    """Add a small rotation to chosen sites (θ ≡ 0 is invariant under a longitudinal impact)."""

    kind: Literal["rotation_seed"]
    theta_rad: float = Field(description="added staggered rotation (rad)")
    sites: list[Annotated[int, Field(ge=0)]] = Field(default_factory=lambda: [0])


class RandomRotation(Strict):
    """Gaussian random rotations on every site, reproducible from ``seed``."""

    kind: Literal["random_rotation"]
    std_rad: Positive
    seed: int = 0


ImperfectionConfig = Annotated[Union[RotationSeed, RandomRotation], Field(discriminator="kind")]


#: the default ``solver.accuracy``: relative error of the wave speeds and amplitudes a run
#: reports (``flexmm.accuracy``), well under 0.1 %
DEFAULT_ACCURACY = 1e-4

#: the method that runs when the scene names none and has an accuracy target (the default): fourth
#: order, symplectic, damping and friction allowed, 4 force evaluations a step. With
#: ``accuracy: null`` the field's own default, velocity Verlet, runs (docs/physics.md §3).
DEFAULT_METHOD = "pefrl"

#: integrators with error control (``IntegratorSpec.adaptive``); they take rtol/atol
ADAPTIVE_INTEGRATORS = frozenset({"dopri5"})


#: the most threads a config may ask for (a config stays valid on any machine; a run clamps a
#: request above the cores it may use to those cores and says so: ``controller.run_problem``)
MAX_THREADS = 256


class Solver(Strict):
    """Time integration: method, step and duration.

    ``integrator`` names an entry of ``flexmm.integrators.INTEGRATORS`` (tests check the two
    agree). The adaptive ``dopri5`` takes ``rtol``/``atol`` and reads ``dt_s`` as its largest
    step; the fixed-step methods take ``dt_s`` (or ``dt_fraction`` of their stable limit).
    """

    integrator: Literal["velocity_verlet", "pefrl", "blanes_moan6", "rk4", "dopri5", "implicit_midpoint"] = Field(
        "velocity_verlet",
        description="unset: pefrl while solver.accuracy is set (the default; also with an explicit dt_s), "
        "velocity_verlet with accuracy: null. velocity_verlet (2nd order symplectic), pefrl (4th order symplectic), "
        "blanes_moan6 (6th order symplectic, no velocity-dependent forces), rk4, "
        "dopri5 (adaptive 5(4), error control), implicit_midpoint (A-stable, stiff scenes)",
    )
    dt_s: Positive | None = Field(
        None,
        validation_alias=AliasChoices("dt_s", "dt"),
        description="time step (s); omitted: a fraction `dt_fraction` of the stable limit",
    )
    rtol: Positive | None = Field(None, lt=1, description="relative tolerance of dopri5 (default 1e-6)")
    atol: Positive | None = Field(
        None, description="absolute tolerance of dopri5, nondimensional (default 1e-2 × rtol)"
    )
    threads: int | None = Field(
        None, ge=1, le=MAX_THREADS, description=f"threads for parallel kernels, at most {MAX_THREADS} (default: all "
        "cores for ≥ 1e5 units, else 1); more than this machine's cores runs on its cores, with a line saying so"
    )
    dt_fraction: float = Field(0.1, gt=0, le=1, description="auto dt = fraction × stable limit "
                               "(with solver.accuracy: null; otherwise the accuracy pilots choose dt)")
    duration_s: Positive
    allow_unstable: bool = Field(False, description="run even if dt exceeds the stable limit")
    accuracy: Positive | None = Field(
        DEFAULT_ACCURACY, lt=1,
        description="target relative error of the wave speeds and amplitudes the run reports: pilots pick dt "
        "(and, when the scene sets the target without an integrator, the integrator); an explicit dt_s is honoured "
        "and its error estimated. Every run stores its estimate. null: no error control (dt = dt_fraction x the "
        "stable limit, no estimate)",
    )
    error_check: Literal["pilot", "run"] = Field(
        "pilot", description="how the error estimate is made: 'pilot' (step doubling over the pilot window, a "
        "tenth of the run: ~0.3 runs of cost) or 'run' (step doubling over the whole run after it: ~3 runs of cost)",
    )

    @model_validator(mode="after")
    def _tolerances_need_adaptive(self):
        if self.integrator not in ADAPTIVE_INTEGRATORS:
            given = [k for k in ("rtol", "atol") if getattr(self, k) is not None]
            if given:
                verb = "apply" if len(given) > 1 else "applies"
                raise ValueError(
                    f"solver.{' and solver.'.join(given)} {verb} only to an adaptive integrator "
                    f"({', '.join(sorted(ADAPTIVE_INTEGRATORS))}); {self.integrator} takes fixed steps "
                    "(set solver.dt_s or solver.dt_fraction)"
                )
        return self


class Output(Strict):
    """What to save and how often (always including the first and last time)."""

    directory: str = "runs"
    fields: list[str] | None = Field(None, description="coordinates to save; default all")
    velocities: bool = True
    every_s: Positive | None = Field(None, description="output interval, dividing solver.duration_s (the last frame "
                                     "is the run's end); default from n_frames")
    n_frames: int = Field(201, ge=2, le=1_000_000, description="frames saved (at most 10⁶; every_s for more)")
    exact_frame_times: bool = Field(
        False, description="frames always land at every_s (or duration/(n_frames-1)): a step flexmm chooses is "
        "shortened to divide the interval; true: a given solver.dt_s too (reported as a plan change), false: a given "
        "dt_s that does not divide the interval is refused, naming the nearest that do")
    site_stride: int = Field(1, ge=1, description="save every k-th unit; less than lattice.n_units, so at "
                             "least two units are saved")
    energy: bool = True


class Scene(Strict):
    """A complete, validated scene."""

    name: str = Field(pattern=r"^[A-Za-z0-9][A-Za-z0-9_.\-]*$", max_length=120)
    description: str = ""
    lattice: LatticeConfig = Field(discriminator="kind")
    excitation: ExcitationConfig = Field(default_factory=lambda: NoExcitation(kind="none"))
    damping: Damping = Field(default_factory=Damping)
    imperfection: ImperfectionConfig | None = None
    initial: Initial | None = Field(None, description="initial state of any shape (config/initial.py)")
    solver: Solver
    output: Output = Field(default_factory=Output)

    def _check_initial(self, n: int) -> None:
        valid = getattr(type(self.lattice), "FIELD_NAMES", None)
        init = self.initial
        for where, items in (("fields", init.fields), ("pinned", init.pinned)):
            for k, item in enumerate(items):
                if valid is not None and item.field not in valid:
                    raise ValueError(f"initial.{where}.{k}.field {item.field!r}: this lattice's fields are "
                                     f"{', '.join(valid)}")
        for k, pin in enumerate(init.pinned):
            bad = [s for s in pin.sites if s >= n]
            if bad:
                raise ValueError(f"initial.pinned.{k}.sites {bad} outside 0..{n - 1}")
        needs = {"toda_soliton": "toda", "toda_two_soliton": "toda", "sech2_pulse": "polynomial",
                 "fpu_beta_pulse": "polynomial", "hertz_kdv_pulse": "hertz", "kink": "linear", "tanh_front": "linear"}
        for k, spec in enumerate(init.launch):
            centers = spec.center_site if isinstance(spec.center_site, tuple) else (spec.center_site,)
            if not all(0 <= c <= n - 1 for c in centers):
                raise ValueError(f"initial.launch.{k}.center_site={spec.center_site} is outside 0..{n - 1}")
            law = getattr(getattr(self.lattice, "bond", None), "law", None)
            if not MODELS[self.lattice.kind].chain_waves or law != needs[spec.kind]:
                raise ValueError(f"initial.launch.{k}: a {spec.kind} launches on a mass_chain with a "
                                 f"{needs[spec.kind]} bond (this lattice: {self.lattice.kind}"
                                 + (f", {law} bond)" if law else ")"))

    @model_validator(mode="after")
    def _consistent(self):
        lat, exc = self.lattice, self.excitation
        n = lat.n_units
        ends = {e: getattr(lat, e) for e in ("left", "right", "bottom", "top") if hasattr(lat, e)}
        bounds = [p for p in exc.components() if p.at_end]
        for end, cond in ends.items():
            if cond == "driven" and not any(p.end == end for p in bounds):
                names = [k for k, spec in EXCITATIONS.items() if spec.config.at_end]
                raise ValueError(f"lattice.{end} is 'driven' but no {', '.join(names[:-1])} or {names[-1]} "
                                 f"acts on the {end} end")
        for t in exc.targets():
            if t.end is not None and t.end not in ends:
                raise ValueError(f"excitation end {t.end!r}: this lattice's ends are {', '.join(ends)}")
            if t.end is not None and ends[t.end] in ("fixed", "periodic"):
                raise ValueError(f"excitation acts on the {t.end} end, which lattice.{t.end} makes {ends[t.end]}")
            bad = [s for s in (getattr(t, "sites", None) or []) if s >= n]
            if bad:
                raise ValueError(f"excitation sites {bad} outside 0..{n - 1}")
            if getattr(t, "units", None) is not None:
                names = lat.unit_set_names() if hasattr(lat, "unit_set_names") else None
                if names is None or t.units not in names:
                    where = f"this lattice's unit sets: {', '.join(names) or 'none'}" if names is not None else \
                        f"a {lat.kind} lattice has no named unit sets (a rigid_network has)"
                    raise ValueError(f"excitation units {t.units!r}: not a named unit set ({where})")
        for p in exc.launches():
            if p.center_site >= n:
                raise ValueError(f"excitation.center_site={p.center_site} is outside 0..{n - 1}")
        if self.initial is not None:
            self._check_initial(n)
        if isinstance(self.imperfection, RotationSeed):
            bad = [s for s in self.imperfection.sites if s >= n]
            if bad:
                raise ValueError(f"imperfection.sites {bad} outside 0..{n - 1}")
        if self.output.site_stride >= n:
            raise ValueError(f"output.site_stride={self.output.site_stride} saves only unit 0 of the {n} units "
                             f"(lattice.n_units); use a stride below {n}, at most {max(1, (n - 1) // 10)} to save "
                             f"ten or more units")
        if self.output.fields is not None:
            valid = type(lat).FIELD_NAMES
            unknown = [f for f in self.output.fields if f not in valid]
            if unknown:
                raise ValueError(f"output.fields {unknown} not in this model's fields {list(valid)}")
        return self
