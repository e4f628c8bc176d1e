"""Shared fixtures: scenes from dicts, the LEGO chain config, example lattices per model kind.

Tests that take an ``example_lattice`` argument run once per entry of ``EXAMPLE_LATTICES`` for
every kind in ``flexmm.models.MODELS``; a kind without an example is reported as skipped, so
a new model is noticed. Add a small representative config for it below.
"""

from __future__ import annotations

import contextlib
import copy
import subprocess
from pathlib import Path

import numpy as np
import pytest

from flexmm.config import scene_from_dict
from flexmm.io.run_dataset import open_run
from flexmm.models import MODELS

#: The LEGO rotating-squares unit (docs/physics.md §1.1): the one source of these numbers for the
#: tests (``from conftest import LEGO_PARAMETERS``); a test that needs other values overrides
#: them, ``dict(LEGO_CHAIN, k_shear_n_per_m=...)``.
LEGO_PARAMETERS = {
    "a_m": 0.016,
    "k_long_n_per_m": 71690.0,
    "k_shear_n_per_m": 1326.98,
    "k_rot_n_m_per_rad": 7.038e-4,
    "mass_kg": 4.52e-3,
    "inertia_kg_m2": 8.7814e-8,
}
#: a LEGO rotating-squares chain, one lateral neighbour (n_units, θ0 and ends left to the test)
LEGO_CHAIN = {"kind": "rotating_squares_chain", **LEGO_PARAMETERS, "n_lateral": 1}
#: a LEGO rotating-squares sheet (size, θ0 and edges left to the test)
LEGO_SHEET = {"kind": "rotating_squares_sheet", **LEGO_PARAMETERS}
#: stiff hinges on the LEGO chain (nondimensional K_s = 0.5, K_θ = 0.02): pulses a few sites wide
LEGO_STIFF_HINGES = {"k_shear_n_per_m": 0.5 * LEGO_PARAMETERS["k_long_n_per_m"],
                     "k_rot_n_m_per_rad": 0.02 * LEGO_PARAMETERS["k_long_n_per_m"] * LEGO_PARAMETERS["a_m"] ** 2}
# The LEGO impact of configs/lego_vector_soliton.yaml on a 200-unit chain with a free far end, for
# 0.8 s: the demo's scene at the size tests run (the demo is this with DEMO_CHANGES; tests/test_cli.py
# checks that they agree).
LEGO_LATTICE = {**LEGO_CHAIN, "n_units": 200, "theta0_rad": 0.0, "left": "driven", "right": "free"}
LEGO_SCENE = {
    "name": "lego_vector_soliton",
    "description": "LEGO rotating-squares chain struck at its left end; an elastic vector soliton forms.",
    "lattice": LEGO_LATTICE,
    "excitation": {"kind": "impact", "end": "left", "velocity_m_s": 3.0, "angular_velocity_rad_s": 300.0},
    "damping": {},
    "solver": {"integrator": "velocity_verlet", "duration_s": 0.8},
    "output": {"n_frames": 801},
}
#: what configs/lego_vector_soliton.yaml changes in LEGO_SCENE (dotted): a chain long enough for the
#: soliton to form and travel, with an absorbing far end
DEMO_CHANGES = {"lattice.n_units": 900, "damping.absorbing": {"end": "right", "n_units": 120},
                "solver.duration_s": 2.0, "output.n_frames": 1001}
#: dotted overrides that turn the shipped demo into LEGO_SCENE's chain (200 units, free far end)
DEMO_AS_LEGO_SCENE = {"lattice.n_units": 200, "damping.absorbing": None, "solver.duration_s": 0.8,
                      "output.n_frames": 801}
#: the same as ``--set``/``load_scene`` strings
DEMO_AS_LEGO_SCENE_SETS = [f"{k}={'null' if v is None else v}" for k, v in DEMO_AS_LEGO_SCENE.items()]


def _chain(**changes) -> dict:
    """A small rotating-squares chain (LEGO stiffnesses unless changed)."""
    lat = dict(LEGO_LATTICE, n_units=9, left="free", right="free")
    lat.update(changes)
    return lat


