"""Compiled once per machine: a second process loads every integrator loop from numba's cache.

Each case runs a fresh interpreter twice on an empty cache directory (NUMBA_CACHE_DIR): the
first compiles and saves, the second must load the stepper's advance kernel from the cache
(no cache miss) and produce bit-identical states: a graded chain by default (the fused kernel
reading parameter columns; sincos and the hinge laws with explicit fused multiply-adds,
``_jit.fma``, which must not depend on what was inlined where). Also: an unwritable cache location falls
back to a temporary one, then to no caching, with a note that says so.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time

import pytest
from conftest import LEGO_CHAIN

SCRIPT = r"""
import json, sys, warnings
import numpy as np
from flexmm.assemble import build_problem
from flexmm.config import scene_from_dict
from flexmm.integrators.stepper import make_stepper
import flexmm._jit as J

integrator, model = sys.argv[1], sys.argv[2]
if model in ("chain", "graded"):
    lat = json.loads(sys.argv[3])  # the LEGO chain of tests/conftest.py, 12 units (graded: θ0 and k_θ vary)
    excitation = {"kind": "impact", "end": "left", "velocity_m_s": 1.0, "angular_velocity_rad_s": 50.0}
else:  # the sheet, driven on its left column (Verlet fused with the sheet force)
    lat = {"kind": "rotating_squares_sheet", "n_rows": 5, "n_cols": 7, "a_m": 0.01, "theta0_rad": 0.35,
           "k_long_n_per_m": 1.0e4, "k_shear_n_per_m": 3.3e3, "k_rot_n_m_per_rad": 7.5e-3, "mass_kg": 1.0e-3,
           "inertia_kg_m2": 8.333333333e-9, "left": "driven"}
    excitation = {"kind": "shaker", "end": "left", "frequency_hz": 500.0, "amplitude_n": 2.0, "ramp_cycles": 0.5,
                  "duration_s": 0.002}
scene = scene_from_dict({"name": "t", "lattice": lat, "excitation": excitation,
                         "solver": {"duration_s": 1e-3, "integrator": integrator}})
st = make_stepper(build_problem(scene), threads=1)
st.advance(50)
stats = st.kernel.stats
print(json.dumps({"hits": sum(stats.cache_hits.values()), "misses": sum(stats.cache_misses.values()),
                  "q": st.q.tolist(), "v": st.v.tolist(), "cache_dir": str(J.CACHE_DIR),
                  "compile_s": st.compile_s, "kernel": st.kernel.__name__}))
