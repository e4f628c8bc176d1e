"""A pull on the loaded end forms one rarefaction vector soliton (configs/predeformed_rarefaction_pull.yaml).

Slow: runs the scene. Measured against the prestressed theory (flexmm.theory.prestressed): the
leading pulse's speed is steady and its amplitude is the one the law gives at that speed; its
width is the exact soliton's. The pull's impulse is compared with the impulse the missing left
half of an infinite chain exerts on the end unit while the exact soliton passes (computed here with
the chain's own force kernel). docs/scenes.md quotes the measured values.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from rigid_scene_checks import peak, run
from scipy import optimize
from test_predeformed_scenes import _exact_fwhm_sites, _fwhm

from flexmm.analysis.context import RunContext
from flexmm.analysis.features.rest import from_rest, rest_fields
from flexmm.assemble import build_system
from flexmm.models.kernels import model_force
from flexmm.models.rotating_chain import theory_parameters
from flexmm.theory.prestressed import prestressed_chain, soliton_window
from flexmm.theory.rotating import soliton_initial_state, soliton_speed

pytestmark = pytest.mark.slow

BIG = 0.3  # rad: a pulse of the soliton window (−0.404…−0.346 rad) is deeper than this


def _leading_pulse(theta: np.ndarray):
    """Per frame: position, signed height and FWHM of the furthest pulse deeper than BIG, and the
    largest |Δθ| more than 10 units behind it (NaN when there is none)."""
    out = np.full((theta.shape[0], 4), np.nan)
    for i, row in enumerate(theta):
        big = np.flatnonzero(np.abs(row) > BIG)
        if big.size == 0 or big[-1] + 20 >= row.size:
            continue
        lo = max(big[-1] - 12, 1)
        pos, amp = peak(row[lo : big[-1] + 6])
        out[i] = pos + lo, amp, _fwhm(row[lo : big[-1] + 20]), np.abs(row[: max(lo - 10, 1)]).max()
    return out


def _cut_impulse(system, p, A: float, per_site: int = 20) -> float:
    """∫ F dt (N s) that the left half of an infinite chain exerts on unit 0 while the exact soliton
    of amplitude A passes it: F = m ü − f(q) on the longitudinal DOF of the cut chain (f with its
    load; the hinges are nearest-neighbour, so only units 0 and 1 of the soliton state matter).
    The soliton is sampled at ``per_site`` centres per unit and moved by whole units (it is a
    travelling wave), from 30 units before the end to 30 after."""
    n, rest, sc = system.n_sites, system.rest_state, system.scales
    states = [soliton_initial_state(p, A, 200, 100 + j / per_site, 1) for j in range(per_site)]
    u, th, du, dth = [], [], [], []
    for K in range(30, -31, -1):  # the centre at j/per_site − K: units 0, 1 read units K + 100, K + 101
        for U, Th, dU, dT in states:
            u.append(U[K + 100 : K + 102])
            th.append(Th[K + 100 : K + 102])
            du.append(dU[K + 100])
    dt = 1.0 / (per_site * float(soliton_speed(p, A)) / p.eta)  # T per sample
    acc = np.gradient(np.asarray(du), dt)
    q, f = rest.copy(), np.zeros(2 * n)
    force = np.empty(len(u))
    for k in range(len(u)):
        q[0:2], q[n : n + 2] = rest[0:2] + u[k], rest[n : n + 2] + th[k]
        model_force(q, system.args, f)
        force[k] = acc[k] / system.inv_mass[0] - f[0]
    return float(np.trapezoid(force, dx=dt)) * sc.force * sc.time_s


def test_scene_a_pull_forms_one_rarefaction_soliton_on_the_prestressed_law(tmp_path):
    scene, ds, _ = run("predeformed_rarefaction_pull", tmp_path)
    lat, exc = scene.lattice, scene.excitation
    system, _ = build_system(scene)
    n = system.n_sites
    p = prestressed_chain(theory_parameters(lat), float(system.rest_state[n + n // 2]))
    theta = from_rest(ds, rest_fields(RunContext.from_dataset(ds)))["theta"].values
    t = ds["time"].values / math.sqrt(lat.mass_kg / lat.k_long_n_per_m)
    pos, amp, fwhm, wake = _leading_pulse(theta).T
    sel = (pos > 40) & (pos < n - 40)
    assert pos[sel].max() - pos[sel].min() > 140  # tracked over 140+ units
    # one pulse in the window, ahead of a slow, shallow wake
    assert all(np.sum(np.diff((np.abs(r) > BIG).astype(int)) == 1) == 1 for r in theta[sel])
    assert np.nanmax(wake[sel]) < 0.25
    c = np.polyfit(t[sel], pos[sel], 1)[0]  # units per sqrt(m/k_l)
    stretches = [np.polyfit(t[m], pos[m], 1)[0] for m in
                 (sel & (pos >= s) & (pos < s + 50) for s in (40, 90, 140))]
    assert np.ptp(stretches) < 0.01 * c  # steady speed
    A = amp[sel].mean()
    lo, hi = soliton_window(p, -1)  # (the window's shallow and deep ends)
    assert hi < amp[sel].min() and amp[sel].max() < lo  # inside the window throughout ...
    assert np.ptp(amp[sel]) < 0.12 * abs(A)  # ... breathing by at most ±6 %
    A_at_c = optimize.brentq(lambda a: float(soliton_speed(p, a)) / p.eta - c, hi + 1e-4, lo - 1e-4)
    assert A == pytest.approx(A_at_c, rel=0.02)  # the law's amplitude at the measured speed
    assert np.nanmean(fwhm[sel]) == pytest.approx(_exact_fwhm_sites(p, A_at_c), rel=0.15)
    # the pull carries about the soliton's impulse at the cut
    pull = 2 * exc.amplitude_n * exc.duration_s / math.pi
    assert pull == pytest.approx(_cut_impulse(system, p, A_at_c), rel=0.15)