_SHEET = LEGO_SHEET
# rotating triangles (docs/physics.md §1.6): LEGO k_l, a stiffer shear spring (0.1 k_l) to couple the fields
#: a geometry file of two squares and two triangles (tests/models/data)
GEOMETRY_FILE = str(Path(__file__).resolve().parent / "models" / "data" / "mixed_units.yaml")
_NET = {"kind": "rigid_network", "a_m": 0.01, "k_long_n_per_m": 1e4, "k_shear_n_per_m": 3e3,
        "k_rot_n_m_per_rad": 2e-3, "areal_density_kg_m2": 20.0}
_TRI = {"a_m": 0.02, "k_long_n_per_m": LEGO_PARAMETERS["k_long_n_per_m"], "k_shear_n_per_m": 7169.0,
        "k_rot_n_m_per_rad": 0.05, "mass_kg": LEGO_PARAMETERS["mass_kg"], "inertia_kg_m2": 1.2e-7}
_MASS = {"spacing_m": 0.01, "mass_kg": 0.01,
         "bond": {"law": "polynomial", "k1_n_per_m": 100.0, "k2_n_per_m2": 2e3, "k3_n_per_m3": 1e5}}


#: kind -> {example id -> {"lattice": lattice dict, "translation_invariant": bool,
#: optional "not_at_rest": why q = 0 is not a stress-free equilibrium (the rest test xfails)}}.
#: Keep them small (a few dozen DOFs): the kernel tests take finite differences over every DOF.
EXAMPLE_LATTICES: dict[str, dict[str, dict]] = {
    "rotating_squares_chain": {
        "lego-theta0-nv1": {"lattice": _chain(theta0_rad=0.15, n_lateral=1), "translation_invariant": True},
        "sheet-wave-nv2-sv": {
            "lattice": _chain(theta0_rad=-0.2, n_lateral=2, lateral_stretch=True),
            "translation_invariant": True,
        },
        "single-row-stiff": {
            "lattice": _chain(n_units=8, theta0_rad=0.3, n_lateral=0, **LEGO_STIFF_HINGES),
            "translation_invariant": True,
        },
        "precompressed-loads": {  # constant end loads (predeform): an extra linear energy term
            "lattice": _chain(theta0_rad=0.05, predeform={"loads": [{"end": "left", "force_n": 0.2},
                                                                   {"end": "right", "force_n": 0.2}]}),
            "translation_invariant": True,  # the two loads balance
            "not_at_rest": "the end loads act at q = 0 (the relaxed state is q0)",
        },
        "graded-theta0": {
            "lattice": _chain(theta0_rad=0.1, n_lateral=1, lateral_stretch=True, variation=[
                {"kind": "gradient", "target": "theta0_rad", "start": 0.05, "end": 0.3},
                {"kind": "gradient", "target": "k_rot_n_m_per_rad", "start": 5e-4, "end": 2e-3},
            ]),
            "translation_invariant": True,
            # The hinge law of docs/physics.md §1.1 has no rest offset in the shear spring: with θ0 varying along a
            # chain whose centres stay on the axis (v suppressed), Δy ≠ 0 at q = 0.
            "not_at_rest": "a θ0 gradient leaves the hinge shear springs pre-stressed at q = 0",
        },
    },
    "rotating_squares_sheet": {
        "theta0-3x4": {
            "lattice": dict(_SHEET, n_rows=3, n_cols=4, theta0_rad=0.15),
            "translation_invariant": True,
        },
        "pla-ligament-2x3": {  # Bordiga et al. 2024 PLA squares (docs/physics.md §1.1), with a ligament
            "lattice": dict(_SHEET, n_rows=2, n_cols=3, a_m=0.015, theta0_rad=-0.2, ligament_length_m=0.002,
                            k_long_n_per_m=1.2e5, k_shear_n_per_m=1190.0, k_rot_n_m_per_rad=1.5e-3,
                            mass_kg=None, inertia_kg_m2=None, areal_density_kg_m2=6.18),
            "translation_invariant": True,
        },
        "periodic-graded-4x4": {  # wrap hinges on both axes; per-hinge and per-unit variation
            "lattice": dict(_SHEET, n_rows=4, n_cols=4, theta0_rad=0.1, left="periodic", right="periodic",
                            bottom="periodic", top="periodic", variation=[
                                {"kind": "gradient", "target": "k_rot_n_m_per_rad", "start": 5e-4, "end": 2e-3},
                                {"kind": "random", "target": "mass_kg", "relative_std": 0.1, "seed": 1},
                                {"kind": "interface", "target": "k_shear_n_per_m", "position": 2, "value": 3e3,
                                 "axis": "y"}]),
            "translation_invariant": True,
        },
        "magnets-2x3": {  # face dipoles of hinged and diagonal neighbours, with their contact core
            "lattice": dict(_SHEET, n_rows=2, n_cols=3, a_m=0.02, k_long_n_per_m=5e4, k_shear_n_per_m=5e4,
                            k_rot_n_m_per_rad=0.01, mass_kg=0.005, inertia_kg_m2=None,
                            magnets={"moment_a_m2": 0.253, "recess_m": 0.003}),
            "translation_invariant": True,
            "not_at_rest": "facing magnets pull on each other at q = 0",
        },
    },
    "rotating_triangles_chain": {
        "theta0-free": {"lattice": dict(_TRI, kind="rotating_triangles_chain", n_units=7, theta0_rad=0.2),
                        "translation_invariant": True},
        "straight-fixed-ends": {"lattice": dict(_TRI, kind="rotating_triangles_chain", n_units=6, left="fixed",
                                                right="fixed", inertia_kg_m2=None),
                                "translation_invariant": True},
        "negative-theta0-periodic": {"lattice": dict(_TRI, kind="rotating_triangles_chain", n_units=6,
                                                     theta0_rad=-0.35, left="periodic", right="periodic"),
                                     "translation_invariant": True},
        "varied": {"lattice": dict(_TRI, kind="rotating_triangles_chain", n_units=7, theta0_rad=0.2, variation=[
            {"kind": "gradient", "target": "k_rot_n_m_per_rad", "start": 0.02, "end": 0.08},
            {"kind": "interface", "target": "k_long_n_per_m", "position": 4, "value": 9.0e4},
            {"kind": "defects", "target": "k_shear_n_per_m", "sites": [3], "factor": 3.0},
            {"kind": "random", "target": "mass_kg", "relative_std": 0.1, "seed": 2}]),
                   "translation_invariant": True},
    },
    "rotating_triangles_sheet": {
        "theta0-3x4": {"lattice": dict(_TRI, kind="rotating_triangles_sheet", n_rows=3, n_cols=4, theta0_rad=0.25),
                       "translation_invariant": True},
        "periodic-4x4": {"lattice": dict(_TRI, kind="rotating_triangles_sheet", n_rows=4, n_cols=4, theta0_rad=-0.1,
                                         left="periodic", right="periodic", bottom="periodic", top="periodic"),
                         "translation_invariant": True},
        "varied-3x4": {"lattice": dict(_TRI, kind="rotating_triangles_sheet", n_rows=3, n_cols=4, theta0_rad=0.25,
                                       variation=[
            {"kind": "gradient", "target": "k_long_n_per_m", "start": 6e4, "end": 9e4, "axis": "y"},
            {"kind": "defects", "target": "inertia_kg_m2", "box": [1, 2, 0, 1], "factor": 2.0},
            {"kind": "random", "target": "k_rot_n_m_per_rad", "std": 0.005, "seed": 1}]),
                       "translation_invariant": True},
    },
    "rigid_network": {
        "squares-3x4": {"lattice": dict(_NET, n_rows=3, n_cols=4, theta0_rad=0.2), "translation_invariant": True},
        "random-quads-fixed-3x3": {"lattice": dict(_NET, pattern="random_quads", vertex_jitter=0.1, seed=4, n_rows=3,
                                                   n_cols=3, ligament_length_m=0.001, left="fixed"),
                                   "translation_invariant": True},
        "kagome-3x4": {"lattice": dict(_NET, pattern="rotating_triangles", n_rows=3, n_cols=4, theta0_rad=-0.15,
                                       bottom="fixed"),
                       "translation_invariant": True},
        "hexagons-3x4": {"lattice": dict(_NET, pattern="rotating_hexagons", n_rows=3, n_cols=4, theta0_rad=0.2),
                         "translation_invariant": True},
        "rectangles-3x3": {"lattice": dict(_NET, pattern="rectangles", aspect_ratio=0.6, n_rows=3, n_cols=3,
                                           theta0_rad=0.1, ligament_length_m=0.001),
                           "translation_invariant": True},
        "file-mixed": {"lattice": {k: v for k, v in _NET.items() if k != "a_m"} | {"geometry": GEOMETRY_FILE},
                       "translation_invariant": True},
        "masked-squares-4x4": {"lattice": dict(_NET, n_rows=4, n_cols=4, theta0_rad=0.2,
                                               mask={"holes": [{"circle_m": [0.0, 0.0, 0.004]}]},
                                               unit_sets={"far": {"box_m": [0.02, 0.02, 1.0, 1.0]}}, fixed_units=["far"]),
                               "translation_invariant": True},
    },
    "bistable_linkage": {
        "six-bars": {
            "lattice": {"kind": "bistable_linkage", "n_cols": 3, "bar_length_m": 0.01, "theta0_rad": 0.3,
                        "theta_deployed_rad": 0.7, "mass_kg": 1e-3, "k_pin_n_per_m": 1e4,
                        "released_energy_j": 1e-4},
            "translation_invariant": True,
        },
    },
    "mass_chain": {
        "fpu-toda": {
            "lattice": dict(_MASS, kind="mass_chain", n_units=8, bond2={"law": "toda", "a_n": 1.0, "b_per_m": 50.0}),
            "translation_invariant": True,
        },
    },
    "mass_grid": {
        "fpu-3x3": {"lattice": dict(_MASS, kind="mass_grid", nx=3, ny=3), "translation_invariant": True},
    },
    "mass_network": {
        "y-junction": {
            "lattice": dict(_MASS, kind="mass_network", junctions=[{"name": "j"}], branches=[
                {"name": "a", "n_units": 3, "end": "j"}, {"name": "b", "n_units": 3, "start": "j"},
                {"name": "c", "n_units": 2, "start": "j"}]),
            "translation_invariant": True,
        },
    },
}


