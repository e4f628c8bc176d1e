"""The same config gives the same numbers, bit for bit, whatever the state of numba's cache."""

import subprocess
import sys

import pytest

SCRIPT = """
import hashlib
from flexmm.assemble import build_problem
from flexmm.config import load_scene
from flexmm.integrators.runner import integrate
sc = load_scene("configs/lego_vector_soliton.yaml", ["lattice.n_units=60", "lattice.left=free", "damping.absorbing=null",
                "excitation={kind: soliton, amplitude_rad: 0.45, center_site: 8}", "solver.duration_s=0.06"])
p = build_problem(sc)
for name in ("velocity_verlet", "pefrl"):
    tr = integrate(p, name, h=p.dt, n_frames=11)
    print(name, hashlib.sha256(tr.q.tobytes() + tr.v.tobytes()).hexdigest())
"""


@pytest.mark.slow
def test_cold_and_warm_numba_cache_give_identical_bits(tmp_path):
    """A first process compiles every kernel (cold cache, kernels inlined as compiled), a second
    loads them from the cache: both must produce the same bits (no reassociation/contraction)."""
    from pathlib import Path

    repo = Path(__file__).resolve().parents[1]
    env = {"NUMBA_CACHE_DIR": str(tmp_path / "numba"), "PATH": "/usr/bin:/bin"}
    runs = [subprocess.run([sys.executable, "-c", SCRIPT], cwd=repo, env=env, capture_output=True,
                           text=True, timeout=600) for _ in range(2)]
    for r in runs:
        assert r.returncode == 0, r.stderr
    assert runs[0].stdout.split() == runs[1].stdout.split()
    assert (tmp_path / "numba").exists()  # the first run did write a cache the second one read
