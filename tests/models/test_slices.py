"""Each kind's slice — the facts its ``ModelSpec`` and ``FIELDS`` declare — agrees with what its
builder builds: the field roles a ``System`` derives, the hinges and topology read without
building, the element counts of its variation targets."""

from __future__ import annotations

import numpy as np

from flexmm.models import MODELS, lattice_hinges
from flexmm.models.mass_topology import build_topology


def built(example_lattice, scene_dict, make_scene):
    kind, example = example_lattice
    lattice = make_scene(scene_dict(example["lattice"])).lattice
    return MODELS[kind], lattice, MODELS[kind].build(lattice)


def test_field_roles_are_the_models(example_lattice, scene_dict, make_scene):
    """u along x (the longitudinal field), v along y, θ the rotation; the bottom and top ends of a
    lattice with v are pushed along v, every other end along u."""
    _, _, system = built(example_lattice, scene_dict, make_scene)
    names = [f.name for f in system.fields]
    assert system.longitudinal_field == "u"
    assert system.axis_fields == ({"x": "u", "y": "v"} if "v" in names else {"x": "u"})
    assert system.rotation_field == ("theta" if "theta" in names else None)
    for end in [*system.ends, "bottom", "top"]:
        assert system.end_field(end) == ("v" if end in ("bottom", "top") and "v" in names else "u"), end


def test_hinges_topology_and_elements_are_the_builders(example_lattice, scene_dict, make_scene):
    spec, lattice, system = built(example_lattice, scene_dict, make_scene)
    if spec.hinges is not None:  # the args of rotating units open with their hinges' two units
        a, b, axis, wrap = lattice_hinges(lattice)
        args = getattr(system.args, "chain", system.args)  # a chain under loads: its chain's
        np.testing.assert_array_equal(a, args[0])
        np.testing.assert_array_equal(b, args[1])
        assert axis.shape == a.shape and np.array_equal(wrap, b <= a)
    if spec.topology is not None:
        topo = build_topology(lattice)
        assert topo.n_sites == system.n_sites and topo.ends == system.ends
        np.testing.assert_array_equal(topo.bonds, system.neighbour_pairs)
    if spec.elements is not None:
        counts = spec.hook("elements")(lattice)
        assert counts and all(n > 0 for n in counts.values())
    assert (spec.topology is None) == (system.rotation_field is not None)  # masses, or rotating units
