"""Energy colouring: the energies per unit (site) add up to the model's energy, every model kind.

``flexmm.render`` computes energies from the stored config alone (no model rebuild); here the
sum over units of the potential part is compared with the model's numpy reference energy at
random states, and the kinetic part with ½ m v² from the model's masses. The parameter tables the
render reads from the config (θ0, masses, stiffnesses after variations; the relaxed initial state
of mass lattices) are compared with the built model's too.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from render_helpers import NOT_RENDERED, build, random_fields

from flexmm.config import load_scene
from flexmm.models import MODELS
from flexmm.render.masses import mass_params, site_energy_j
from flexmm.render.params import rigid_params
from flexmm.render.rigid import unit_energy_j

RIGID = ("rotating_squares_chain", "rotating_squares_sheet", "bistable_linkage")
CONFIGS = Path(__file__).resolve().parents[2] / "configs"


def model_potential_j(system, q: np.ndarray) -> float:
    """The model's potential energy (J) without magnets and end loads (not part of the colouring)."""
    from flexmm.models.kernels import kernels_of
    from flexmm.models.magnets import empty_dipoles

    args = system.args
    if hasattr(args, "chain"):  # LoadedChainArgs: the chain without its constant loads
        args = args.chain
    elif hasattr(args, "dipoles"):
        args = args._replace(dipoles=empty_dipoles(system.n_sites))
    return kernels_of(type(args)).reference(q, args)[0] * system.scales.energy


def test_energy_per_unit_adds_up_to_the_model_energy(example_lattice):
    kind, example = example_lattice
    if kind in NOT_RENDERED:
        pytest.skip(f"{kind} has no energy colouring (its drawing gives the model energy: tests/render/test_shapes.py)")
    lat, system = build(example["lattice"])
    fields = random_fields(system, 2, seed=11, amplitude=0.5)
    sc = system.scales
    q = np.concatenate([fields[f.name][1] / sc.coordinate(f.kind) for f in system.fields])
    rates = {f"{f.name}_dot": fields[f"{f.name}_dot"][1] for f in system.fields}
    if kind in RIGID:
        p = rigid_params(lat)
        potential = unit_energy_j(p, fields["u"][1], fields.get("v", [None, None])[1], fields["theta"][1], None)
        total = unit_energy_j(p, fields["u"][1], fields.get("v", [None, None])[1], fields["theta"][1], rates)
    else:
        p = mass_params(lat)
        potential = site_energy_j(p, fields["u"][1], None)
        total = site_energy_j(p, fields["u"][1], fields["u_dot"][1])
    assert potential.sum() == pytest.approx(model_potential_j(system, q), rel=1e-9, abs=1e-15)
    v = np.concatenate([rates[f"{f.name}_dot"] / sc.rate(f.kind) for f in system.fields])
    kinetic = 0.5 * np.sum(system.mass * v * v) * sc.energy
    assert (total - potential).sum() == pytest.approx(kinetic, rel=1e-12)


def test_parameter_tables_match_the_model(example_lattice):
    """θ0, masses, inertias and hinge stiffnesses read from the config equal the built model's."""
    kind, example = example_lattice
    if kind in NOT_RENDERED:
        pytest.skip(f"{kind} has no energy colouring (its drawing gives the model energy: tests/render/test_shapes.py)")
    lat, system = build(example["lattice"])
    sc = system.scales
    n = system.n_sites
    if kind not in RIGID:
        p = mass_params(lat)
        np.testing.assert_allclose(p.values["mass_kg"], system.mass * sc.mass_kg, rtol=1e-12)
        np.testing.assert_array_equal(p.bonds, system.neighbour_pairs)
        return
    p = rigid_params(lat)
    args = getattr(system.args, "chain", system.args)
    theta0 = args.site_prm[:, 0] if kind == "rotating_squares_chain" else args.theta0
    np.testing.assert_allclose(p.theta0_rad, theta0, rtol=1e-12)
    np.testing.assert_allclose(p.mass_kg, system.mass[:n] * sc.mass_kg, rtol=1e-12)
    np.testing.assert_allclose(p.inertia_kg_m2, system.mass[-n:] * sc.inertia, rtol=1e-12)
    np.testing.assert_array_equal(p.hinge_a, args.hinge_a)
    np.testing.assert_array_equal(p.hinge_b, args.hinge_b)
    for col, mine, unit in ((4, p.k_long_n_per_m, sc.stiffness), (5, p.k_shear_n_per_m, sc.stiffness),
                            (6, p.k_rot_n_m_per_rad, sc.energy)):
        np.testing.assert_allclose(mine, args.hinge_prm[:, col] * unit, rtol=1e-12, atol=1e-300)


#: scenes whose relaxation takes over 10 s: checked with -m slow
SLOW_RELAX = {"e_tensegrity_rarefaction.yaml"}
MASS_CONFIGS = [pytest.param(name, marks=pytest.mark.slow) if name in SLOW_RELAX else name
                for name in sorted(p.name for p in CONFIGS.glob("*.yaml")
                                   if load_scene(p).lattice.kind in ("mass_chain", "mass_network", "mass_grid"))]


@pytest.mark.parametrize("config", MASS_CONFIGS)
def test_relaxed_initial_state_matches_the_model(config):
    """The initial state the render relaxes from the config equals the model's (u is measured from it)."""
    lat = load_scene(CONFIGS / config).lattice
    system = MODELS[lat.kind].build(lat)
    p = mass_params(lat)
    np.testing.assert_allclose(p.x0, system.initial_displacement_m, rtol=0, atol=1e-6 * lat.spacing_m)
