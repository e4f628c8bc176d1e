"""One variation schema and engine for every lattice (flexmm.config.variation, flexmm.models.variation).

The same YAML entry gives the same per-element values in every family that has the parameter;
a gradient is exact at its ends and leaves the rest alone; bonds and hinges take the mean over
their two sites; random noise is reproducible from its seed, independent across seeds and targets
and of the other entries; a bad entry is a config error at its file:line and field.
"""

from __future__ import annotations

import numpy as np
import pytest

from flexmm.config import ConfigError, load_scene, scene_from_dict
from flexmm.config.variation import Defects, Gradient, Interface, Random
from flexmm.models import MODELS
from flexmm.models.variation import apply_variations, parameter_arrays

M = 0.004  # kg, base site mass of every lattice below
RIGID = {"a_m": 0.016, "k_long_n_per_m": 7.0e4, "k_shear_n_per_m": 1.3e3, "k_rot_n_m_per_rad": 7e-4,
         "mass_kg": M, "inertia_kg_m2": 9e-8}
MASSES = {"spacing_m": 0.01, "mass_kg": M, "bond": {"law": "linear", "k_n_per_m": 100.0}, "relax": False}
#: lattices of the same shape in each family: a chain of 10 and a 5-column × 3-row sheet/grid
SHAPES = {  # rotating squares, rotating triangles, masses
    "chain": ({"kind": "rotating_squares_chain", "n_units": 10}, {"kind": "rotating_triangles_chain", "n_units": 10},
              {"kind": "mass_chain", "n_units": 10}),
    "sheet": ({"kind": "rotating_squares_sheet", "n_rows": 3, "n_cols": 5},
              {"kind": "rotating_triangles_sheet", "n_rows": 3, "n_cols": 5}, {"kind": "mass_grid", "nx": 5, "ny": 3}),
}
SHARED = {  # mass_kg variations valid on both shapes
    "chain": [
        {"kind": "gradient", "target": "mass_kg", "start": 0.002, "end": 0.008, "first": 2, "last": 6},
        {"kind": "interface", "target": "mass_kg", "position": 8, "value": 0.01},
        {"kind": "random", "target": "mass_kg", "relative_std": 0.05, "distribution": "uniform", "seed": 3},
        {"kind": "defects", "target": "mass_kg", "sites": [0, 9], "box": [4, 5, 0, 0], "factor": 2.0},
    ],
    "sheet": [
        {"kind": "gradient", "target": "mass_kg", "start": 0.002, "end": 0.006, "axis": "y"},
        {"kind": "interface", "target": "mass_kg", "position": 3, "value": 0.01},
        {"kind": "random", "target": "mass_kg", "std": 1e-4, "seed": 8},
        {"kind": "defects", "target": "mass_kg", "sites": [0], "box": [1, 2, 1, 2], "value": 0.02},
    ],
}


def _site_masses_kg(lattice: dict) -> np.ndarray:
    cfg = scene_from_dict({"name": "t", "lattice": lattice, "solver": {"duration_s": 1e-3}}).lattice
    system = MODELS[cfg.kind].build(cfg)
    return system.mass[: system.n_sites] * M  # nondimensional masses are in units of the base mass


@pytest.mark.parametrize("shape", sorted(SHAPES))
def test_one_yaml_variation_gives_the_same_values_in_every_family(shape):
    squares, triangles, masses = SHAPES[shape]
    variation = SHARED[shape]
    m_squares = _site_masses_kg({**RIGID, **squares, "variation": variation})
    m_triangles = _site_masses_kg({**RIGID, **triangles, "variation": variation})
    m_masses = _site_masses_kg({**MASSES, **masses, "variation": variation})
    np.testing.assert_array_equal(m_squares, m_masses)
    np.testing.assert_array_equal(m_triangles, m_masses)
    assert np.ptp(m_squares) > 0.005  # the variations did act


def test_the_values_follow_the_documented_rules_on_a_grid():
    """A 5 × 3 grid (site = col + 5 row): each rule written out by hand."""
    col, row = np.tile(np.arange(5), 3), np.repeat(np.arange(3), 5)
    ha = np.array([0, 5])  # two hinges: (0, 1) horizontal and (5, 10) vertical
    hb = np.array([1, 10])
    base = {"theta0_rad": 0.0, "mass_kg": 1.0, "inertia_kg_m2": 1.0, "k_long_n_per_m": 4.0,
            "k_shear_n_per_m": 1.0, "k_rot_n_m_per_rad": 1.0}
    sites, hinges = parameter_arrays(base, [
        Gradient(kind="gradient", target="mass_kg", start=2.0, end=5.0, first=1, last=4),
        Gradient(kind="gradient", target="k_long_n_per_m", start=0.0, end=8.0, axis="y"),
        Defects(kind="defects", target="inertia_kg_m2", sites=[14], box=[0, 1, 1, 2], factor=3.0),
    ], col, row, ha, hb)
    np.testing.assert_array_equal(sites["mass_kg"].reshape(3, 5), [[1, 2, 3, 4, 5]] * 3)
    # hinge (row 1, row 2): the ramp at both its units (4, 8) -> mean 6; hinge (0, 1): both rows 0 -> 0
    np.testing.assert_array_equal(hinges["k_long_n_per_m"], [0.0, 6.0])
    expect = np.ones((3, 5))
    expect[1:, :2] = 3.0
    expect[2, 4] = 3.0
    np.testing.assert_array_equal(sites["inertia_kg_m2"].reshape(3, 5), expect)


