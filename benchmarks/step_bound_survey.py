"""The step bound over the shipped scenes (issue 37): ω_max by the whole-lattice solve
(``linalg.top_eigenvalue``: what a lattice of their size uses) against the bounds of
``linalg.banded_bounds`` that a lattice above ``stability.BOUND_MIN_DOFS`` uses — the window's lower
bound and the Gershgorin upper bound (with the margin the run uses) — or 'not banded'.

    python benchmarks/step_bound_survey.py [CONFIG ...]     # default: configs/*.yaml
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import numpy as np

from flexmm.assemble import build_system
from flexmm.config.loader import load_scene
from flexmm.linalg import DENSE_LIMIT, banded_bounds, top_eigenvalue
from flexmm.stability import BOUND_MARGIN, dynamical_operator, reached_state


def survey(path: Path) -> list[str]:
    system, terms = build_system(load_scene(path))
    rest = system.rest_state
    q_ref = None if rest is None else np.concatenate([rest, system.q0[rest.size:]])
    q_hit = reached_state(system, terms, q_ref)
    out = []
    for tag, q in (("rest", q_ref), ("hit", q_hit)):
        if tag == "hit" and q is None:
            continue
        op, free = dynamical_operator(system, terms, q)
        t0 = time.perf_counter()
        lam = top_eigenvalue(op, system.ndof, free, DENSE_LIMIT)
        t1 = time.perf_counter()
        b = banded_bounds(op, system.n_sites, system.ndof, (1 + BOUND_MARGIN) ** 2)
        t2 = time.perf_counter()
        w = math.sqrt(max(lam, 1e-300))
        head = f"{path.name:45s} {tag:4s} ndof {system.ndof:7d} ω {w:.6g}"
        if b is None:
            out.append(f"{head} not banded (solve {t1 - t0:.2f} s, bounds {t2 - t1:.2f} s)")
            continue
        lo, up = (math.sqrt(max(v, 0.0)) for v in b)
        verdict = "bound used" if up <= (1 + BOUND_MARGIN) * lo else "loose: whole-lattice solve"
        out.append(f"{head} lower/ω {lo / w:.5f} upper/ω {up / w:.5f} upper/lower {up / lo:.4f} {verdict} "
                   f"(solve {t1 - t0:.2f} s, bounds {t2 - t1:.2f} s)")
    return out


def main(argv: list[str]) -> None:
    root = Path(__file__).resolve().parents[1]
    for path in [Path(a) for a in argv] or sorted((root / "configs").glob("*.yaml")):
        try:
            print("\n".join(survey(path)), flush=True)
        except Exception as exc:  # noqa: BLE001 - a survey row, not a run
            print(f"{path.name:45s} skipped ({type(exc).__name__}: {str(exc)[:60]})")


if __name__ == "__main__":
    main(sys.argv[1:])
