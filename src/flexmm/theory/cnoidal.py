"""Cnoidal (periodic travelling) waves of theta'' = C0 + C1 theta + C2 theta^2 + C3 theta^3 (docs/physics.md §1.3).

The first integral theta'^2 = P(theta) = C3 theta^4/2 + 2 C2 theta^3/3 + C1 theta^2 + 2 C0 theta + E is a
quartic; a periodic wave oscillates between two adjacent real roots lo < hi with P > 0 between them,
and is a Jacobi elliptic function of zeta (Byrd & Friedman, Handbook of Elliptic Integrals, 252-259).
With a = C3/2 and the other two roots r3, r4:

- a < 0, r3, r4 real and below lo (reflect theta -> -theta when both lie above hi): with
  e1 = hi > e2 = lo > e3 > e4, m = (e1-e2)(e3-e4)/((e1-e3)(e2-e4)), u = sqrt(-a (e1-e3)(e2-e4)) zeta/2,
  theta = [e2 (e1-e3) - e3 (e1-e2) sn^2 u]/[(e1-e3) - (e1-e2) sn^2 u], wavelength 2K(m)/(du/dzeta).
  The dn wave of docs/physics.md §1.3 (C0 = C2 = 0, C1 > 0, C3 < 0) is this case.
- a < 0, r3,4 = b +- i d: A^2 = (hi-b)^2 + d^2, B^2 = (lo-b)^2 + d^2, m = [(hi-lo)^2 - (A-B)^2]/(4AB),
  u = sqrt(-a A B) zeta, theta = [(lo A + hi B) + (lo A - hi B) cn u]/[(A+B) + (A-B) cn u],
  wavelength 4K(m)/sqrt(-a A B). The cn wave of docs/physics.md §1.3.
- a > 0, roots e1 > hi = e2 > lo = e3 > e4: m = (e2-e3)(e1-e4)/((e1-e3)(e2-e4)),
  u = sqrt(a (e1-e3)(e2-e4)) zeta/2, theta = [e3 (e2-e4) - e4 (e2-e3) sn^2 u]/[(e2-e4) - (e2-e3) sn^2 u],
  wavelength 2K(m)/(du/dzeta). The sn wave of docs/physics.md §1.3.

m -> 0 is a sinusoid (phonon); m -> 1 a train of solitons (or kinks) separated by ever longer flats.
m is the parameter of the sn^2 (resp. cn) form above: the KdV cnoidal parameter (e1-e2)/(e1-e3) when
C3 -> 0 (e4 -> -inf), the m of docs/physics.md §1.3 for its cn wave, and that m after a Landen
transformation for its dn wave, ((1 - sqrt(1-m))/(1 + sqrt(1-m)))^2, and sn wave, 4 sqrt(m)/(1 + sqrt(m))^2.
Profiles are returned with the crest at zeta = 0. Pure numpy/scipy; the rotating-chain application
(a driven wave at given frequency, with the mean-force condition) is driven_wave below.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from scipy import special


class CnoidalWave(NamedTuple):
    """A periodic solution of theta'^2 = P(theta): coefficients (C0..C3), energy E, band, modulus m.

    kind: 'real' (four real roots, a < 0), 'complex' (a complex root pair) or 'inner' (a > 0);
    wavelength in zeta units; roots: (4,) complex, the roots of P.
    """

    coefficients: tuple[float, float, float, float]
    energy: float
    trough: float
    crest: float
    m: float
    wavelength: float
    kind: str
    roots: np.ndarray

    def profile(self, zeta):
        """theta(zeta), crest at zeta = 0; shape of zeta."""
        return _profile(self, np.asarray(zeta, dtype=float))

    def harmonics(self, n: int = 4, samples: int = 1024) -> np.ndarray:
        """Mean and amplitudes of harmonics 1..n over one wavelength: (n + 1,) [mean, |H1|, ...]."""
        th = self.profile(np.arange(samples) * self.wavelength / samples)
        F = np.fft.rfft(th) / samples
        return np.concatenate([[F[0].real], 2 * np.abs(F[1 : n + 1])])


def quartic(C, E, theta):
    """P(theta) = C3 theta^4/2 + 2 C2 theta^3/3 + C1 theta^2 + 2 C0 theta + E; shape of theta."""
    C0, C1, C2, C3 = C
    th = np.asarray(theta, dtype=float)
    return (((0.5 * C3 * th + 2.0 * C2 / 3.0) * th + C1) * th + 2.0 * C0) * th + E


def cnoidal_through(C, crest: float) -> CnoidalWave:
    """The periodic wave of theta'' = C0 + C1 theta + C2 theta^2 + C3 theta^3 whose crest is `crest`.

    E = -P(crest) without E; the trough is the next real root below the crest. ValueError if P is not
    positive just below the crest (no oscillation has that crest) or the band is unbounded.
    """
    C0, C1, C2, C3 = (float(c) for c in C)
    E = -float(quartic((C0, C1, C2, C3), 0.0, crest))
    if C3 == 0:
        raise ValueError("C3 = 0: the first integral is cubic, not quartic")
    roots = np.roots([0.5 * C3, 2.0 * C2 / 3.0, C1, 2.0 * C0, E])
    real = np.sort(roots[np.abs(roots.imag) <= 1e-9 * max(1.0, np.abs(roots).max())].real)
    k = int(np.argmin(np.abs(real - crest)))
    if k == 0 or not quartic((C0, C1, C2, C3), E, 0.5 * (real[k] + real[k - 1])) > 0:
        raise ValueError(f"no periodic wave with crest {crest}: P <= 0 below it")
    hi, lo = float(crest), float(real[k - 1])
    return _classify((C0, C1, C2, C3), E, lo, hi, np.asarray(_remove(roots, (hi, lo))), roots)


def _remove(roots, edges) -> list:
    """The roots left after removing the one nearest to each edge."""
    r = list(roots)
    for edge in edges:
        r.pop(int(np.argmin([abs(x - edge) for x in r])))
    return r


def _classify(C, E, lo, hi, others, roots) -> CnoidalWave:
    a = 0.5 * C[3]
    if np.all(np.abs(others.imag) <= 1e-9 * max(1.0, np.abs(others).max())):
        r3, r4 = sorted(others.real, reverse=True)
        if a < 0 and r3 < lo:
            m, _, lam = _real_band(a, hi, lo, r3, r4)
            kind = "real"
        elif a < 0 and r4 > hi:  # reflected: -theta oscillates in [-hi, -lo] above -r4 > -r3
            m, _, lam = _real_band(a, -lo, -hi, -r4, -r3)
            kind = "real_reflected"
        elif a > 0 and r4 < lo and r3 > hi:
            e1, e2, e3, e4 = r3, hi, lo, r4
            m = (e2 - e3) * (e1 - e4) / ((e1 - e3) * (e2 - e4))
            lam = 2 * float(special.ellipk(m)) / (0.5 * math.sqrt(a * (e1 - e3) * (e2 - e4)))
            kind = "inner"
        else:
            raise ValueError("the band between the roots is unbounded")
    else:
        if a > 0:
            raise ValueError("C3 > 0 with a complex root pair: the band is unbounded")
        b, d = float(others[0].real), abs(float(others[0].imag))
        A, B = math.hypot(hi - b, d), math.hypot(lo - b, d)
        m = ((hi - lo) ** 2 - (A - B) ** 2) / (4 * A * B)
        lam = 4 * float(special.ellipk(m)) / math.sqrt(-a * A * B)
        kind = "complex"
    return CnoidalWave(tuple(C), E, lo, hi, float(min(max(m, 0.0), 1.0)), lam, kind, roots)


def _real_band(a, e1, e2, e3, e4):
    """(m, du/dzeta, wavelength) of the a < 0 band [e2, e1] above the roots e3 > e4."""
    m = (e1 - e2) * (e3 - e4) / ((e1 - e3) * (e2 - e4))
    rate = 0.5 * math.sqrt(-a * (e1 - e3) * (e2 - e4))
    return m, rate, 2 * float(special.ellipk(min(max(m, 0.0), 1.0))) / rate


def _complex(w: CnoidalWave, a: float, r3: complex, r4: complex, zeta: np.ndarray) -> np.ndarray:
    """The profile of a wave whose other two roots are complex."""
    hi, lo = w.crest, w.trough
    b, d = r3.real, abs(r3.imag)
    A, B = math.hypot(hi - b, d), math.hypot(lo - b, d)
    K = float(special.ellipk(w.m))
    _, cn, _, _ = special.ellipj(math.sqrt(-a * A * B) * zeta + 2 * K, w.m)  # cn = -1 at the crest
    return ((lo * A + hi * B) + (lo * A - hi * B) * cn) / ((A + B) + (A - B) * cn)


def _inner(w: CnoidalWave, a: float, r3: complex, r4: complex, zeta: np.ndarray) -> np.ndarray:
    """The profile of a wave in the band between the two other real roots."""
    r3, r4 = sorted((r3.real, r4.real), reverse=True)
    e1, e2, e3, e4 = r3, w.crest, w.trough, r4
    sn, _, _, _ = special.ellipj(0.5 * math.sqrt(a * (e1 - e3) * (e2 - e4)) * zeta + float(special.ellipk(w.m)), w.m)
    s2 = sn * sn
    return (e3 * (e2 - e4) - e4 * (e2 - e3) * s2) / ((e2 - e4) - (e2 - e3) * s2)


def _band(sign: float):
    """The profile of a wave in the a < 0 band above the two other real roots (``sign`` −1: the
    reflected band, theta = −psi with psi in [−crest, −trough])."""
    def profile(w: CnoidalWave, a: float, r3: complex, r4: complex, zeta: np.ndarray) -> np.ndarray:
        r3, r4 = sorted((r3.real, r4.real), reverse=True)
        hi, lo = w.crest, w.trough
        e1, e2, e3, e4 = (hi, lo, r3, r4) if sign > 0 else (-lo, -hi, -r4, -r3)
        _, rate, _ = _real_band(a, e1, e2, e3, e4)
        shift = float(special.ellipk(w.m)) if sign > 0 else 0.0  # crest of theta: psi = e1 (sn^2 = 1) or e2 (sn = 0)
        sn, _, _, _ = special.ellipj(rate * zeta + shift, w.m)
        s2 = sn * sn
        return sign * (e2 * (e1 - e3) - e3 * (e1 - e2) * s2) / ((e1 - e3) - (e1 - e2) * s2)
    return profile


#: a wave's ``kind`` -> its ``profile(wave, a, r3, r4, zeta)`` (r3, r4: the roots other than crest and trough)
PROFILES = {"complex": _complex, "inner": _inner, "real": _band(1.0), "real_reflected": _band(-1.0)}


def _profile(w: CnoidalWave, zeta: np.ndarray) -> np.ndarray:
    r3, r4 = _remove(w.roots, (w.crest, w.trough))
    return PROFILES[w.kind](w, 0.5 * w.coefficients[3], r3, r4, zeta)


# ---------------------------------------------------------------- driven waves of the rotating chain
class DrivenWave(NamedTuple):
    """Steady periodic wave of a rotating-squares chain at drive frequency omega (nondimensional).

    c: phase speed (X units per T; c/eta sites per T); mean_stretch: G-bar, the orbit average of
    G(theta) fixed by the mean-force condition; wave: the cnoidal solution in zeta = X - cT.
    """

    c: float
    mean_stretch: float
    wave: CnoidalWave


def wave_coefficients(p, c: float, mean_stretch: float) -> tuple[float, float, float, float]:
    """(C0, C1, C2, C3) of a periodic travelling wave whose time-averaged hinge force is that of rest.

    Derivation: travelling, the longitudinal equation integrates to c^2 U' = eta (eta U' + G) + K;
    for a solitary wave K = 0 (rest ahead). A periodic wave from a force drive carries the mean
    applied force, i.e. the perturbation of the hinge stretch w = eta U' + G averages to zero, which
    fixes K = -c^2 G-bar/eta and w = sigma (G - G-bar), sigma = c^2/(c^2 - eta^2). The reduced
    potential gains -sigma G-bar G(theta); with G = s0 theta + eta theta^2/2 - s0 theta^3/6 + ... and
    D = D_full(0) (flexmm.theory.rotating) this adds, with k = sigma G-bar, k s0/D, k eta/D,
    -k s0/(2D) and -k eta/(6D) to C0..C3 (C0 = 0 and the C1..C3 of docs/physics.md §1.3 at G-bar = 0).
    """
    from flexmm.theory import rotating as rt

    C1, C2, C3 = rt.continuum_coefficients(p, c, "full")
    D = float(rt.gradient_coefficient(p, c, 0.0, "full")[0])
    k = c * c / (c * c - p.eta**2) * mean_stretch
    return (k * p.s0 / D, C1 + k * p.eta / D, C2 - k * p.s0 / (2 * D), C3 - k * p.eta / (6 * D))


def linear_speed(p, omega: float) -> float:
    """Phase speed c of small waves at frequency omega: omega = c sqrt(-C1(c)), the slowest root above
    the long-wave speed (lower branch; ValueError if none below the longitudinal speed eta)."""
    from scipy import optimize

    from flexmm.theory import rotating as rt

    def mismatch(c):
        C1 = rt.continuum_coefficients(p, c, "full")[0]
        return c * math.sqrt(-C1) - omega if C1 < 0 else math.nan

    grid = np.geomspace(rt.long_wave_speed(p) * (1 + 1e-9), p.eta * (1 - 1e-6), 400)
    g = np.array([mismatch(c) for c in grid])
    up = np.flatnonzero((g[:-1] < 0) & (g[1:] >= 0))
    if up.size == 0:
        raise ValueError(f"no linear wave of frequency {omega} below the longitudinal speed")
    return optimize.brentq(mismatch, grid[up[0]], grid[up[0] + 1], xtol=1e-15, rtol=1e-13)


def _wave_at(p, omega: float, crest: float, guess: tuple[float, float]) -> DrivenWave:
    """Solve wavelength = 2 pi c/omega and <G> = G-bar for (c, G-bar) at a given crest (from guess)."""
    from scipy import optimize

    from flexmm.theory import rotating as rt

    def residual(x):
        c, gbar = x
        try:
            w = cnoidal_through(wave_coefficients(p, c, gbar), crest)
        except ValueError:
            return [1.0, 1.0]
        th = w.profile(np.arange(256) * w.wavelength / 256)
        return [w.wavelength * omega / (2 * math.pi * c) - 1, float(np.mean(rt.hinge_stretch(p, th))) - gbar]

    (c, gbar), info, ok, msg = optimize.fsolve(residual, guess, full_output=True, xtol=1e-12)
    if ok != 1 or max(abs(r) for r in residual((c, gbar))) > 1e-9:
        raise ValueError(f"no driven wave with crest {crest} at omega = {omega}: {msg}")
    return DrivenWave(float(c), float(gbar), cnoidal_through(wave_coefficients(p, c, gbar), crest))


def driven_wave(p, omega: float, amplitude: float, steps: int = 40) -> DrivenWave:
    """The steady wave of fundamental amplitude `amplitude` (|H1| of theta) at drive frequency omega.

    p: RotatingChainND (prestressed or not, theta0 != 0 for a first-order coupling to the drive);
    omega = 2 pi f sqrt(m/k_l). Continues the family from the linear wave (crest -> 0, c =
    linear_speed) in `steps` crest increments with the mean-force condition (wave_coefficients),
    then solves |H1| = amplitude for the crest. ValueError when the family ends first.
    """
    from scipy import optimize

    if not amplitude > 0:
        raise ValueError(f"amplitude must be > 0, got {amplitude}")
    guess = (linear_speed(p, omega), 0.0)
    crest, prev = 0.0, None
    step = 1.5 * amplitude / steps
    while True:
        crest += step
        wave = _wave_at(p, omega, crest, guess)
        guess = (wave.c, wave.mean_stretch)
        h1 = wave.wave.harmonics(1)[1]
        if h1 >= amplitude:
            break
        prev = (crest, guess)
        if crest > 50 * amplitude:
            raise ValueError(f"the driven-wave family does not reach amplitude {amplitude}")
    lo, g0 = prev if prev is not None else (0.5 * step, guess)

    def gap(x):
        return _wave_at(p, omega, x, g0).wave.harmonics(1)[1] - amplitude

    best = optimize.brentq(gap, lo, crest, xtol=1e-12)
    return _wave_at(p, omega, best, g0)


def wave_with_mean(p, omega: float, amplitude: float, mean: float, steps: int = 60) -> DrivenWave:
    """The steady wave at omega with fundamental |H1| = `amplitude` and mean rotation `mean`.

    The family of periodic travelling waves at a given frequency has two parameters: the amplitude
    and the constant of the integrated longitudinal equation (the mean hinge force). A force drive
    fixes that constant (wave_coefficients); behind a displacement drive it is set by the mean-flow
    transient at the wave's front, which the steady theory does not determine, so here the measured
    mean rotation closes the family instead. Continued from the linear wave (amplitude and mean
    scaled together over `steps` steps, secant predictor); mean_stretch is returned in the force
    convention of wave_coefficients. ValueError when the continuation fails.
    """
    from scipy import optimize

    def solve(x0, amp, avg):
        def residual(x):
            c, gbar, crest = x
            try:
                w = cnoidal_through(wave_coefficients(p, c, gbar), crest)
            except ValueError:
                return [1.0, 1.0, 1.0]
            m0, h1 = w.harmonics(1)[:2]
            return [w.wavelength * omega / (2 * math.pi * c) - 1, h1 / amp - 1, (m0 - avg) / amp]

        x, _, ok, msg = optimize.fsolve(residual, x0, full_output=True, xtol=1e-12)
        if ok != 1 or max(abs(r) for r in residual(x)) > 1e-9:
            raise ValueError(f"no periodic wave of amplitude {amp} and mean {avg} at omega = {omega}: {msg}")
        return np.asarray(x)

    s_grid = np.linspace(0.05, 1.0, steps)
    hist = [solve(np.array([linear_speed(p, omega), 0.0, s_grid[0] * amplitude]), s_grid[0] * amplitude,
                  s_grid[0] * mean)]
    for s in s_grid[1:]:
        guess = hist[-1] if len(hist) < 2 else 2 * hist[-1] - hist[-2]
        hist.append(solve(guess, s * amplitude, s * mean))
    c, gbar, crest = hist[-1]
    return DrivenWave(float(c), float(gbar), cnoidal_through(wave_coefficients(p, c, gbar), crest))
