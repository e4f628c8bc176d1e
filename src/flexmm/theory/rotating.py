"""Analytical theory of the rotating-squares chain (docs/physics.md §1.1, §1.3, §1.4).

Everything is nondimensional (docs/physics.md §1.1): U = u/a, T = t sqrt(k_l/m), positions X = x/a,
speeds in units of c0 = a sqrt(k_l/m). Site n sits at X_n = n cos(theta0) (spacing h = a cos theta0),
so a speed c in X units is c / cos(theta0) sites per unit T. Travelling coordinate zeta = X - cT.

Gradient models: 'constant' uses the commonly quoted constant D(c) (the Klein-Gordon C1..C3, docs/physics.md §1.3);
'full' (default for exact profiles) keeps the theta dependence of the gradient coefficient derived in
exact_soliton. Both give the same exact speed law; 'full' agrees with the discrete chain far better
(and, unlike the constant D(c), with the exact linear dispersion when theta0 != 0).

A chain held in a rotated state by an external load (theta_s != 0, see flexmm.theory.prestressed for
the derivation) is the stress-free chain of rest angle theta0 plus the on-site potential
W(theta) = gamma theta_s [theta - G(theta)/s0]; the speed law, exact profiles, continuum
coefficients and linear dispersion below include it.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from scipy import integrate, optimize, special


@dataclass(frozen=True)
class RotatingChainND:
    """Nondimensional rotating-squares chain parameters (docs/physics.md §1.1).

    theta0: rest angle [rad]; Ks = k_s/k_l; Ktheta = k_theta/(k_l a^2); alpha2 = J/(m a^2);
    n_v: lateral hinges per unit (0, 1, 2); s_v: 1 if lateral contraction is blocked.
    theta_s: part of theta0 held by an external load (prestress, flexmm.theory.prestressed); 0 for a
    stress-free chain. Then theta0 is the loaded equilibrium angle and theta is measured from it.
    """

    theta0: float
    Ks: float
    Ktheta: float
    alpha2: float
    n_v: int = 0
    s_v: int = 0
    theta_s: float = 0.0

    def __post_init__(self):
        if not abs(self.theta0) < math.pi / 2:
            raise ValueError(f"|theta0| must be < pi/2, got {self.theta0}")
        if self.alpha2 <= 0 or self.Ks < 0 or self.Ktheta < 0:
            raise ValueError("need alpha2 > 0, Ks >= 0, Ktheta >= 0")
        if self.n_v not in (0, 1, 2) or self.s_v not in (0, 1):
            raise ValueError(f"n_v must be 0, 1 or 2 and s_v 0 or 1, got {self.n_v}, {self.s_v}")
        if self.theta_s != 0 and self.theta0 == 0:
            raise ValueError("a prestressed chain (theta_s != 0) needs theta0 != 0")

    @classmethod
    def from_si(cls, a_m, theta0_rad, k_long, k_shear, k_rot, mass, inertia, n_v=0, s_v=0):
        """Build from SI values: a [m], k_long, k_shear [N/m], k_rot [N m/rad], mass [kg], inertia [kg m^2]."""
        return cls(theta0=float(theta0_rad), Ks=k_shear / k_long, Ktheta=k_rot / (k_long * a_m**2),
                   alpha2=inertia / (mass * a_m**2), n_v=int(n_v), s_v=int(s_v))

    @property
    def eta(self) -> float:
        """cos(theta0)."""
        return math.cos(self.theta0)

    @property
    def s0(self) -> float:
        """sin(theta0)."""
        return math.sin(self.theta0)

    @property
    def gamma(self) -> float:
        """gamma = (4 + 2 n_v) Ktheta (docs/physics.md §1.3)."""
        return (4 + 2 * self.n_v) * self.Ktheta

    @property
    def gradient_stiffness(self) -> float:
        """Lambda = (Ks eta^2 - s0^2 - 4 Ktheta)/4: linear gradient stiffness per site^2 (constant D(c), docs/physics.md §1.3)."""
        return (self.Ks * self.eta**2 - self.s0**2 - 4 * self.Ktheta) / 4


def lego_parameters(theta0: float = 0.0, n_v: int = 1, s_v: int = 0) -> RotatingChainND:
    """LEGO chain of Deng et al. 2017/2018 (docs/physics.md §1.1), nondimensional.

    Ks = 1.851e-2, Ktheta = 1.534e-4/4, alpha2 = 1/(4 * 1.815^2). The default n_v = 1, s_v = 0
    reproduces Deng 2017's torsional term k_theta(theta_{i+1} + 4 theta_i + theta_{i-1}).
    """
    return RotatingChainND(theta0=theta0, Ks=1.851e-2, Ktheta=1.534e-4 / 4,
                           alpha2=1.0 / (4 * 1.815**2), n_v=n_v, s_v=s_v)


def _g(p: RotatingChainND, theta):
    """G(theta)/theta = sin(theta0 + theta/2) sinc(theta/2), free of cancellation at small theta."""
    theta = np.asarray(theta, dtype=float)
    return np.sin(p.theta0 + theta / 2) * np.sinc(theta / (2 * np.pi))


def hinge_stretch(p: RotatingChainND, theta):
    """G(theta) = cos(theta0) - cos(theta0 + theta) (docs/physics.md §1.3); same shape as theta."""
    return np.asarray(theta, dtype=float) * _g(p, theta)


def _prestress(p: RotatingChainND, theta):
    """(2 W/theta^2, W') of the prestress potential W = gamma theta_s [theta - G/s0]; shapes of theta.

    theta - G/s0 = (theta - sin theta) - (eta/s0)(1 - cos theta); both zero when theta_s = 0.
    """
    th = np.asarray(theta, dtype=float)
    if p.theta_s == 0:
        return np.zeros_like(th), np.zeros_like(th)
    k, r = p.gamma * p.theta_s, p.eta / p.s0
    small = np.abs(th) < 1e-3
    t = np.where(small, 1.0, th)
    cubic = np.where(small, th / 6 - th**3 / 120, (t - np.sin(t)) / t**2)  # (theta - sin theta)/theta^2
    w2 = 2 * k * (cubic - r * 0.5 * np.sinc(th / (2 * np.pi)) ** 2)
    return w2, k * (1 - np.sin(p.theta0 + th) / p.s0)


def continuum_coefficients(p: RotatingChainND, c: float, gradient: str = "constant"):
    """(C1, C2, C3) of theta'' = C1 theta + C2 theta^2 + C3 theta^3 at speed c (docs/physics.md §1.3).

    C1 = -(gamma + S s0^2)/D, C2 = -(3/2) S s0 eta/D, C3 = -S(eta^2/2 - 2 s0^2/3)/D with
    S = c^2/(c^2 - eta^2) + n_v s_v/2 and D = the constant D(c) of docs/physics.md §1.3; gradient='full' uses D = D_full(0)
    from gradient_coefficient instead (correct linear tail for theta0 != 0). A prestress adds the
    Taylor terms of W' = k[-(eta/s0) theta + theta^2/2 + (eta/s0) theta^3/6], k = gamma theta_s:
    -k eta/s0, k/2 and k eta/(6 s0) to the brackets of C1, C2 and C3.
    """
    if abs(c * c - p.eta**2) < 1e-14:
        raise ValueError(f"c = {c} equals the longitudinal speed cos(theta0): S(c) is singular")
    S = c * c / (c * c - p.eta**2) + p.n_v * p.s_v / 2
    D = float(gradient_coefficient(p, c, 0.0, gradient)[0])
    if D == 0:
        raise ValueError(f"D = 0 at c = {c}: c is the rotational cut-off speed")
    k, r = p.gamma * p.theta_s, (p.eta / p.s0 if p.theta_s else 0.0)
    return (-(p.gamma - k * r + S * p.s0**2) / D, -(1.5 * S * p.s0 * p.eta + k / 2) / D,
            -(S * (p.eta**2 / 2 - 2 * p.s0**2 / 3) + k * r / 6) / D)


def soliton_width(p: RotatingChainND, c: float, gradient: str = "constant") -> float:
    """W = 1/sqrt(C1) in X units (docs/physics.md §1.3); ValueError when C1 <= 0 (no localized pulse)."""
    C1 = continuum_coefficients(p, c, gradient)[0]
    if not C1 > 0:
        raise ValueError(f"no soliton at c = {c}: C1 = {C1:.3g} <= 0 (tails do not decay)")
    return 1.0 / math.sqrt(C1)


def soliton_profile(p: RotatingChainND, c: float, zeta, branch: int = +1):
    """Cubic-truncation soliton theta = 1/(D1 +- D2 cosh(zeta/W)) (docs/physics.md §1.3); shape of zeta.

    A branch is regular iff sign(D1 +- D2) = +-1 (the denominator never vanishes); otherwise
    ValueError. For theta0 = 0 this is +-A sech(zeta/W), A^2 = -2 C1/C3.
    """
    if branch not in (1, -1):
        raise ValueError("branch must be +1 or -1")
    W = soliton_width(p, c)
    C1, C2, C3 = continuum_coefficients(p, c)
    D1 = -C2 / (3 * C1)
    D2sq = C2**2 / (9 * C1**2) - C3 / (2 * C1)
    if D2sq < 0:
        raise ValueError(f"no soliton at c = {c}: D2^2 = {D2sq:.3g} < 0")
    D2 = math.sqrt(D2sq)
    if not branch * (D1 + branch * D2) > 0:
        raise ValueError(f"branch {branch:+d} is singular at c = {c} (D1 = {D1:.3g}, D2 = {D2:.3g})")
    e = np.exp(-np.abs(np.asarray(zeta, dtype=float)) / W)
    return 2 * e / (2 * D1 * e + branch * D2 * (1 + e * e))


def soliton_speed(p: RotatingChainND, A):
    """Exact speed-amplitude law c = eta sqrt(Q/(1+Q)), Q = gamma A^2/G(A)^2 + n_v s_v/2 (§1.3).

    Written as c^2 = eta^2 (gamma + n_v s_v g^2/2)/(gamma + (1 + n_v s_v/2) g^2), g = G(A)/A, which is
    regular at A = 0 (c -> long_wave_speed). With a prestress gamma A^2 becomes gamma A^2 + 2 W(A)
    (flexmm.theory.prestressed); nan where that is negative. Shape of A. Existence is not checked
    (see soliton_exists).
    """
    g2 = _g(p, A) ** 2
    h = p.n_v * p.s_v / 2
    gam = p.gamma + _prestress(p, A)[0]
    with np.errstate(invalid="ignore"):
        return p.eta * np.sqrt((gam + h * g2) / (gam + (1 + h) * g2))


def long_wave_speed(p: RotatingChainND) -> float:
    """Small-amplitude limit of soliton_speed = long-wave speed of the lower linear branch (§1.3, §1.4)."""
    return float(soliton_speed(p, 0.0))


def rotational_cutoff_speed(p: RotatingChainND) -> float:
    """c_theta with D(c_theta) = 0: c_theta^2 = eta^2 Lambda/alpha2 (= (Ks/4 - Ktheta)/alpha2 at theta0 = 0).

    Returns 0.0 when Lambda <= 0 (then D(c) > 0 for every c > 0).
    """
    lam = p.gradient_stiffness
    return p.eta * math.sqrt(lam / p.alpha2) if lam > 0 else 0.0


def _turn(p, theta):
    """h = G - theta G'; zero where Q(A) is stationary (end of a monotone branch)."""
    return hinge_stretch(p, theta) - theta * np.sin(p.theta0 + theta)


def _branch(p: RotatingChainND, sign: int, branch: str) -> tuple[float, float]:
    """|A| interval on which c(A) is monotone, for polarity sign (see soliton_amplitude)."""
    if p.theta_s != 0:
        raise ValueError("branches are mapped for stress-free chains only (theta_s = 0); for a "
                         "prestressed chain use soliton_speed and soliton_exists")
    if sign not in (1, -1):
        raise ValueError("sign must be +1 or -1")
    t0, same = abs(p.theta0), sign * p.theta0 >= 0
    if branch == "short":
        if same:
            raise ValueError("the short branch exists only for polarity opposite to theta0 != 0")
        return 0.0, 2 * t0
    if branch != "main":
        raise ValueError(f"branch must be 'main' or 'short', got {branch!r}")
    lo, top = (0.0, math.pi - t0) if same else (2 * t0, math.pi + t0)
    end = optimize.brentq(lambda a: _turn(p, sign * a), max(lo, 1e-6), top, xtol=1e-14)
    return lo, end


def soliton_amplitude(p: RotatingChainND, c: float, sign: int = +1, branch: str = "main") -> float:
    """Invert the exact speed law for the signed amplitude A with c(A) = c (brentq).

    'main' branch: |A| from 0 (from 2|theta0| if sign opposes theta0) up to the stationary point of
    Q(A) (tan(A/2) = A, A ~ 2.33 at theta0 = 0); c decreases along it (larger pulses are slower).
    'short' branch (sign opposite to theta0 only): 0 < |A| < 2|theta0|, c increasing. ValueError when
    c lies outside the branch's speed range.
    """
    lo, hi = _branch(p, sign, branch)
    c_lo, c_hi = (float(soliton_speed(p, sign * a)) for a in (lo, hi))
    if not min(c_lo, c_hi) < c < max(c_lo, c_hi):
        raise ValueError(f"no {branch}-branch amplitude of sign {sign:+d} for c = {c}: "
                         f"speeds span ({min(c_lo, c_hi):.6g}, {max(c_lo, c_hi):.6g})")
    a = optimize.brentq(lambda x: float(soliton_speed(p, sign * x)) - c, lo, hi, xtol=1e-15, rtol=1e-15)
    return sign * a


def gradient_coefficient(p: RotatingChainND, c: float, theta, gradient: str = "full"):
    """D(theta) and dD/dtheta in the travelling-wave Lagrangian D(theta) theta'^2/2 - V(theta); shape of theta.

    'constant': constant D(c) = alpha2 c^2 - (eta^2/4)(Ks eta^2 - s0^2 - 4 Ktheta) (docs/physics.md §1.3).
    'full' (derived in exact_soliton): D(theta) = alpha2 c^2 + eta^2 [a_s sin^2(theta0+theta)
    - (Ks/4) cos^2(theta0+theta) + Ktheta], a_s = sigma/4 + c^2 eta^2/(12 (c^2-eta^2)^2), sigma = c^2/(c^2-eta^2).
    The two agree at theta0 = theta = 0; for theta0 != 0 only 'full' reproduces the tail decay rate
    given by the exact discrete dispersion (docs/physics.md §1.4) as c -> long_wave_speed.
    """
    th = np.asarray(theta, dtype=float)
    if gradient == "constant":
        return np.full_like(th, p.alpha2 * c * c - p.eta**2 * p.gradient_stiffness), np.zeros_like(th)
    if gradient != "full":
        raise ValueError(f"gradient must be 'full' or 'constant', got {gradient!r}")
    e2, d = p.eta**2, c * c - p.eta**2
    a_s = c * c / (4 * d) + c * c * e2 / (12 * d * d)
    ang = p.theta0 + th
    D = p.alpha2 * c * c + e2 * (a_s * np.sin(ang) ** 2 - p.Ks / 4 * np.cos(ang) ** 2 + p.Ktheta)
    return D, e2 * (a_s + p.Ks / 4) * np.sin(2 * ang)


def soliton_exists(p: RotatingChainND, A: float, gradient: str = "full", n_check: int = 4001) -> bool:
    """True if the first integral theta'^2 = f(theta) (see exact_soliton) has a pulse of amplitude A.

    Requires f > 0 between 0 and A (checked on n_check points, so C1 = f''(0)/2 > 0) and a simple
    turning point at A.
    """
    A = float(A)
    gA = float(_g(p, A)) if math.isfinite(A) else 0.0
    if A == 0 or gA == 0 or p.gamma == 0:
        return False
    c = float(soliton_speed(p, A))
    if not 0 < c < p.eta:
        return False
    th = A * np.linspace(0.0, 1.0, n_check)[:-1]
    (wA,), (dwA,) = _prestress(p, [A])
    gam = p.gamma + _prestress(p, th)[0]
    F = -(gam - (p.gamma + wA) * (_g(p, th) / gA) ** 2) / gradient_coefficient(p, c, th, gradient)[0]
    # f'(A) != 0, scaled to G - A G' (= _turn) when theta_s = 0
    turn = float(_turn(p, A)) + (dwA * gA - wA * A * float(np.sin(p.theta0 + A))) / p.gamma
    return bool(np.all(F > 0) and abs(turn) > 1e-12 * max(1.0, abs(A)))


def amplitude_gap(p: RotatingChainND, sign: int = +1) -> float:
    """Smallest |A| of a main-branch soliton of polarity sign (the amplitude gap, §1.3); 0.0 if no gap.

    Existence needs D(c) < 0 and C1 > 0, i.e. c < min(c_theta, long_wave_speed); A_min solves
    c(A_min) = that speed (c(A_min) = c_theta at theta0 = 0, gap iff alpha2 > Ks/4 - Ktheta).
    ValueError if no main-branch soliton of that polarity exists at all.
    """
    lo, hi = _branch(p, sign, "main")
    c_lim = min(rotational_cutoff_speed(p), long_wave_speed(p))
    c_start, c_end = float(soliton_speed(p, sign * lo)), float(soliton_speed(p, sign * hi))
    if c_lim >= c_start:
        return 0.0
    if c_lim <= c_end:
        raise ValueError(f"no main-branch soliton of sign {sign:+d}: needs c < {c_lim:.6g} <= {c_end:.6g}")
    return abs(soliton_amplitude(p, c_lim, sign))


class TravellingState(NamedTuple):
    """Sampled travelling pulse: U, theta, dU/dT, dtheta/dT, each of shape (n_sites,)."""

    U: np.ndarray
    theta: np.ndarray
    U_dot: np.ndarray
    theta_dot: np.ndarray


@functools.lru_cache(maxsize=64)
def _exact_solution(p: RotatingChainND, A: float, gradient: str):
    """The two integrations of ``_exact`` (core to θ = A/2, then the tail in ψ = ln θ/A), kept per
    (p, A, gradient): a run's analysis and its summary evaluate the same soliton several times."""
    if not soliton_exists(p, A, gradient):
        raise ValueError(f"no regular soliton of amplitude A = {A} for {p} (gradient={gradient!r})")
    c = float(soliton_speed(p, A))
    S = -(p.gamma + float(_prestress(p, A)[0])) / float(_g(p, A)) ** 2
    kU = p.eta / (c * c - p.eta**2)

    def F(th):  # f(theta)/theta^2
        return -(S * _g(p, th) ** 2 + p.gamma + _prestress(p, th)[0]) / gradient_coefficient(p, c, th, gradient)[0]

    C1 = float(F(0.0))

    def core(z, y):
        G = float(hinge_stretch(p, y[0]))
        D, dD = (float(v) for v in gradient_coefficient(p, c, y[0], gradient))
        dV = S * G * math.sin(p.theta0 + y[0]) + p.gamma * y[0] + float(_prestress(p, y[0])[1])
        return [y[1], -(dV + 0.5 * dD * y[1] ** 2) / D, kU * G]

    def tail(z, y):
        th = A * math.exp(y[0])
        return [-math.sqrt(max(float(F(th)), 0.0)), kU * float(hinge_stretch(p, th))]

    def half(z, y):
        return y[0] - 0.5 * A

    def deep(z, y):
        return y[0] + 45.0

    half.terminal = deep.terminal = True
    span = 1e6 / math.sqrt(C1)
    opts = dict(method="DOP853", rtol=1e-12, dense_output=True)
    s1 = integrate.solve_ivp(core, (0, span), [A, 0.0, 0.0], events=half, atol=1e-15 * abs(A), **opts)
    z1, (_, _, I1) = s1.t_events[0][0], s1.y_events[0][0]
    s2 = integrate.solve_ivp(tail, (z1, z1 + span), [math.log(0.5), I1], events=deep, atol=1e-14, **opts)
    z2, (psi2, I_inf) = s2.t_events[0][0], s2.y_events[0][0]
    return s1, s2, z1, z2, psi2, I_inf, C1, kU, F


def _exact(p: RotatingChainND, A: float, zeta, gradient: str):
    """theta, dtheta/dzeta, U' and U (U -> 0 as zeta -> +inf) of the first integral; shapes of zeta."""
    s1, s2, z1, z2, psi2, I_inf, C1, kU, F = _exact_solution(p, float(A), gradient)
    zeta = np.asarray(zeta, dtype=float)
    z = np.abs(zeta).ravel()
    th, dth, I = np.empty_like(z), np.empty_like(z), np.full_like(z, I_inf)
    m1, m3 = z <= z1, z > z2
    m2 = ~(m1 | m3)
    if m1.any():
        th[m1], dth[m1], I[m1] = s1.sol(z[m1])
    psi = np.zeros(0)
    if m2.any():
        psi, I[m2] = s2.sol(z[m2])
    th[m2] = A * np.exp(psi)
    dth[m2] = -th[m2] * np.sqrt(np.maximum(F(th[m2]), 0.0))
    th[m3] = A * np.exp(psi2 - math.sqrt(C1) * (z[m3] - z2))
    dth[m3] = -math.sqrt(C1) * th[m3]
    sgn = np.sign(zeta).ravel()
    out = (th, sgn * dth, kU * hinge_stretch(p, th), sgn * I - I_inf)
    return tuple(a.reshape(zeta.shape) for a in out)


def exact_soliton(p: RotatingChainND, A: float, zeta, gradient: str = "full"):
    """Soliton of the non-truncated continuum first integral: returns (theta, U'), each shaped like zeta.

    Derivation (docs/physics.md §1.1; sites n, X = n eta, sigma = c^2/(c^2 - eta^2)): expanding every hinge
    about its midpoint to second order in gradients, the energy per site is (U'+G)^2/2
    + (U'+G)(G''/8 + U'''/24) + (Ks/8)[(sin(theta0+theta))']^2 + 2 Ktheta theta^2 - Ktheta theta'^2/2
    + n_v (s_v G^2/4 + Ktheta theta^2). In a travelling wave U' is slaved, U' = eta G/(c^2 - eta^2); as
    this is a stationary point its gradient corrections do not enter the reduced Lagrangian at this
    order, which becomes L = D(theta) theta'^2/2 - V(theta), V = (S G^2 + gamma theta^2)/2, with D(theta)
    from gradient_coefficient. Its energy integral (theta -> 0 at infinity) is

        theta'^2 = f(theta) = -(S G(theta)^2 + gamma theta^2)/D(theta).

    The turning point f(A) = 0 fixes S = -gamma A^2/G(A)^2: the exact law c^2 = eta^2 Q/(1+Q), for
    either D. With gradient='constant' (constant D) the Euler-Lagrange equation D theta'' = -S G G'
    - gamma theta expands to the C1, C2, C3 of docs/physics.md §1.3. Solved by integrating D theta'' = -V' - D' theta'^2/2
    from (A, 0) to theta = A/2, then psi = ln(theta/A), psi' = -sqrt(f)/|theta| (stable in the tail);
    theta is even in zeta. ValueError when soliton_exists(p, A, gradient) is False; note that 'full'
    admits no near-sonic pulses (c -> cos theta0), where the slaving of U' and hence the expansion fail.
    """
    th, _, Up, _ = _exact(p, A, zeta, gradient)
    return th, Up


def soliton_initial_state(p: RotatingChainND, A: float, n_sites: int, center: float,
                          direction: int = +1, gradient: str = "full") -> TravellingState:
    """Exact-first-integral soliton sampled on sites n = 0..n_sites-1 (X_n = n eta), arrays (n_sites,).

    Pulse centred at site `center` moving in direction +1 (+x) or -1 (-x) at c = soliton_speed(p, A):
    theta = Theta(xi), U = direction Ucal(xi), xi = direction (X - X_c) - cT, Ucal' = eta G/(c^2 - eta^2),
    Ucal -> 0 ahead of the pulse. Velocities dU/dT = -c direction Ucal'(xi), dtheta/dT = -c Theta'(xi),
    i.e. exactly U_T = -direction c U_X and theta_T = -direction c theta_X.
    """
    if direction not in (1, -1):
        raise ValueError("direction must be +1 or -1")
    c = float(soliton_speed(p, A))
    xi = direction * (np.arange(n_sites, dtype=float) - center) * p.eta
    th, dth, Up, U = _exact(p, A, xi, gradient)
    return TravellingState(U=direction * U, theta=th, U_dot=-c * direction * Up, theta_dot=-c * dth)


def cnoidal_wave(p: RotatingChainND, c: float, m: float, kind: str, zeta):
    """Cnoidal wave of theta'' = C1 theta + C3 theta^3 (theta0 = 0, docs/physics.md §1.3): (theta, wavelength).

    'dn': P dn(kz|m), k^2 = C1/(2-m), P^2 = -2C1/(C3(2-m)), wavelength 2K(m)/k  (C1 > 0, C3 < 0);
    'cn': P cn(kz|m), k^2 = C1/(2m-1), P^2 = -2mC1/((2m-1)C3), wavelength 4K/k  (C1 > 0, C3 < 0, m > 1/2);
    'sn': P sn(kz|m), k^2 = -C1/(1+m), P^2 = -2mC1/((1+m)C3), wavelength 4K/k  (C1 < 0, C3 > 0).
    theta has the shape of zeta; all satisfy theta'^2 = C1 theta^2 + C3 theta^4/2 + E.
    """
    if p.theta0 != 0:
        raise ValueError("cnoidal waves are implemented for theta0 = 0 only (C2 = 0)")
    if not 0 <= m <= 1:
        raise ValueError(f"elliptic parameter m must be in [0, 1], got {m}")
    C1, _, C3 = continuum_coefficients(p, c)
    if kind not in CNOIDAL:
        raise ValueError(f"kind must be 'dn', 'cn' or 'sn', got {kind!r}")
    focusing, m_above, k2_P2, periods, which = CNOIDAL[kind]
    if not ((C1 > 0 and C3 < 0) if focusing else (C1 < 0 and C3 > 0)):
        signs = "C1 > 0 and C3 < 0" if focusing else "C1 < 0 and C3 > 0"
        raise ValueError(f"{kind} waves need {signs}, got C1={C1:.3g}, C3={C3:.3g}")
    if not m > m_above:
        raise ValueError(f"{kind} waves need m > 1/2")
    k2, P2 = k2_P2(C1, C3, m)
    k = math.sqrt(k2)
    jacobi = special.ellipj(k * np.asarray(zeta, dtype=float), m)  # sn, cn, dn, ph
    return math.sqrt(P2) * jacobi[which], periods * float(special.ellipk(m)) / k


#: ``cnoidal_wave``'s kinds: (C1 > 0 and C3 < 0 (else the opposite signs), m must exceed,
#: (C1, C3, m) -> (k², P²), wavelength in K(m)/k, index of the Jacobi function in (sn, cn, dn))
CNOIDAL = {
    "dn": (True, -1.0, lambda C1, C3, m: (C1 / (2 - m), -2 * 1 * C1 / ((2 - m) * C3)), 2.0, 2),
    "cn": (True, 0.5, lambda C1, C3, m: (C1 / (2 * m - 1), -2 * m * C1 / ((2 * m - 1) * C3)), 4.0, 1),
    "sn": (False, -1.0, lambda C1, C3, m: (-C1 / (1 + m), -2 * m * C1 / ((1 + m) * C3)), 4.0, 0),
}


def _kq(p: RotatingChainND, q):
    """Entries 4 sin^2(q/2), |K12|^2 = s0^2 sin^2 q and R(q) of the Bloch stiffness K(q) (§1.4)."""
    q = np.asarray(q, dtype=float)
    s2, c2 = np.sin(q / 2) ** 2, np.cos(q / 2) ** 2
    R = (p.s0**2 * c2 + p.Ks * p.eta**2 * s2 + 4 * p.Ktheta * c2
         + p.n_v * (p.s_v * p.s0**2 / 2 + 2 * p.Ktheta)
         - (p.gamma * p.theta_s * p.eta / p.s0 if p.theta_s else 0.0))  # W''(0) of a prestress
    return 4 * s2, (p.s0 * np.sin(q)) ** 2, R


def dispersion_chain(p: RotatingChainND, q):
    """Linear branches (Omega_lower, Omega_upper) of K(q) x = Omega^2 diag(1, alpha2) x (docs/physics.md §1.4).

    K = [[4 sin^2(q/2), -i s0 sin q], [i s0 sin q, R(q)]]; q is the phase per site. The 2x2
    generalized eigenproblem is solved in closed form. Both outputs have the shape of q.
    """
    k11, k12sq, R = _kq(p, q)
    det = k11 * R - k12sq
    b = p.alpha2 * k11 + R
    hi = (b + np.sqrt(np.maximum(b * b - 4 * p.alpha2 * det, 0.0))) / (2 * p.alpha2)
    lo = np.divide(det, p.alpha2 * hi, out=np.zeros_like(hi), where=hi > 0)
    return np.sqrt(np.maximum(lo, 0.0)), np.sqrt(np.maximum(hi, 0.0))


def dispersion_rotational(p: RotatingChainND, q):
    """Frequency of the predominantly rotational branch at each q (docs/physics.md §1.4); shape of q.

    Per q, takes the branch whose eigenvector has the larger rotational kinetic fraction
    alpha2 |Theta|^2/(|U|^2 + alpha2 |Theta|^2); at theta0 = 0 this is exactly Omega_theta.
    """
    k11, k12sq, R = _kq(p, q)

    def frac(om):  # eigenvector from whichever row of K - lam M gives the larger vector
        lam = om**2
        a = (k12sq, (lam - k11) ** 2)            # (|U|^2, |Theta|^2) from row 1
        b = ((R - p.alpha2 * lam) ** 2, k12sq)   # from row 2
        use_a = a[0] + a[1] >= b[0] + b[1]
        u2, t2 = np.where(use_a, a[0], b[0]), np.where(use_a, a[1], b[1])
        return p.alpha2 * t2 / np.maximum(u2 + p.alpha2 * t2, 1e-300)

    lo, hi = dispersion_chain(p, q)
    return np.where(frac(lo) > frac(hi), lo, hi)


def _extremum(fun, a: float, b: float, maximize: bool, n: int = 4097) -> float:
    """Extremum of a smooth scalar function on [a, b]: dense sampling, then bounded refinement."""
    q = np.linspace(a, b, n)
    v = fun(q) * (-1 if maximize else 1)
    i = int(np.argmin(v))
    lo, hi = q[max(i - 1, 0)], q[min(i + 1, n - 1)]
    res = optimize.minimize_scalar(lambda x: float(fun(x)) * (-1 if maximize else 1),
                                   bounds=(lo, hi), method="bounded", options={"xatol": 1e-12})
    best = min(v[i], res.fun)
    return float(-best if maximize else best)


def omega_max_chain(p: RotatingChainND) -> float:
    """Highest linear frequency max_q Omega_upper(q), q in [0, pi] (docs/physics.md §1.4)."""
    return _extremum(lambda q: dispersion_chain(p, q)[1], 0.0, math.pi, maximize=True)


class BandEdges(NamedTuple):
    """Linear band edges: lower branch [0, lower_max], upper branch [upper_min, upper_max]."""

    lower_max: float
    upper_min: float
    upper_max: float

    @property
    def gap(self) -> float:
        """Width of the band gap between the branches (0.0 if they overlap)."""
        return max(self.upper_min - self.lower_max, 0.0)


def band_edges(p: RotatingChainND) -> BandEdges:
    """Band edges of the two branches over q in [0, pi] (docs/physics.md §1.4)."""
    return BandEdges(_extremum(lambda q: dispersion_chain(p, q)[0], 0.0, math.pi, True),
                     _extremum(lambda q: dispersion_chain(p, q)[1], 0.0, math.pi, False),
                     omega_max_chain(p))


def min_phase_speed_rotational(p: RotatingChainND) -> float:
    """min over q in (0, pi] of the rotational-branch phase speed eta Omega_rot(q)/q, in X units (§1.3).

    Discrete pulses faster than this can resonate with rotational waves and radiate.
    """
    return _extremum(lambda q: p.eta * dispersion_rotational(p, q) / q, math.pi / 8192, math.pi, False)
