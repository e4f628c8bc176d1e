"""Every integrator through the controller (``run_scene``): datasets, attrs, dense frames, threads."""

from __future__ import annotations

import numpy as np
import pytest
from integrator_helpers import LEGO

from flexmm.api import run_scene
from flexmm.config import scene_from_dict
from flexmm.integrators import INTEGRATORS
from flexmm.io.run_dataset import open_run


def impact_scene(integrator: str, damped: bool | None = None, **solver) -> dict:
    """An impact on a 40-unit chain, damped unless the method takes no velocity-dependent forces."""
    damped = INTEGRATORS[integrator].velocity_dependent_forces if damped is None else damped
    return {
        "name": f"impact_{integrator}",
        "lattice": dict(LEGO, n_units=40, left="driven"),
        "excitation": {"kind": "impact", "end": "left", "velocity_m_s": 1.0, "angular_velocity_rad_s": 100.0},
        **({"damping": {"viscous": {"damping_ratio": 0.005}, "dashpot_n_s_per_m": 0.2}} if damped else {}),
        "solver": {"integrator": integrator, "duration_s": 0.01, **solver},
        "output": {"n_frames": 41},
    }


@pytest.mark.parametrize("name", list(INTEGRATORS))
def test_run_scene_with_each_integrator(name, tmp_path) -> None:
    result = run_scene(scene_from_dict(impact_scene(name)), run_dir=tmp_path)
    assert result.ok, result.reason
    ds = open_run(result.path)
    assert ds.attrs["integrator"] == name and ds.sizes["time"] == 41
    assert ds.attrs["force_evaluations"] > 0 and ds.attrs["threads"] == 1
    t_end, dt = ds.time.values[-1], ds.attrs["dt_s"]
    assert 0.01 * (1 - 1e-9) <= t_end < 0.01 + ds.attrs["frame_interval_s"]  # the last frame at or past the end
    assert abs(t_end / dt - round(t_end / dt)) < 1e-6  # ... after whole steps of dt
    # energy ledger: E(t) + dissipated = E(0) to the method's accuracy (no drive)
    e = ds.total_energy.values + ds.dissipated_energy.values
    assert np.max(np.abs(e - e[0])) < 5e-3 * e[0]
    if INTEGRATORS[name].adaptive:
        assert ds.attrs["rtol"] == 1e-6 and "rejected_steps" in ds.attrs


def test_all_integrators_agree_on_the_impact(tmp_path) -> None:
    def final_theta(name, damped):
        solver = {"rtol": 1e-9} if INTEGRATORS[name].adaptive else {"dt_fraction": 0.05}
        scene = impact_scene(name, damped, **solver)
        scene["output"]["exact_frame_times"] = True  # compare at the same times: steps fitted to the frames
        result = run_scene(scene_from_dict(scene), run_dir=tmp_path / f"{name}_{damped}")
        return open_run(result.path).theta.values[-1]

    refs = {}
    for name, spec in INTEGRATORS.items():
        damped = spec.velocity_dependent_forces
        if damped not in refs:
            refs[damped] = final_theta("dopri5", damped)
        th = final_theta(name, damped)
        print(f"{name}: max |θ − θ_dopri5| = {np.max(np.abs(th - refs[damped])):.3g} rad (damped: {damped})")
        assert np.max(np.abs(th - refs[damped])) < 1e-4
