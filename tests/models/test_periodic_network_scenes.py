"""The shipped scenes of periodic networks and interfaces show what docs/scenes.md ("Periodic
networks, Bloch bands and interfaces") says, in numbers (slow: each runs its scene)."""

import numpy as np
import pytest
from rigid_scene_checks import run

from flexmm.analysis import analyze_run
from flexmm.linear.network import cell_lattice, network_bands
from flexmm.models.network import build

pytestmark = pytest.mark.slow


def test_the_torus_pulse_runs_at_its_bands_speed(tmp_path):
    """The acoustic branches' slopes at Γ along x are 19.75 and 44.25 m/s; the pulse launched at the
    faster runs at 44.28 m/s."""
    scene, _, res = run("network_bloch_torus", tmp_path)
    lat = scene.lattice
    scales = build(cell_lattice(lat)).scales
    k = 1e-4
    slopes = network_bands(lat, np.array([[k, 0.0]]))[0, :2] / k * scales.length_m / scales.time_s
    assert slopes == pytest.approx([19.75, 44.25], rel=1e-3)
    pulse = analyze_run(res.path, field_spec="u").pulses[0]
    assert pulse.speed_m_s == pytest.approx(slopes[1], rel=2e-3)


def test_the_interface_transmits_two_thirds_and_reflects_a_third(tmp_path):
    """Twice the impedance beyond the interface: transmitted 2/3 of the 0.1 mm at twice the speed,
    reflected −1/3 at the same speed."""
    _, _, res = run("network_interface", tmp_path)
    pulses = analyze_run(res.path, field_spec="u").pulses
    fast = max(pulses, key=lambda p: p.speed_m_s)
    back = min(pulses, key=lambda p: p.amplitude)
    assert fast.amplitude == pytest.approx(2 / 3 * 1e-4, rel=5e-3) and fast.speed_m_s == pytest.approx(127.46, rel=5e-3)
    assert back.amplitude == pytest.approx(-1 / 3 * 1e-4, rel=1e-2) and abs(back.speed_m_s) == pytest.approx(63.73, rel=5e-3)
