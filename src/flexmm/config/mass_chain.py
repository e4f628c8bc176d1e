"""Lattice configs of chains of masses (docs/physics.md §2): laws, variations, chain/network/grid.

A site has one displacement x (m). Bonds (nearest and optional second neighbours) and on-site
terms each follow one *law* (discriminated on ``law``); any numeric law field, the site mass,
the initial displacement and the friction level can vary by element (``variation``).
Each law's ``offset_m`` shifts its argument: the law is evaluated at (elongation − offset) for a
bond and (displacement − offset) on site.
"""

from __future__ import annotations

from pathlib import Path
from typing import ClassVar, Annotated, Literal, Union

from pydantic import Field, ValidationInfo, field_validator, model_validator

from flexmm.config.base import (EdgeCondition, EndCondition, Finite, NonNegative, Positive, Strict, check_periodic,
                                exactly_one)
from flexmm.config.variation import Variation, check_variations


# ---------------------------------------------------------------- laws
class _Law(Strict):
    offset_m: Finite = Field(0.0, description="argument shift: law evaluated at z − offset_m")


class Linear(_Law):
    """E = ½ k z² (a linear spring; on site, a spring to the ground)."""

    law: Literal["linear"]
    k_n_per_m: Positive


class Polynomial(_Law):
    """Force T(z) = k1 z + k2 z² + k3 z³ (FPU α = k2, β = k3; k2 > 0 softens under compression)."""

    law: Literal["polynomial"]
    k1_n_per_m: Finite
    k2_n_per_m2: Finite = 0.0
    k3_n_per_m3: Finite = 0.0


class PolynomialEnergy(_Law):
    """E = Σ_{n=1..8} c_n z^n with ``coefficients`` = [c_1, …] in J/m^n."""

    law: Literal["polynomial_energy"]
    coefficients: list[Finite] = Field(min_length=1, max_length=8)


class Raney2016(_Law):
    """Measured bistable beam pair (Raney et al. PNAS 2016), energy polynomial for constraint d.

    ψ(x) = Σ C_n x^n with x in mm, ψ in mJ, from the bundled copy of
    ``raney2016_bistable_energy_coeffs.csv``; wells near x = 0 (low energy) and x ≈ 7 mm.
    """

    law: Literal["raney2016"]
    d_mm: float = Field(ge=14.5, le=19.0, description="lateral constraint width d; coefficients interpolated between rows")


class BistableCubic(_Law):
    """On-site force V′(z) = α z (z − βL)(z − L): wells 0 and L, released energy αL⁴(1−2β)/12."""

    law: Literal["bistable_cubic"]
    alpha_n_per_m3: Positive
    beta: float = Field(gt=0.0, lt=1.0, description="barrier at βL; β = ½ gives equal wells")
    jump_m: Positive = Field(description="distance L between the wells")


class Phi4(_Law):
    """Symmetric double well V = h (1 − (z/L)²)² − h, wells ±L, barrier h."""

    law: Literal["phi4"]
    barrier_j: Positive
    half_distance_m: Positive


class ConstantForce(_Law):
    """V = −F z: a constant force F (tilts a landscape, or holds a static load)."""

    law: Literal["constant_force"]
    force_n: Finite


class Sine(_Law):
    """V = A (1 − cos(2π z/λ)) (Frenkel–Kontorova substrate)."""

    law: Literal["sine"]
    amplitude_j: Positive
    period_m: Positive


class Hertz(_Law):
    """Contact force A δ₊^p with overlap δ = precompression − z; no tension."""

    law: Literal["hertz"]
    stiffness_n_per_m_p: Positive = Field(description="A in F = A δ^p (N/m^p)")
    exponent: float = Field(1.5, ge=1.0, le=3.0)
    precompression_m: NonNegative = Field(
        0.0, description="overlap δ0 at zero elongation; the chain keeps it only if held (fixed "
        "ends, or static_load_n with relax, which sets the overlap to (F/A)^(1/p))")


class Toda(_Law):
    """E = (A/B)(e^{−Bz} − 1) + A z (Toda lattice; stiffness A B at rest)."""

    law: Literal["toda"]
    a_n: Positive
    b_per_m: Positive


class Dipole(_Law):
    """Repulsion of facing magnets at gap d + z: E = C (d + z)^{−p}.

    Give C directly or the magnetic moment m of two side-by-side parallel dipoles,
    C = μ0 m²/(4π) with p = 3.
    """

    law: Literal["dipole"]
    distance_m: Positive = Field(description="gap d between the magnets at rest")
    coefficient_j_m_p: Positive | None = None
    moment_a_m2: Positive | None = None
    exponent: float = Field(3.0, gt=0.0)

    @model_validator(mode="after")
    def _one(self):
        return exactly_one(self, "coefficient_j_m_p", "moment_a_m2")

    @property
    def coefficient(self) -> float:
        if self.coefficient_j_m_p is not None:
            return self.coefficient_j_m_p
        return 1e-7 * self.moment_a_m2**2  # μ0/(4π) = 1e-7


