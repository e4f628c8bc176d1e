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
                         text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    return {**json.loads(out.stdout.strip().splitlines()[-1]), "stderr": out.stderr}


@pytest.mark.parametrize(("integrator", "model"), [("velocity_verlet", "graded"),
                                                   pytest.param("velocity_verlet", "chain", marks=pytest.mark.slow),
                                                   pytest.param("pefrl", "chain", marks=pytest.mark.slow),
                                                   pytest.param("velocity_verlet", "sheet", marks=pytest.mark.slow)])
def test_second_process_loads_the_stepper_from_cache_bit_identically(integrator, model, tmp_path) -> None:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    cold = _run(integrator, env, model)
    warm = _run(integrator, env, model)
    assert cold["misses"] >= 1 and cold["cache_dir"] == str(tmp_path / "cache")
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
    where, note = _jit._choose_cache_dir()
    assert str(where).startswith(str(tmp_path / "tmp")) and "is not writable" in note and "cached in" in note
    monkeypatch.setattr(tempfile, "tempdir", str(blocked))
    where, note = _jit._choose_cache_dir()
    assert where is None and "not cached" in note and "NUMBA_CACHE_DIR" in note


def test_default_cache_directory_is_keyed_by_the_kernel_sources(tmp_path, monkeypatch) -> None:
    from flexmm import _jit

    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    old = tmp_path / "flexmm" / "numba" / "0000"
    old.mkdir(parents=True)
    os.utime(old, (0, 0))  # unused for decades: pruned
    where, note = _jit._choose_cache_dir()
    assert where == tmp_path / "flexmm" / "numba" / _jit.source_key() and note == ""
    assert not old.exists()
