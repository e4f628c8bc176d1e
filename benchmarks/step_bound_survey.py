"""The step bound over the shipped scenes (issue 37): for each, ω_max by the whole-lattice solve
(``linalg.top_eigenvalue``, what a run of that size uses) against the window lower bound and the
Gershgorin upper bound of ``linalg.banded_bounds`` (None: not banded within its probe budget).

    python benchmarks/step_bound_survey.py [CONFIG ...]
"""
import sys, glob, time, math, numpy as np
from flexmm.config.loader import load_scene
from flexmm.assemble import build_system
from flexmm.stability import dynamical_operator, reached_state
from flexmm.linalg import top_eigenvalue, banded_bounds, DENSE_LIMIT
files = sys.argv[1:] or sorted(glob.glob(str(__import__('pathlib').Path(__file__).resolve().parents[1] / 'configs' / '*.yaml')))
for f in files:
    try:
        scene = load_scene(f)
        system, terms = build_system(scene)
    except Exception as e:
        print(f"{f.split('/')[-1]:45s} skip {type(e).__name__}: {str(e)[:60]}"); continue
    rest = system.rest_state
    q_ref = None if rest is None else np.concatenate([rest, system.q0[rest.size:]])
    for tag, q in (("rest", q_ref), ("hit", reached_state(system, terms, q_ref))):
        if q is None and tag == "hit": continue
        op, free = dynamical_operator(system, terms, q)
        t0=time.perf_counter(); lam = top_eigenvalue(op, system.ndof, free, DENSE_LIMIT); t1=time.perf_counter()
        b = banded_bounds(op, system.n_sites, system.ndof); t2=time.perf_counter()
        if b is None:
            print(f"{f.split('/')[-1]:45s} {tag:4s} ndof {system.ndof:7d} lam {lam:.6g} not banded ({t1-t0:.2f}s, {t2-t1:.2f}s)")
        else:
            lo, up = b
            print(f"{f.split('/')[-1]:45s} {tag:4s} ndof {system.ndof:7d} w {math.sqrt(max(lam,0)):.6g} wL/w {math.sqrt(max(lo,0))/math.sqrt(max(lam,1e-300)):.5f} wU/w {math.sqrt(max(up,0))/math.sqrt(max(lam,1e-300)):.5f} wU/wL {math.sqrt(up/lo) if lo>0 else float('nan'):.4f} ({t1-t0:.2f}s, {t2-t1:.2f}s)")