class Tabulated(_Law):
    """Force–displacement curve (force = dE/dz) through a C² cubic spline, integrated exactly.

    Either inline lists or a CSV with two numeric columns (displacement m, force N; a header
    line and '#' comments are allowed). A relative path is relative to the directory of the
    config file that names it (``load_scene``), else to the working directory; it is stored
    resolved, so the resolved config names the file that was read.
    """

    law: Literal["table"]
    csv: str | None = None
    displacement_m: list[Finite] | None = None
    force_n: list[Finite] | None = None

    @field_validator("csv")
    @classmethod
    def _relative_to_config(cls, value: str | None, info: ValidationInfo) -> str | None:
        base = (info.context or {}).get("base_dir")
        if value is None or base is None or Path(value).expanduser().is_absolute():
            return value if value is None else str(Path(value).expanduser())
        return str((Path(base) / value).resolve())

    @model_validator(mode="after")
    def _source(self):
        inline = self.displacement_m is not None or self.force_n is not None
        if (self.csv is None) == (not inline):
            raise ValueError("give either csv or both displacement_m and force_n")
        if inline and (self.displacement_m is None or self.force_n is None
                       or len(self.displacement_m) != len(self.force_n) or len(self.force_n) < 4):
            raise ValueError("displacement_m and force_n need the same length, at least 4")
        if self.csv is not None and not Path(self.csv).is_file():
            raise ValueError(f"csv file {self.csv!r} not found")
        return self


Law = Annotated[
    Union[Linear, Polynomial, PolynomialEnergy, Raney2016, BistableCubic, Phi4, ConstantForce,
          Sine, Hertz, Toda, Dipole, Tabulated],
    Field(discriminator="law"),
]


class Friction(Strict):
    """Regularised Coulomb friction with the ground, F = −F_c tanh(v/v_ε) on every site.

    ``backward_force_n`` (default = ``force_n``) acts for v < 0: anisotropic friction. Explicit
    in time: keep dt·F_c/(m v_ε) < 1 (the build checks it).
    """

    force_n: NonNegative
    backward_force_n: NonNegative | None = None
    regularisation_m_s: Positive = 1e-3


# ---------------------------------------------------------------- lattices
class _MassLattice(Strict):
    #: per-site coordinates of the built model (models.mass_chain.FIELDS)
    FIELD_NAMES: ClassVar[tuple[str, ...]] = ("u",)

    spacing_m: Positive = Field(description="distance between neighbouring sites (length scale)")
    mass_kg: Positive = Field(description="mass of a site")
    bond: Law = Field(description="nearest-neighbour law")
    bond2: Law | None = Field(None, description="optional second-neighbour law")
    onsite: list[Law] = Field(default_factory=list, description="on-site terms, summed")
    friction: Friction | None = None
    initial_displacement_m: Finite = Field(0.0, description="start guess of every site")
    relax: bool = Field(True, description="start from the energy minimum nearest the guess")
    reference_stiffness_n_per_m: Positive | None = Field(
        None, description="time scale sqrt(m/k); default from the bond law's rest stiffness"
    )
    variation: list[Variation] = Field(default_factory=list)

    @model_validator(mode="after")
    def _variation(self):
        n_cols, n_rows = self.variation_lines()
        check_variations(self.variation, n_cols=n_cols, n_rows=n_rows, site_targets=self.site_targets(),
                         bond_targets=self.bond_targets())
        return self

    def variation_lines(self) -> tuple[int, int]:
        """(columns, rows) that variations address; a chain or network: its sites in one row."""
        return self.n_sites, 1

    def site_targets(self) -> list[str]:
        """Per-site variation targets: mass, initial displacement, friction, on-site law fields."""
        out = ["mass_kg", "initial_displacement_m"]
        if self.friction is not None:
            out.append("friction.force_n")
        return out + [f"onsite.{k}.{f}" for k, law in enumerate(self.onsite) for f in law_numeric_fields(law)]

    def bond_targets(self) -> list[str]:
        """Per-bond variation targets: the numeric fields of the bond laws."""
        return [f"{prefix}.{f}" for prefix, law in (("bond", self.bond), ("bond2", self.bond2))
                if law is not None for f in law_numeric_fields(law)]


def law_numeric_fields(law) -> list[str]:
    """Numeric (scalar float) fields of a law config."""
    return [k for k, v in law if isinstance(v, float) and not isinstance(v, bool)]