def set_path(data: dict, dotted: str, value) -> None:
    """Set ``data['a']['b'] = value`` for ``dotted = 'a.b'``, creating mappings on the way."""
    *head, last = dotted.split(".")
    for key in head:
        data = data.setdefault(key, {})
    data[last] = value


@pytest.fixture
def lego_config() -> dict:
    """A fresh (deep) copy of LEGO_SCENE (the demo's LEGO impact on a 200-unit free-ended chain)."""
    return copy.deepcopy(LEGO_SCENE)


@pytest.fixture
def example_lattices() -> dict:
    """A deep copy of EXAMPLE_LATTICES (kind -> id -> example)."""
    return copy.deepcopy(EXAMPLE_LATTICES)


@pytest.fixture
def make_scene():
    """``make_scene(data, {"solver.dt_s": 1e-6, ...})`` -> validated Scene (data is not modified)."""

    def make(data: dict, overrides: dict | None = None):
        d = copy.deepcopy(data)
        for key, value in (overrides or {}).items():
            set_path(d, key, value)
        return scene_from_dict(d)

    return make


@pytest.fixture
def scene_dict():
    """``scene_dict(lattice, **sections)`` -> minimal scene dict (no excitation, 1 s) around a lattice."""

    def make(lattice: dict, **sections) -> dict:
        out = {"name": "test", "lattice": copy.deepcopy(lattice), "solver": {"duration_s": 1.0}}
        out.update(copy.deepcopy(sections))
        return out

    return make


