"""A damping ratio that damps a scene's waves far more than it says is warned about.

``damping.viscous.damping_ratio`` ζ gives every DOF the decay rate γ = 2ζω_ref, ω_ref the model's
reference frequency (docs/physics.md §3). A Hertz chain without precompression has no stiffness at
rest; its ω_ref is the contact stiffness at 100 % strain, far above any frequency of its waves, so
ζ = 0.02 damped a struck chain's pulse within a few sites, silently, on the old code.
"""

from __future__ import annotations

from flexmm.assemble import build_problem
from flexmm.config import load_scene, scene_from_dict
from flexmm.plan import make_plan
from flexmm.prepare import prepare


def warnings(problem) -> list[str]:
    return [n for n in problem.notes if n.startswith("WARNING") and "damping_ratio" in n]


def test_a_ratio_that_overdamps_a_sonic_vacuum_chain_is_warned_about() -> None:
    scene = load_scene("configs/hertz_granular_impact.yaml", ["damping.viscous.damping_ratio=0.02"])
    for problem in (build_problem(scene), prepare(make_plan(scene))):  # the default run keeps it too
        (w,) = warnings(problem)
        ratio = problem.system.omega_ref / problem.omega_max
        assert ratio > 2  # ω_ref at 100 % strain against the struck chain's own top frequency
        assert f"at least {0.02 * ratio:.3g}" in w


def test_no_warning_where_the_ratio_means_what_it_says() -> None:
    linear = {"name": "lin", "lattice": {"kind": "mass_chain", "n_units": 30, "spacing_m": 0.01, "mass_kg": 0.01,
                                         "bond": {"law": "linear", "k_n_per_m": 1e4}},
              "excitation": {"kind": "impact", "end": "left", "velocity_m_s": 0.1},
              "damping": {"viscous": {"damping_ratio": 0.02}},
              "solver": {"duration_s": 0.01, "accuracy": None}}
    assert warnings(build_problem(scene_from_dict(linear))) == []
    precompressed = load_scene("configs/hertz_granular_impact.yaml",
                               ["damping.viscous.damping_ratio=0.02", "lattice.bond.precompression_m=1e-6",
                                "lattice.right=fixed", "solver.accuracy=null"])
    assert warnings(build_problem(precompressed)) == []