class MassChain(_MassLattice):
    """A chain of n masses, nearest-neighbour (and optional second-neighbour) bonds."""

    kind: Literal["mass_chain"]
    n_units: int = Field(ge=2, le=20_000_000)
    left: EdgeCondition = Field("free", description="free, fixed, driven, or periodic (with right: a ring, "
                                "the last mass bonded to the first)")
    right: EdgeCondition = "free"
    static_load_n: Finite = Field(
        0.0, description="compressive force on both free ends (holds a precompression)"
    )

    @model_validator(mode="after")
    def _ring(self):
        if check_periodic(self, "left", "right", self.n_units, "n_units"):
            if self.n_units < (5 if self.bond2 is not None else 3):
                raise ValueError(f"a periodic chain (ring) needs n_units ≥ {5 if self.bond2 is not None else 3} "
                                 f"(got {self.n_units}): every bond must join two different units once")
            if self.static_load_n:
                raise ValueError("static_load_n acts on free ends; a periodic chain (ring) has none")
        return self

    @property
    def n_sites(self) -> int:
        return self.n_units

    def small_copy(self, n: int):
        """The same chain with at most ``n`` sites (for cheap estimates; not validated)."""
        return self.model_copy(update={"n_units": min(self.n_units, n), "variation": []})


class Branch(Strict):
    """A chain segment of a network; its ends attach to junctions or are free."""

    name: str = Field(pattern=r"^[A-Za-z][A-Za-z0-9_]*$")
    n_units: int = Field(ge=1)
    start: str | None = Field(None, description="junction before the first site (None: free end)")
    end: str | None = Field(None, description="junction after the last site (None: free end)")


class Junction(Strict):
    """A site shared by several branches; ``onsite`` replaces the default on-site terms there."""

    name: str = Field(pattern=r"^[A-Za-z][A-Za-z0-9_]*$")
    onsite: list[Law] | None = None
    mass_kg: Positive | None = None


class MassNetwork(_MassLattice):
    """Branches of chains joined at junctions (diodes, logic gates).

    Site numbering: branches in order, then junctions. Each branch's coordinate points from its
    start to its end. ``left`` lists the branches whose free *start* forms the 'left' end
    (excitations push it into the branch); ``right`` those whose free *end* forms the 'right' end.
    """

    kind: Literal["mass_network"]
    branches: list[Branch] = Field(min_length=1)
    junctions: list[Junction] = Field(default_factory=list)
    left: list[str] = Field(default_factory=list)
    right: list[str] = Field(default_factory=list)

    @model_validator(mode="after")
    def _graph(self):
        names = [b.name for b in self.branches]
        jn = [j.name for j in self.junctions]
        if len(set(names)) != len(names) or len(set(jn)) != len(jn) or set(names) & set(jn):
            raise ValueError("branch and junction names must be unique")
        for b in self.branches:
            for j in (b.start, b.end):
                if j is not None and j not in jn:
                    raise ValueError(f"branch {b.name!r} refers to unknown junction {j!r}")
        by = {b.name: b for b in self.branches}
        for side, attr in (("left", "start"), ("right", "end")):
            for name in getattr(self, side):
                if name not in by:
                    raise ValueError(f"{side}: unknown branch {name!r}")
                if getattr(by[name], attr) is not None:
                    raise ValueError(f"{side}: branch {name!r} has no free {attr}")
        return self

    @property
    def n_units(self) -> int:
        return sum(b.n_units for b in self.branches) + len(self.junctions)

    @property
    def n_sites(self) -> int:
        return self.n_units

    def small_copy(self, n: int):
        """Each branch cut to at most ``n`` // branches sites (for cheap estimates; not validated)."""
        per = max(2, n // len(self.branches))
        return self.model_copy(update={"branches": [b.model_copy(update={"n_units": min(b.n_units, per)})
                                                    for b in self.branches], "variation": []})


class MassGrid(_MassLattice):
    """nx × ny sites on a square grid (site = i + nx·j), horizontal and vertical bonds.

    ``bond2`` (if given) joins diagonal neighbours. The 'left' end is column i = 0, 'right'
    column nx − 1; ``left``/``right`` set their condition.
    """

    kind: Literal["mass_grid"]
    nx: int = Field(ge=2)
    ny: int = Field(ge=1)
    left: EndCondition = "free"
    right: EndCondition = "free"

    @property
    def n_units(self) -> int:
        return self.nx * self.ny

    @property
    def n_sites(self) -> int:
        return self.nx * self.ny

    def small_copy(self, n: int):
        """The same grid cut to at most about ``n`` sites (for cheap estimates; not validated)."""
        side = max(2, int(n**0.5))
        return self.model_copy(update={"nx": min(self.nx, side), "ny": min(self.ny, side), "variation": []})

    def variation_lines(self) -> tuple[int, int]:
        """(columns, rows) that variations address: the grid's nx × ny."""
        return self.nx, self.ny
