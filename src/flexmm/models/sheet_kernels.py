"""Compiled kernels of the 2D rotating-squares sheet (and the linkage): ``SheetArgs``, force, energy.

The hinge law of ``hinge.py`` over the sheet's hinge list (``rotating_sheet`` documents the
geometry), plus the extra terms of the rigid-unit family, each over its own arrays: point
dipoles (``magnets``), bistable joints (``joints``) and constant loads (``loads``).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from flexmm._jit import jit
from flexmm._trig import sincos
from flexmm.models.hinge import H_HALF_A, H_HALF_B, H_KL, H_KS, H_KT, H_REST, H_SIGN, hinge_law
from flexmm.models.joints import joint_reference, joint_terms
from flexmm.models.loads import load_reference, load_terms
from flexmm.models.magnets import dipole_reference, dipole_terms


@jit
def _angles(q, theta0, cs, sn):
    """cos/sin of θ0 + θ per site into the scratch ``cs``, ``sn`` (N,).

    Two simple loops over a view from 0 so that both vectorise (``_trig.sincos``); with
    libm's scalar sin/cos this pass cost as much as the hinge loop (benchmarks/).
    """
    n = theta0.shape[0]
    th = q[2 * n : 3 * n]
    for i in range(n):
        cs[i] = theta0[i] + th[i]
    for i in range(n):
        s, c = sincos(cs[i])
        cs[i] = c
        sn[i] = s


class SheetArgs(NamedTuple):
    """What the sheet kernels read (``sheet_force``, ``sheet_energy``; also the linkage's).

    ``hinge_a``/``hinge_b`` (H,) joined units, ``hinge_axis`` (H,) 0 for an x hinge, 1 for y,
    ``hinge_prm`` (H, 7) law parameters, ``theta0`` (N,) rest angles, ``cos``/``sin`` (N,)
    scratch, ``dipoles`` (``magnets.empty_dipoles``), ``joints`` (``linkage.empty_joints``),
    ``loads`` (``predeform.empty_loads``: constant generalised forces).
    """

    hinge_a: np.ndarray
    hinge_b: np.ndarray
    hinge_axis: np.ndarray
    hinge_prm: np.ndarray
    theta0: np.ndarray
    cos: np.ndarray
    sin: np.ndarray
    dipoles: tuple
    joints: tuple
    loads: tuple


@jit
def _hinges(q, args, out, want_force):
    ha, hb, hax, hprm, theta0, cs, sn = args[:7]
    n = theta0.shape[0]
    total = 0.0
    for h in range(ha.shape[0]):
        a = ha[h]
        b = hb[h]
        if hax[h] == 0:
            la, lb, sa, sb = a, b, n + a, n + b
        else:
            la, lb, sa, sb = n + a, n + b, a, b
        e, fl, fs, gA, gB = hinge_law(
            q[lb] - q[la], q[sb] - q[sa], q[2 * n + a], q[2 * n + b], cs[a], sn[a], cs[b], sn[b], hprm[h]
        )
        total += e
        if want_force:
            out[la] += fl
            out[lb] -= fl
            out[sa] += fs
            out[sb] -= fs
            out[2 * n + a] -= gA
            out[2 * n + b] -= gB
    return total


@jit
def sheet_force(q, args, out):
    """Generalised forces −∂E/∂q of the sheet (hinges + dipoles + joints + loads) into ``out``."""
    theta0, cs, sn = args[4], args[5], args[6]
    for k in range(out.shape[0]):
        out[k] = 0.0
    _angles(q, theta0, cs, sn)
    _hinges(q, args, out, True)
    dipole_terms(q, args[7], out, True)
    joint_terms(q, theta0.shape[0], args[8], out, True)
    load_terms(q, args[9], out, True)


@jit
def sheet_energy(q, args):
    """Potential energy of the sheet (same arguments as ``sheet_force``)."""
    theta0, cs, sn = args[4], args[5], args[6]
    _angles(q, theta0, cs, sn)
    dummy = np.empty(0)
    return (_hinges(q, args, dummy, False) + dipole_terms(q, args[7], dummy, False)
            + joint_terms(q, theta0.shape[0], args[8], dummy, False) + load_terms(q, args[9], dummy, False))


def sheet_reference(q: np.ndarray, args: tuple) -> tuple[float, np.ndarray]:
    """Numpy version of the sheet energy and forces (vectorised over hinges), for the tests."""
    ha, hb, hax, hprm, theta0 = args[:5]
    n = theta0.size
    u, v, th = q[:n], q[n : 2 * n], q[2 * n : 3 * n]
    c, s = np.cos(theta0 + th), np.sin(theta0 + th)
    horiz = hax == 0
    dl = np.where(horiz, u[hb] - u[ha], v[hb] - v[ha])
    ds = np.where(horiz, v[hb] - v[ha], u[hb] - u[ha])
    p = hprm.T
    el = dl + p[H_REST] - (p[H_HALF_A] * c[ha] + p[H_HALF_B] * c[hb])
    es = ds + p[H_SIGN] * (p[H_HALF_B] * s[hb] - p[H_HALF_A] * s[ha])
    ep = th[ha] + th[hb]
    energy = 0.5 * float(np.sum(p[H_KL] * el**2 + p[H_KS] * es**2 + p[H_KT] * ep**2))
    fl, fs, fp = p[H_KL] * el, p[H_KS] * es, p[H_KT] * ep
    f = np.zeros_like(q)
    la, lb = np.where(horiz, ha, n + ha), np.where(horiz, hb, n + hb)
    sa, sb = np.where(horiz, n + ha, ha), np.where(horiz, n + hb, hb)
    np.add.at(f, la, fl)
    np.add.at(f, lb, -fl)
    np.add.at(f, sa, fs)
    np.add.at(f, sb, -fs)
    np.add.at(f, 2 * n + ha, -(fl * p[H_HALF_A] * s[ha] - fs * p[H_SIGN] * p[H_HALF_A] * c[ha] + fp))
    np.add.at(f, 2 * n + hb, -(fl * p[H_HALF_B] * s[hb] + fs * p[H_SIGN] * p[H_HALF_B] * c[hb] + fp))
    for e_f in (dipole_reference(q, args[7]), joint_reference(q, n, args[8]), load_reference(q, args[9])):
        energy += e_f[0]
        f += e_f[1]
    return energy, f


# ---------------------------------------------------------------- geometry