@pytest.fixture
def run_dir(tmp_path):
    """An empty directory for one run's outputs."""
    d = tmp_path / "run"
    d.mkdir()
    return d


def pytest_generate_tests(metafunc):
    """Parametrise ``example_lattice`` = (kind, example) over every registered model kind."""
    if "example_lattice" not in metafunc.fixturenames:
        return
    params = []
    for kind in sorted(MODELS):
        examples = EXAMPLE_LATTICES.get(kind)
        if not examples:
            reason = f"no example lattice for model kind {kind!r}: add one to EXAMPLE_LATTICES in tests/conftest.py"
            params.append(pytest.param((kind, None), id=kind, marks=pytest.mark.skip(reason=reason)))
            continue
        for name, example in examples.items():
            params.append(pytest.param((kind, example), id=f"{kind}-{name}"))
    metafunc.parametrize("example_lattice", params)


#: Directories whose tests compile the most numba kernels on an empty cache (a fresh clone, CI), each
#: its own family of kernels (the gradient sweeps; the integrators' steppers): under pytest-xdist's
#: ``--dist worksteal`` (``make test``), each leads one worker's share (``pytest_collection_modifyitems``).
COLD_COMPILE_FIRST = ("tests/design/", "tests/integrators/")


def worksteal_shares(n_items: int, workers: int) -> list[int]:
    """The sizes of the contiguous shares ``--dist worksteal`` first sends its workers, in order
    (xdist's ``WorkStealingScheduling.check_schedule``: each gets the pending count over the workers
    left); a worker that runs out then steals the back half of the longest queue."""
    sizes, left = [], n_items
    for k in range(workers):
        sizes.append(left // (workers - k))
        left -= sizes[-1]
    return sizes


def lead_shares(items: list, workers: int, first=COLD_COMPILE_FIRST) -> list:
    """``items`` reordered so that the tests under ``first[g]`` open worker ``g % workers``'s share
    (``worksteal_shares``), the rest keeping their order: the compile-heavy families start at once
    on different workers, and what is left to steal at the end is many short tests. Where a
    share cannot hold its leading tests, the order is kept."""
    lead = [[] for _ in range(workers)]
    rest = []
    for item in items:
        g = next((g for g, d in enumerate(first) if item.nodeid.startswith(d)), None)
        (rest if g is None else lead[g % workers]).append(item)
    sizes = worksteal_shares(len(items), workers)
    if any(len(a) > b for a, b in zip(lead, sizes)):
        return items
    out = []
    for w in range(workers):
        take = sizes[w] - len(lead[w])
        out += lead[w] + rest[:take]
        rest = rest[take:]
    return out


@pytest.hookimpl(trylast=True)
def pytest_collection_modifyitems(config, items) -> None:
    """In pytest-xdist workers (several), the compile-heavy directories lead the workers' shares
    (``lead_shares``, dealt as ``--dist worksteal`` deals them; a worker sees its own ``dist`` as
    "no", so the mode is not checked); every worker collects the same order. A run in one
    process keeps pytest's order."""
    workerinput = getattr(config, "workerinput", None)
    workers = int(workerinput["workercount"]) if workerinput is not None else 1
    if workers > 1:
        items[:] = lead_shares(items, workers)


def default_sigint() -> None:
    """``preexec_fn`` of a test's child process that receives SIGINT: its disposition back to the
    default, so Python turns SIGINT into KeyboardInterrupt even when the tests run with SIGINT
    ignored (as a background job of a non-interactive shell, which its children inherit)."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_DFL)


@pytest.fixture
def in_process_scheduler():
    """A real Dask LocalCluster in this process (threads): no worker start-up or recompilation
    (the sweep tests)."""
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster:
        yield cluster.scheduler_address


def assert_same_data(a: Path, b: Path) -> None:
    """The datasets of two runs are equal bit for bit (every variable), with the same step and
    force-evaluation counts and status."""
    da, db = open_run(a), open_run(b)
    assert set(da.variables) == set(db.variables)
    differ = [k for k in da.variables if not np.array_equal(da[k].values, db[k].values)]
    assert differ == [], f"not bit-identical: {differ}"
    for key in ("n_steps", "force_evaluations", "status"):
        assert da.attrs[key] == db.attrs[key], key


def is_stopped(pid: int) -> bool:
    """The process is stopped (SIGSTOP: state T in /proc)."""
    stat = Path(f"/proc/{pid}/stat").read_text()
    return stat[stat.rfind(")") + 2] == "T"


@contextlib.contextmanager
def mounted_tmpfs(where: Path, size: str):
    """A real tmpfs of ``size`` (mount's notation, e.g. ``40m``) mounted at ``where`` (created) for
    the block; the test is skipped where it cannot be mounted (needs root)."""
    where.mkdir()
    res = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(where)], capture_output=True,
                         text=True)
    if res.returncode != 0:
        pytest.skip(f"cannot mount a {size} tmpfs (needs root): {res.stderr.strip()[:200]}")
    try:
        yield where
    finally:
        subprocess.run(["umount", "-l", str(where)], capture_output=True)