"""


#: a graded LEGO chain: the fused kernel streams its site columns (sincos and hinges: ``_jit.fma``)
GRADED = dict(LEGO_CHAIN, n_units=12, theta0_rad=0.1, lateral_stretch=True, variation=[
    {"kind": "gradient", "target": "theta0_rad", "start": 0.05, "end": 0.3},
    {"kind": "gradient", "target": "k_rot_n_m_per_rad", "start": 5e-4, "end": 2e-3}])


def _run(integrator: str, env: dict, model: str = "chain") -> dict:
    chain = json.dumps(GRADED if model == "graded" else dict(LEGO_CHAIN, n_units=12))
    out = subprocess.run([sys.executable, "-c", SCRIPT, integrator, model, chain], env=env, capture_output=True,
                         text=True, timeout=1800)  # a hang guard: a cold compile takes minutes on a loaded machine
    assert out.returncode == 0, out.stderr[-3000:]
    return {**json.loads(out.stdout.strip().splitlines()[-1]), "stderr": out.stderr}


@pytest.mark.parametrize(("integrator", "model", "where"), [
    ("velocity_verlet", "graded", "default"),
    pytest.param("velocity_verlet", "chain", "NUMBA_CACHE_DIR", marks=pytest.mark.slow),
    pytest.param("pefrl", "chain", "NUMBA_CACHE_DIR", marks=pytest.mark.slow),
    pytest.param("velocity_verlet", "sheet", "NUMBA_CACHE_DIR", marks=pytest.mark.slow)])
def test_second_process_loads_the_stepper_from_cache_bit_identically(integrator, model, where, tmp_path) -> None:
    """``default``: the per-module directories under ``$XDG_CACHE_HOME``; else ``$NUMBA_CACHE_DIR``."""
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env.update({"XDG_CACHE_HOME": str(tmp_path / "xdg")} if where == "default" else
               {"NUMBA_CACHE_DIR": str(tmp_path / "cache")})
    cold = _run(integrator, env, model)
    warm = _run(integrator, env, model)
    root = tmp_path / "xdg" / "flexmm" / "numba" if where == "default" else tmp_path / "cache"
    assert cold["misses"] >= 1 and cold["cache_dir"] == str(root)
    if where == "default":  # the stepper's kernels are saved under their modules' keyed directories
        assert any(root.glob("flexmm.integrators.verlet*-*/**/*.nbi"))
    assert warm["misses"] == 0 and warm["hits"] >= 1
    assert warm["q"] == cold["q"] and warm["v"] == cold["v"]  # bit for bit
    assert model != "sheet" or cold["kernel"] == "sheet_verlet_advance"
    assert model != "graded" or cold["kernel"].startswith("chain_verlet_advance")
    assert warm["compile_s"] < cold["compile_s"]
    print(f"{integrator}: compile {cold['compile_s']:.2f} s cold, {warm['compile_s']:.3f} s from cache")


def test_unwritable_cache_location_falls_back_then_turns_caching_off(tmp_path, monkeypatch) -> None:
    import tempfile

    from flexmm import _jit

    blocked = tmp_path / "file"
    blocked.write_text("not a directory")
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(blocked / "cache"))
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "tmp"))
    (tmp_path / "tmp").mkdir()
    where, keyed, note = _jit._choose_cache_dir()
    assert str(where).startswith(str(tmp_path / "tmp")) and keyed
    assert "is not writable" in note and "cached in" in note
    monkeypatch.setattr(tempfile, "tempdir", str(blocked))
    where, keyed, note = _jit._choose_cache_dir()
    assert where is None and "not cached" in note and "NUMBA_CACHE_DIR" in note


def test_default_cache_directory_is_one_per_module_keyed_by_its_sources(tmp_path, monkeypatch) -> None:
    from flexmm import _jit

    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    root = tmp_path / "flexmm" / "numba"
    old = root / "0000"
    old.mkdir(parents=True)
    os.utime(old, (0, 0))  # unused for decades: pruned
    where, keyed, note = _jit._choose_cache_dir()
    assert where == root and keyed and note == ""
    assert not old.exists()
    monkeypatch.setattr(_jit, "CACHE_DIR", where)
    monkeypatch.setattr(_jit, "CACHE_KEYED", True)
    module = "flexmm.models.hinge"
    stale, recent, other = (root / f"{module}-{'0' * 16}", root / f"{module}-{'1' * 16}",
                            root / f"flexmm.models.laws-{'0' * 16}")
    for d in (stale, recent, other):
        d.mkdir()
    os.utime(stale, (0, 0))
    os.utime(other, (0, 0))
    assert _jit.module_cache_dir(module) == root / f"{module}-{_jit.module_key(module)}"
    assert (root / f"{module}-{_jit.module_key(module)}").is_dir()
    assert not stale.exists() and recent.exists() and other.exists()  # only the module's own old versions


def test_a_module_cache_directory_is_found_once_per_process(tmp_path, monkeypatch) -> None:
    """Each kernel of a module asks for its directory; the cache root is listed (pruned) once per
    module, not once per kernel (hundreds of directories × hundreds of kernels cost ~0.4 s an import)."""
    from flexmm import _jit

    monkeypatch.setattr(_jit, "CACHE_DIR", tmp_path)
    monkeypatch.setattr(_jit, "CACHE_KEYED", True)
    listed = []
    monkeypatch.setattr(_jit, "prune_cache", lambda root, keep=None: listed.append(root))
    first = [_jit.module_cache_dir("flexmm.models.hinge") for _ in range(5)]
    assert first == [tmp_path / f"flexmm.models.hinge-{_jit.module_key('flexmm.models.hinge')}"] * 5
    assert first[0].is_dir() and len(listed) == 1
    _jit.module_cache_dir("flexmm.models.laws")
    assert len(listed) == 2


#: every module with compiled kernels, and which of them a change to one module's source must
#: recompile (read off their imports: the chain laws reach the integrators through
#: models.kernels; the hinge law reaches the sheet, the loads and the gradient kernels)
COMPILED = ["flexmm._trig", "flexmm.models.laws", "flexmm.models.mass_kernels", "flexmm.models.hinge",
            "flexmm.models.sheet_kernels", "flexmm.models.ligaments", "flexmm.models.loads",
            "flexmm.models.kernels", "flexmm.integrators.rk4", "flexmm.integrators.verlet",
            "flexmm.integrators.verlet_chain", "flexmm.design.kernels", "flexmm.design.kernels_extra",
            "flexmm.design.sweeps"]
EDITS = {
    "flexmm.models.laws": {"flexmm.models.laws", "flexmm.models.mass_kernels", "flexmm.models.kernels",
                           "flexmm.integrators.rk4", "flexmm.integrators.verlet", "flexmm.integrators.verlet_chain",
                           "flexmm.design.kernels", "flexmm.design.sweeps"},
    "flexmm.integrators.rk4": {"flexmm.integrators.rk4"},
    "flexmm.integrators.verlet": {"flexmm.integrators.verlet", "flexmm.integrators.verlet_chain",
                                  "flexmm.design.sweeps"},  # the gradient's sweeps step with verlet.step
    "flexmm.design.kernels_extra": {"flexmm.design.kernels_extra", "flexmm.design.kernels", "flexmm.design.sweeps"},
    "flexmm._jit": set(COMPILED),
}


@pytest.mark.parametrize("edited", sorted(EDITS))
def test_editing_one_module_changes_the_cache_keys_of_its_importers_only(edited) -> None:
    from flexmm import _jit

    def edit(name):
        source, imports = _jit._source_and_imports(name)
        return (source + b"\n# edited\n" if name == edited else source), imports

    before = {m: _jit.module_key(m) for m in COMPILED}
    after = {m: _jit.module_key(m, sources=edit) for m in COMPILED}
    assert {m for m in COMPILED if after[m] != before[m]} == EDITS[edited]


def test_module_imports_resolves_relative_and_submodule_imports() -> None:
    from flexmm._jit import module_imports

    source = b"""
