"""Linkage transition wave (Fig. 1k): where its front is steady and where it is not (slow).

docs/scenes.md quotes the numbers. Damping only the rotations (dissipation in the hinges) gives a
front of constant speed over most of the strip; damping every DOF at the same rate (the shipped
scene: a drag on the translating, still folded remainder) makes it slow down mid-strip.
"""
import numpy as np
import pytest
from mass_chain_helpers import crossing_times
from rigid_scene_checks import run

pytestmark = pytest.mark.slow

# the rotation rate of damping_ratio 0.02, γ = 2ζ sqrt(k_pin/m), as a coefficient γ J (J = m L²/12)
ROTATION_ONLY = "damping.viscous={coefficient_n_s_per_m: 0.0, rotational_coefficient_n_m_s: 1.8856e-5}"


def _stretch_speeds(tmp_path, overrides):
    scene, ds, _ = run("k_linkage_transition_wave", tmp_path, overrides + ["output.n_frames=1501"])
    lat = scene.lattice
    switched = ds["theta"].values[:, : lat.n_cols] / (lat.theta_deployed_rad - lat.theta0_rad)
    arrival = crossing_times(ds["time"].values, switched, 0.5)
    speeds = []
    for a in (10, 30, 50):
        cols = np.arange(a, a + 20)
        speeds.append(np.polyfit(arrival[cols], cols, 1)[0])
    return np.asarray(speeds)


def test_linkage_front_steady_with_hinge_damping_only(tmp_path):
    steady = _stretch_speeds(tmp_path / "rot", [ROTATION_ONLY])
    assert np.ptp(steady) < 0.01 * steady.mean()  # columns 10-70: one speed within 1 %
    drag = _stretch_speeds(tmp_path / "all", [])
    assert drag[1] < 0.5 * drag[0] and drag.max() < 0.5 * steady.mean()
