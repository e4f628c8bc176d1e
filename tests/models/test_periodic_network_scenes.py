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


def test_the_rotation_interface_transmits_and_reflects_by_the_impedances(tmp_path):
    """θ0 = 0.05 meets θ0 = 0.3 (Z₂/Z₁ = 0.784): analyze's theory rows (the media's Bloch modes) for the
    incident, transmitted (1.121 × 0.1 mm) and reflected (+0.121 ×) pulses, within 0.5 %, 1 % and 2 %."""
    from flexmm.analysis.report.analyze import analyze_run as analyze

    _, _, res = run("network_rotation_interface", tmp_path)
    rows = [c for c in analyze(res.path, field_spec="u", threshold_fraction=0.05).comparisons
            if c.quantity == "amplitude" and c.predicted is not None]
    by_kind = {c.note.split(" ")[0].rstrip(":"): c for c in rows}
    assert by_kind["transmitted"].predicted == pytest.approx(1.1209e-4, rel=1e-3)
    assert by_kind["reflected"].predicted == pytest.approx(1.209e-5, rel=3e-3)
    for kind, tol in (("incident", 5e-3), ("transmitted", 1e-2), ("reflected", 2e-2)):
        assert abs(by_kind[kind].rel_diff) < tol, kind