import numpy as np
import flexmm._trig
from . import laws
from .hinge import param
from ..integrators import common
from flexmm.models import kernels as k
def later():
    from flexmm._jit import fma
"""
    assert module_imports("flexmm.models.fake", source) == {
        "flexmm._trig", "flexmm.models.laws", "flexmm.models.hinge", "flexmm.integrators.common",
        "flexmm.models.kernels", "flexmm._jit"}


TWICE = """
from flexmm._jit import jit


@jit
def scaled(x):
    return {factor} * x
"""
PROBE = ("import json, ctmod; ctmod.scaled(1.0); s = ctmod.scaled.stats; "
         "print(json.dumps([sum(s.cache_hits.values()), sum(s.cache_misses.values())]))")


def test_checkouts_of_the_same_sources_share_the_compiled_code(tmp_path) -> None:
    """Two copies of a module in different directories (two checkouts, or a checkout and an
    installation) use one keyed directory: the second loads what the first compiled; a copy whose
    text differs compiles its own."""
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["XDG_CACHE_HOME"] = str(tmp_path / "xdg")
    counts = []
    for name, factor in (("a", "2.0"), ("b", "2.0"), ("c", "3.0")):
        (tmp_path / name).mkdir()
        (tmp_path / name / "ctmod.py").write_text(TWICE.format(factor=factor))
        out = subprocess.run([sys.executable, "-c", PROBE], cwd=tmp_path / name, env=env, capture_output=True,
                             text=True, timeout=600)
        assert out.returncode == 0, out.stderr[-3000:]
        counts.append(json.loads(out.stdout.strip().splitlines()[-1]))
    assert counts == [[0, 1], [1, 0], [0, 1]]  # (hits, misses): compiled, loaded, compiled
    assert len(list((tmp_path / "xdg" / "flexmm" / "numba").glob("ctmod-*"))) == 2



HOLD = r"""
import fcntl, os, time, ctmod, numba
compile_ = ctmod.scaled.compile
fd = os.open(compile_.lock_path, os.O_CREAT | os.O_RDWR)
fcntl.flock(fd, fcntl.LOCK_EX)  # as a process compiling ctmod.scaled holds it
print("held", flush=True)
while not os.path.exists("go"):
    time.sleep(0.05)
compile_.unlocked((numba.float64,))  # compiles and saves
os.close(fd)
"""
WAIT = ("import json, ctmod; print('calling', flush=True); ctmod.scaled(1.0); s = ctmod.scaled.stats; "
        "print(json.dumps([sum(s.cache_hits.values()), sum(s.cache_misses.values())]))")


def test_a_kernel_another_process_is_compiling_is_loaded_not_compiled_again(tmp_path) -> None:
    """Two processes on one empty cache (two test workers, a sweep's workers): while one holds a
    function's compile lock, the other waits, then loads what it saved (one compile, not two)."""
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["XDG_CACHE_HOME"] = str(tmp_path / "xdg")
    (tmp_path / "ctmod.py").write_text(TWICE.format(factor="2.0"))
    run = {"cwd": tmp_path, "env": env, "stdout": subprocess.PIPE, "text": True}
    with subprocess.Popen([sys.executable, "-c", HOLD], **run) as holder:
        assert holder.stdout.readline().strip() == "held"
        with subprocess.Popen([sys.executable, "-c", WAIT], **run) as waiter:
            assert waiter.stdout.readline().strip() == "calling"
            time.sleep(2.0)  # unlocked, the waiter would have compiled by now
            assert waiter.poll() is None
            (tmp_path / "go").touch()
            out = waiter.stdout.read()
        assert holder.wait(timeout=600) == 0 and waiter.wait(timeout=600) == 0
    assert json.loads(out.strip().splitlines()[-1]) == [1, 0]  # (hits, misses): loaded


def test_constants_passed_through_runtime_compile_the_callee_once() -> None:
    """numba compiles a function once per constant passed to it (a literal type); through
    ``_jit.runtime`` the constants share one compiled copy (what the fused chain kernel relies on)."""
    import numba
    import numpy as np

    from flexmm._jit import runtime

    @numba.njit
    def pick(x, flip, k):
        return -x[k] if flip else x[k]

    @numba.njit
    def through_runtime(x):
        return pick(x, runtime(True), runtime(0)) + pick(x, runtime(False), runtime(1))

    @numba.njit
    def as_constants(x):
        return pick(x, True, 0) + pick(x, False, 1)

    x = np.array([2.0, 5.0])
    assert through_runtime(x) == 3.0 and len(pick.signatures) == 1
    assert as_constants(x) == 3.0 and len(pick.signatures) == 3  # a copy per pair of constants