def test_a_gradient_is_exact_at_its_ends_and_leaves_the_rest_alone():
    n = 12
    values = {"x": np.full(n, 7.0), "k": np.full(n - 1, 7.0)}
    ramp = {"start": 0.1, "end": 0.3, "first": 3, "last": 8}
    i = np.arange(n)
    apply_variations(values, [Gradient(kind="gradient", target=t, **ramp) for t in ("x", "k")], i, 0 * i,
                     lambda t: (i[:-1], i[1:]) if t == "k" else None)
    x, k = values["x"], values["k"]
    assert x[3] == 0.1 and x[8] == 0.3  # exact, not within rounding
    np.testing.assert_array_equal(x[:3], 7.0)
    np.testing.assert_array_equal(x[9:], 7.0)
    np.testing.assert_allclose(x[3:9], 0.1 + 0.2 * np.arange(6) / 5, rtol=1e-15)
    # bond b joins sites b, b+1: inside the ramp the mean of its sites, straddling an end half the old value
    np.testing.assert_allclose(k[3:8], (x[3:8] + x[4:9]) / 2, rtol=1e-15)
    assert k[2] == pytest.approx((7.0 + 0.1) / 2) and k[8] == pytest.approx((0.3 + 7.0) / 2)
    np.testing.assert_array_equal(k[:2], 7.0)
    np.testing.assert_array_equal(k[9:], 7.0)


def test_gradients_compose_into_a_piecewise_linear_profile():
    values = {"x": np.zeros(9)}
    i = np.arange(9)
    apply_variations(values, [Gradient(kind="gradient", target="x", start=0.0, end=1.0, first=2, last=4),
                              Gradient(kind="gradient", target="x", start=1.0, end=0.0, first=4, last=6)],
                     i, 0 * i, lambda t: None)
    np.testing.assert_allclose(values["x"], [0, 0, 0, 0.5, 1, 0.5, 0, 0, 0])


def _noise(seed, target="x", n=20000, before=(), **kw):
    values = {"x": np.ones(n), "y": np.ones(n)}
    i = np.arange(n)
    apply_variations(values, [*before, Random(kind="random", target=target, seed=seed, **kw)], i, 0 * i,
                     lambda t: None)
    return values[target] - 1.0


def test_random_is_reproducible_differs_across_seeds_and_targets_and_has_its_spread():
    a = _noise(5, relative_std=0.1)
    np.testing.assert_array_equal(a, _noise(5, relative_std=0.1))
    assert not np.allclose(a, _noise(6, relative_std=0.1))
    # another target with the same seed: independent noise (correlation ~ 1/sqrt(n))
    assert abs(np.corrcoef(a, _noise(5, "y", relative_std=0.1))[0, 1]) < 0.05
    # the other entries do not shift the stream
    defect = Defects(kind="defects", target="y", sites=[0], value=2.0)
    np.testing.assert_array_equal(a, _noise(5, relative_std=0.1, before=[defect]))
    assert np.std(a) == pytest.approx(0.1, rel=0.03) and abs(np.mean(a)) < 0.005
    u = _noise(5, std=0.2, distribution="uniform")
    assert np.std(u) == pytest.approx(0.2, rel=0.03)
    assert np.max(np.abs(u)) <= 0.2 * np.sqrt(3.0) and np.max(np.abs(u)) > 0.99 * 0.2 * np.sqrt(3.0)


def test_hinge_defects_change_every_hinge_touching_a_listed_unit_once():
    n = 6
    i = np.arange(n)
    values = {"k": np.full(n - 1, 2.0)}
    apply_variations(values, [Defects(kind="defects", target="k", sites=[2, 3], factor=3.0)], i, 0 * i,
                     lambda t: (i[:-1], i[1:]))
    np.testing.assert_array_equal(values["k"], [2, 6, 6, 6, 2])  # (2, 3) touches both: scaled once


def test_interface_bond_across_takes_the_mean():
    n = 6
    i = np.arange(n)
    values = {"k": np.full(n - 1, 1.0), "m": np.full(n, 1.0)}
    apply_variations(values, [Interface(kind="interface", target=t, position=3, value=5.0) for t in ("k", "m")],
                     i, 0 * i, lambda t: (i[:-1], i[1:]) if t == "k" else None)
    np.testing.assert_array_equal(values["m"], [1, 1, 1, 5, 5, 5])
    np.testing.assert_array_equal(values["k"], [1, 1, 3, 5, 5])


_SQUARES_8 = "  kind: rotating_squares_chain\n  n_units: 8\n" + "".join(f"  {k}: {v}\n" for k, v in RIGID.items())
_MASSES = "  spacing_m: 0.01\n  mass_kg: 0.004\n  bond: {law: linear, k_n_per_m: 100.0}\n"
BAD = [  # (lattice lines, the bad entry, field reported, message part)
    (_SQUARES_8, "{kind: gradient, target: mass_kg, start: 1, end: 2, first: 4, last: 9}", "last",
     "a gradient needs first < last < 8"),
    (_SQUARES_8, "{kind: interface, target: k_rot_n_m_per_rad, position: 8, value: 1}", "position",
     "1 ≤ position ≤ 7"),
    ("  kind: mass_grid\n  nx: 4\n  ny: 3\n" + _MASSES,
     "{kind: defects, target: bond.k_n_per_m, box: [0, 1, 2, 3], value: 1}", "box", "j0 ≤ j1 < 3"),
    ("  kind: mass_chain\n  n_units: 8\n" + _MASSES, "{kind: random, target: bond.k9, std: 0.1}", "target",
     "not a parameter of this lattice"),
    ("  kind: mass_chain\n  n_units: 8\n" + _MASSES, "{kind: gradient, target: mass_kg, start: 1, end: 2, axis: y}",
     "axis", "single row"),
]


@pytest.mark.parametrize("lattice, entry, field, message", BAD)
def test_a_bad_entry_is_reported_at_its_file_line_and_field(tmp_path, lattice, entry, field, message):
    text = f"name: t\nlattice:\n{lattice}  variation:\n    - {{kind: defects, target: mass_kg, sites: [0], value: 0.005}}\n"
    line = text.count("\n") + 1
    path = tmp_path / "scene.yaml"
    path.write_text(text + f"    - {entry}\nsolver: {{duration_s: 0.001}}\n")
    with pytest.raises(ConfigError) as err:
        load_scene(path)
    assert f"{path}:{line}: lattice.variation.1.{field}:" in str(err.value)
    assert message in str(err.value)


def test_a_triangle_hinge_stiffness_variation_reaches_the_energy():
    """Two triangles, one hinge: scaling its k_l, k_s and k_θ by 3 triples the energy of any state."""
    def energy(variation):
        cfg = scene_from_dict({"name": "t", "lattice": {**RIGID, "kind": "rotating_triangles_chain", "n_units": 2,
                                                        "theta0_rad": 0.1, "variation": variation},
                               "solver": {"duration_s": 1e-3}}).lattice
        system = MODELS[cfg.kind].build(cfg)
        q = np.array([0.0, 0.03, 0.0, -0.02, 0.0, 0.05])  # (u, v, θ) of both, nondimensional
        return system.energy(q, system.args)

    scaled = [{"kind": "defects", "target": t, "sites": [1], "factor": 3.0}
              for t in ("k_long_n_per_m", "k_shear_n_per_m", "k_rot_n_m_per_rad")]
    base = energy([])
    assert base > 0
    assert energy(scaled) == pytest.approx(3.0 * base, rel=1e-12)


def test_a_varied_triangle_lattice_gets_no_uniform_bloch_speed():
    from types import SimpleNamespace

    from flexmm.analysis.predict.rotating_triangles import CHAIN

    def rows(variation):
        lattice = {**RIGID, "kind": "rotating_triangles_chain", "n_units": 8, "k_shear_n_per_m": 7.0e3,
                   "k_rot_n_m_per_rad": 0.05, "variation": variation}  # a gapped twist branch
        scene = scene_from_dict({"name": "t", "lattice": lattice, "solver": {"duration_s": 1e-3}})
        return CHAIN.pulse(SimpleNamespace(scene=lambda: scene), SimpleNamespace(field="u", speed_m_s=1.0))

    assert len(rows([])) == 1
    assert rows([{"kind": "gradient", "target": "mass_kg", "start": 0.004, "end": 0.008}]) == []


def test_the_documented_clamped_ramp_recipe():
    """docs/scenes.md: base A, an interface at `last` with B, then the gradient A -> B over first..last
    gives the clamped ramp, on the units and on the hinges (sampled at their midpoints)."""
    n, first, last = 12, 3, 7
    i = np.arange(n)
    values = {"m": np.full(n, 1.0), "k": np.full(n - 1, 1.0)}
    for t in ("m", "k"):
        apply_variations(values, [Interface(kind="interface", target=t, position=last, value=2.0),
                                  Gradient(kind="gradient", target=t, start=1.0, end=2.0, first=first, last=last)],
                         i, 0 * i, lambda t: (i[:-1], i[1:]) if t == "k" else None)

    def clamped(x):
        return 1.0 + np.clip((x - first) / (last - first), 0.0, 1.0)

    np.testing.assert_allclose(values["m"], clamped(i), rtol=1e-15)
    np.testing.assert_allclose(values["k"], clamped(i[:-1] + 0.5), rtol=1e-15)
