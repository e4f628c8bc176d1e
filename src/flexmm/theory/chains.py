"""Analytical travelling waves in chains of point masses (docs/physics.md §2).

Chain: m x''_i = F(x_{i+1} - x_i) - F(x_i - x_{i-1}) - V'(x_i) - eta x'_i. Functions take plain floats
in any consistent unit system (a: spacing, m: mass, k: linear coupling stiffness); array arguments
broadcast and the outputs take their broadcast shape.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


def _sech2(z):
    """sech^2 z without overflow: 4 e^(-2|z|)/(1 + e^(-2|z|))^2."""
    e = np.exp(-2 * np.abs(z))
    return 4 * e / (1 + e) ** 2


# ---------------------------------------------------------------- bistable on-site fronts
@dataclass(frozen=True)
class BistableFront:
    """Steady transition front of the cubic bistable chain: released energy, speed, width, c0, jump L."""

    dphi: float
    v: float
    w: float
    c0: float
    L: float

    def profile(self, x, t=0.0):
        """u(x, t) = (L/2)(1 - tanh((x - vt)/w)); see bistable_front_profile."""
        return bistable_front_profile(x, t, self.L, self.v, self.w)


def bistable_front(alpha: float, beta: float, L: float, k: float, m: float, a: float,
                   eta: float) -> BistableFront:
    """Front of the chain with on-site force V'(u) = alpha u (u - beta L)(u - L), 0 < beta < 1/2 (§2).

    Continuum travelling wave (ka^2 - mv^2) u'' + eta v u' - V'(u) = 0 gives (derived, docs/physics.md §2):
    dphi = V(0) - V(L) = alpha L^4 (1 - 2 beta)/12, v = c0/sqrt(1 + 2 eta^2/(m alpha L^2 (1 - 2beta)^2)),
    w = sqrt(8 (k a^2 - m v^2)/(alpha L^2)), c0 = a sqrt(k/m). The front converts u = 0 (ahead) into
    u = L (behind). Without damping the continuum front degenerates (v = c0, w = 0). Discrete fronts
    only a few sites wide (w ~ a) pin instead (propagation failure).
    """
    if not 0 < beta < 0.5:
        raise ValueError(f"need 0 < beta < 1/2 for a forward-moving front, got {beta}")
    if min(alpha, L, k, m, a) <= 0 or eta < 0:
        raise ValueError("need alpha, L, k, m, a > 0 and eta >= 0")
    c0 = a * math.sqrt(k / m)
    v = c0 / math.sqrt(1 + 2 * eta**2 / (m * alpha * L**2 * (1 - 2 * beta) ** 2))
    w = math.sqrt(8 * max(k * a * a - m * v * v, 0.0) / (alpha * L * L))  # eta = 0: v = c0, w = 0
    return BistableFront(alpha * L**4 * (1 - 2 * beta) / 12, v, w, c0, L)


def bistable_front_profile(x, t, L: float, v: float, w: float):
    """u(x, t) = (L/2)(1 - tanh((x - v t)/w)) (docs/physics.md §2); broadcast shape of x and t."""
    return 0.5 * L * (1 - np.tanh((np.asarray(x, dtype=float) - v * np.asarray(t, dtype=float)) / w))


def front_kinetic_energy(m: float, v: float, dphi: float, eta: float, a: float) -> float:
    """Total kinetic energy carried by a steady damped front, K = m v dphi/(2 eta a) (Nadkarni PRB 2016, §2).

    Follows from power balance: released energy per unit time dphi v/a equals the dissipation
    2 eta K/m. Infinite for eta = 0.
    """
    return math.inf if eta == 0 else m * v * dphi / (2 * eta * a)


# ---------------------------------------------------------------- strain-softening chain
@dataclass(frozen=True)
class SechWave:
    """sech^2 solitary wave of a chain with bond tension T(D) = k1 D + k2 D^2.

    Dm: peak bond elongation (sign = polarity), v: speed [length/time], W: width [sites], c0 = a sqrt(k1/m).
    """

    Dm: float
    v: float
    W: float
    c0: float
    a: float = 1.0

    @property
    def polarity(self) -> int:
        """+1 for a tensile (rarefaction) pulse, -1 for a compressive one."""
        return 1 if self.Dm > 0 else -1

    def profile(self, n, t=0.0):
        """Bond elongation D_n(t) = Dm sech^2((n - v t/a)/W); broadcast shape of n and t."""
        return softening_profile(n, t, self.Dm, self.v, self.W, self.a)


def softening_solitary_wave(k1: float, k2: float, Dm: float, m: float = 1.0, a: float = 1.0) -> SechWave:
    """Long-wave solitary wave D = Dm sech^2((n - vt/a)/W) for T(D) = k1 D + k2 D^2 (docs/physics.md §2).

    From the Boussinesq limit m D_tt = a^2 [T(D) + (1/12) T(D)_nn]_nn (n in sites): travelling waves obey
    (k1/12) D'' = (m v^2/a^2 - k1) D - k2 D^2, giving v = c0 sqrt(1 + 2 k2 Dm/(3 k1)), c0 = a sqrt(k1/m),
    W = sqrt(k1/(2 k2 Dm)) sites. Requires sign(Dm) = sign(k2): softening under compression (k2 > 0)
    carries tensile (rarefaction) pulses. Valid for W >> 1 (|k2 Dm| << k1).
    """
    if k1 <= 0 or m <= 0 or a <= 0:
        raise ValueError("need k1, m, a > 0")
    if not k2 * Dm > 0:
        raise ValueError(f"no solitary wave: the pulse sign must equal sign(k2) (k2={k2}, Dm={Dm})")
    v = a * math.sqrt(k1 / m) * math.sqrt(1 + 2 * k2 * Dm / (3 * k1))
    return SechWave(Dm, v, math.sqrt(k1 / (2 * k2 * Dm)), a * math.sqrt(k1 / m), a)


def softening_profile(n, t, Dm: float, v: float, W: float, a: float = 1.0):
    """D_n(t) = Dm sech^2((n - v t/a)/W); broadcast shape of n and t."""
    z = (np.asarray(n, dtype=float) - v * np.asarray(t, dtype=float) / a) / W
    return Dm * _sech2(z)


# ---------------------------------------------------------------- FPU-β chain (mKdV)
def fpu_beta_solitary_wave(k1: float, k3: float, Dm: float, m: float = 1.0, a: float = 1.0) -> tuple[float, float]:
    """Speed v (length/time) and width W (sites) of the solitary wave D = Dm sech((n − vt/a)/W) of
    T(D) = k1 D + k3 D³ (docs/physics.md §2).

    Same Boussinesq limit as ``softening_solitary_wave``: (k1/12) D'' = (m v²/a² − k1) D − k3 D³,
    solved by sech with W = sqrt(k1/(6 k3))/|Dm| sites and v = c0 sqrt(1 + k3 Dm²/(2 k1)) (the
    mKdV soliton to first order in k3 Dm²/k1). Needs k3 > 0 (hardening); either polarity; W >> 1.
    """
    if k1 <= 0 or m <= 0 or a <= 0 or Dm == 0:
        raise ValueError("need k1, m, a > 0 and Dm != 0")
    if not k3 > 0:
        raise ValueError(f"no bright solitary wave of T = k1 D + k3 D³ with k3 = {k3} (needs k3 > 0)")
    return a * math.sqrt(k1 / m) * math.sqrt(1 + k3 * Dm**2 / (2 * k1)), math.sqrt(k1 / (6 * k3)) / abs(Dm)


# ---------------------------------------------------------------- Hertzian chain (Nesterenko)
def nesterenko_speed(A: float, m: float, D: float, xi_m: float) -> float:
    """Solitary-wave speed V = (2/sqrt 5) c xi_m^(1/4), c^2 = A D^(5/2)/m (Nesterenko; docs/physics.md §2).

    A: Hertz constant in F = A delta^(3/2); D: bead diameter; xi_m: peak strain (overlap/D).
    """
    return 2 / math.sqrt(5) * math.sqrt(A * D**2.5 / m) * xi_m**0.25


def nesterenko_precompressed_speed(A: float, m: float, D: float, xi_0: float, xi_m: float) -> float:
    """Solitary-wave speed on a chain precompressed to strain xi_0 (> 0), peak strain xi_m > xi_0
    (Nesterenko; docs/physics.md §2):

        V² = c² [(4/5)(xi_m^(5/2) − xi_0^(5/2)) − 2 xi_0^(3/2)(xi_m − xi_0)] / (xi_m − xi_0)²
           = c0² (4/15)(3 + 2 xi_r^(5/2) − 5 xi_r)/(xi_r − 1)²,   xi_r = xi_m/xi_0,

    from the long-wave equation of ``nesterenko_profile`` integrated twice with xi → xi_0 far from
    the wave (c² = A D^(5/2)/m; c0² = (3/2) c² xi_0^(1/2), the sound speed of the compressed chain,
    reached as xi_r → 1; xi_0 → 0 gives ``nesterenko_speed``).
    """
    if not (xi_0 > 0 and xi_m > xi_0):
        raise ValueError("a precompressed solitary wave needs 0 < xi_0 < xi_m")
    c2 = A * D**2.5 / m
    eps = xi_m / xi_0 - 1.0
    if eps < 1e-3:  # (3 + 2(1+ε)^(5/2) − 5(1+ε)) = (15/4) ε² (1 + ε/6 + O(ε²)): no cancellation
        return math.sqrt(1.5 * c2 * math.sqrt(xi_0) * (1.0 + eps / 6.0))
    return math.sqrt(c2 * (0.8 * (xi_m**2.5 - xi_0**2.5) - 2.0 * xi_0**1.5 * (xi_m - xi_0))) / (xi_m - xi_0)


def hertz_kdv_wave(A: float, m: float, D: float, xi_0: float, eps: float) -> SechWave:
    """Weak solitary wave (KdV limit) of a Hertz chain precompressed to strain xi_0: peak strain
    xi_0 (1 + eps) above it, eps << 1 (docs/physics.md §2).

    Expanding the long-wave equation of ``nesterenko_profile`` about xi_0 gives, for the excess
    strain η, η_tt = c0² [η + η²/(4 xi_0) + (D²/12) η_xx]_xx: the Boussinesq equation of
    ``softening_solitary_wave`` with k2/k1 = 1/(4 xi_0 D) and a = D, so the excess strain is
    η = eps xi_0 sech²(x/(W D)), W = sqrt(2/eps) sites, V = c0 sqrt(1 + eps/6) (the first order of
    ``nesterenko_precompressed_speed``). Returned as the bond elongation (compressive, Dm < 0).
    """
    if not (xi_0 > 0 and eps > 0):
        raise ValueError("a KdV wave needs a precompressed chain (xi_0 > 0) and eps > 0")
    c0 = math.sqrt(1.5 * A * D**2.5 / m * math.sqrt(xi_0))
    return SechWave(-eps * xi_0 * D, c0 * math.sqrt(1 + eps / 6), math.sqrt(2 / eps), c0, D)


def nesterenko_speed_from_force(A: float, m: float, D: float, F_m: float) -> float:
    """Speed from the peak contact force: xi_m = (F_m/A)^(2/3)/D, so V = (2/sqrt5) c (F_m/A)^(1/6) D^(-1/4)."""
    return nesterenko_speed(A, m, D, (F_m / A) ** (2 / 3) / D)


def nesterenko_support(D: float) -> float:
    """Full length of the solitary wave's support, 5 pi D/sqrt(10) ~ 4.97 D."""
    return 5 * math.pi * D / math.sqrt(10)


def nesterenko_profile(A: float, m: float, D: float, xi_m: float, x, t=0.0):
    """Strain xi(x, t) = xi_m cos^4(sqrt(10)(x - Vt)/(5D)) on |x - Vt| < 5 pi D/(2 sqrt 10), else 0.

    Nesterenko's long-wave equation for the compressive strain xi = -u_x,
    xi_tt = c^2 [xi^(3/2) + (D^2/10) xi^(1/4) (xi^(5/4))_xx]_xx, has travelling waves obeying
    V^2 xi = c^2 [xi^(3/2) + (D^2/10) xi^(1/4) (xi^(5/4))'']. Substituting B cos^4(kx) cancels the cos^6
    terms iff k = sqrt(10)/(5D) and leaves V^2 = (4/5) c^2 B^(1/2). Shape: broadcast of x and t.
    """
    s = np.asarray(x, dtype=float) - nesterenko_speed(A, m, D, xi_m) * np.asarray(t, dtype=float)
    k = math.sqrt(10) / (5 * D)
    return np.where(np.abs(k * s) < math.pi / 2, xi_m * np.cos(k * s) ** 4, 0.0)


# ---------------------------------------------------------------- Klein-Gordon kinks (sine-Gordon, φ⁴)
@dataclass(frozen=True)
class Kink:
    """Continuum kink u(x) of m u_tt = k a² u_xx − V'(u) between two wells (docs/physics.md §2).

    jump: well-to-well Δu (m); width: w (m) of the rest profile; c = a sqrt(k/m) (m/s); M = ∫ u_x² dx
    (m) of the rest kink, from the Bogomolny relation u_x = sqrt(2 V(u)/(k a²)); curvature: V'' at
    the wells (N/m), so a constant force F moves both wells by F/V'' (first order).
    """

    law: str
    jump: float
    width: float
    c: float
    M: float
    curvature: float

    def profile(self, x, v: float = 0.0):
        """u(x) − (lower well) of the kink rising from the lower well (x → −∞) to the upper one,
        Lorentz-contracted at speed v; shape of x."""
        xi = np.asarray(x, dtype=float) / (self.width * math.sqrt(1 - (v / self.c) ** 2))
        if self.law == "sine":
            return 2 * self.jump / math.pi * np.arctan(np.exp(np.clip(xi, -700, 700)))
        return 0.5 * self.jump * (1 + np.tanh(xi))

    def width_10_90(self, v: float = 0.0) -> float:
        """Distance (m) over which the moving profile goes from 10 % to 90 % of the jump."""
        wv = self.width * math.sqrt(1 - (v / self.c) ** 2)
        return 2 * wv * (math.log(math.tan(0.45 * math.pi)) if self.law == "sine" else math.atanh(0.8))

    def slope(self, x, v: float = 0.0):
        """du/dx of ``profile``; shape of x."""
        wv = self.width * math.sqrt(1 - (v / self.c) ** 2)
        xi = np.clip(np.asarray(x, dtype=float) / wv, -350, 350)
        if self.law == "sine":
            return self.jump / (math.pi * wv) / np.cosh(xi)
        return 0.5 * self.jump / wv / np.cosh(xi) ** 2


def sine_gordon_kink(A: float, period: float, k: float, m: float, a: float) -> Kink:
    """V = A(1 − cos(2πu/λ)): u = (2λ/π) arctan(e^(x/w)), w = a λ sqrt(k/A)/(2π), M = 4λ sqrt(A/k)/(π a)."""
    return Kink("sine", period, a * period * math.sqrt(k / A) / (2 * math.pi), a * math.sqrt(k / m),
                4 * period * math.sqrt(A / k) / (math.pi * a), A * (2 * math.pi / period) ** 2)


def phi4_kink(h: float, L: float, k: float, m: float, a: float) -> Kink:
    """V = h(1 − (u/L)²)² (wells ±L): u = L tanh(x/w), w = L a sqrt(k/(2h)), M = (4L/3) sqrt(2h/k)/a."""
    return Kink("phi4", 2 * L, L * a * math.sqrt(k / (2 * h)), a * math.sqrt(k / m),
                4 * L / 3 * math.sqrt(2 * h / k) / a, 8 * h / L**2)


def driven_kink_speed(kink: Kink, force: float, eta: float) -> float:
    """Terminal speed (m/s) of a kink driven by a force F per site against viscous damping η:
    the power F Δu v/a balances η v² γ M/a (γ = 1/sqrt(1 − v²/c²)), so
    v = Q/sqrt(1 + (Q/c)²), Q = F Δu/(η M) — for sine-Gordon McLaughlin–Scott's
    v/c = 1/sqrt(1 + (4α/(π γ_F))²), α = η/(m ω0), γ_F = F λ/(2π A). First order in F."""
    if not eta > 0:
        raise ValueError("a driven kink's terminal speed needs viscous damping (η > 0)")
    q = abs(force) * kink.jump / (eta * kink.M)
    return q / math.sqrt(1 + (q / kink.c) ** 2)


# ---------------------------------------------------------------- Toda lattice
def toda_soliton(a: float, b: float, m: float, kappa: float, n, t):
    """Bond stretch r_n(t) of the Toda soliton, e^(-b r_n) - 1 = sinh^2(kappa) sech^2(kappa n - beta t) (§2).

    Potential V(r) = (a/b) e^(-b r) + a r, m r''_n = V'(r_{n+1}) - 2 V'(r_n) + V'(r_{n-1});
    beta = sqrt(ab/m) sinh(kappa). Compressive (r < 0) for b > 0; broadcast shape of n and t.
    """
    beta = math.sqrt(a * b / m) * math.sinh(kappa)
    z = kappa * np.asarray(n, dtype=float) - beta * np.asarray(t, dtype=float)
    return -np.log1p(math.sinh(kappa) ** 2 * _sech2(z)) / b


def toda_speed(a: float, b: float, m: float, kappa: float) -> float:
    """Toda soliton speed beta/kappa in sites per unit time; tends to sqrt(ab/m) as kappa -> 0."""
    return math.sqrt(a * b / m) * math.sinh(kappa) / kappa


def toda_head_on_shifts(kappa1: float, kappa2: float) -> tuple[float, float]:
    """Forward shifts (sites) of two Toda solitons after a head-on collision (docs/physics.md §2).

    A12 = −[(s1 + s2)² − sinh²(κ1 − κ2)]/[(s1 − s2)² − sinh²(κ1 + κ2)], s = sinh κ (Hirota's
    two-soliton τ function); soliton i moves forward by −ln A12/(2 κ_i) sites.
    """
    if min(kappa1, kappa2) <= 0:
        raise ValueError("need kappa1, kappa2 > 0")
    s1, s2 = math.sinh(kappa1), math.sinh(kappa2)
    a12 = -((s1 + s2) ** 2 - math.sinh(kappa1 - kappa2) ** 2) / ((s1 - s2) ** 2 - math.sinh(kappa1 + kappa2) ** 2)
    return -math.log(a12) / (2 * kappa1), -math.log(a12) / (2 * kappa2)


def toda_two_soliton(a: float, b: float, m: float, kappa: tuple[float, float], center: tuple[float, float],
                     sigma: tuple[int, int], n) -> tuple[np.ndarray, np.ndarray]:
    """Bond stretch r_n and its rate ṙ_n (per unit time) of the exact Toda two-soliton at t = 0
    (docs/physics.md §2): e^(−b r_n) = τ_(n+1) τ_(n−1)/τ_n², τ = 1 + e^η1 + e^η2 + A12 e^(η1+η2),
    η_i = 2κ_i (n − n_i) − 2σ_i sinh κ_i s (s = sqrt(ab/m) t), each phase corrected by ln A12 where
    the other soliton lies on its left, so that soliton i is centred on n_i (its asymptotic centre,
    before a collision when both sit on one site). ``n``: bond positions (sites).
    """
    k1, k2 = kappa
    if min(k1, k2) <= 0 or (sigma[0] == sigma[1] and k1 == k2):
        raise ValueError("two Toda solitons need kappa > 0, and different kappas when they move the same way")
    w = [2 * sg * math.sinh(k) for k, sg in zip(kappa, sigma)]
    A12 = -((w[0] - w[1]) ** 2 - 4 * math.sinh(k1 - k2) ** 2) / ((w[0] + w[1]) ** 2 - 4 * math.sinh(k1 + k2) ** 2)
    lnA = math.log(A12)
    n = np.asarray(n, dtype=float)
    nn = np.concatenate([[n[0] - 1], n, [n[-1] + 1]])
    def left_of(j: int, i: int) -> bool:  # on the same site, the soliton moving right is the left one
        return center[j] < center[i] or (center[j] == center[i] and sigma[j] > sigma[i])

    eta = [2 * k * (nn - c) - (lnA if left_of(1 - i, i) else 0.0) for i, (k, c) in enumerate(zip(kappa, center))]
    terms = np.stack([np.zeros_like(nn), eta[0], eta[1], lnA + eta[0] + eta[1]])
    rates = np.array([0.0, -w[0], -w[1], -w[0] - w[1]])[:, None]  # ∂η/∂s of each term
    top = terms.max(axis=0)
    weights = np.exp(terms - top)
    ln_tau = top + np.log(weights.sum(axis=0))
    dln_tau = (rates * weights).sum(axis=0) / weights.sum(axis=0)  # ∂ ln τ/∂s
    second = lambda f: f[2:] + f[:-2] - 2 * f[1:-1]  # noqa: E731
    return -second(ln_tau) / b, -second(dln_tau) * math.sqrt(a * b / m) / b


# ---------------------------------------------------------------- linear chain
def linear_chain_dispersion(k: float, m: float, q, k_onsite: float = 0.0):
    """omega(q) = sqrt((k_onsite + 4 k sin^2(q/2))/m), q the phase per site (q a) (docs/physics.md §2); shape of q."""
    return np.sqrt((k_onsite + 4 * k * np.sin(np.asarray(q, dtype=float) / 2) ** 2) / m)


def linear_chain_band(k: float, m: float, k_onsite: float = 0.0) -> tuple[float, float]:
    """Pass band [sqrt(k_onsite/m), sqrt((k_onsite + 4k)/m)] in angular frequency."""
    return math.sqrt(k_onsite / m), math.sqrt((k_onsite + 4 * k) / m)


def linear_chain_cutoff_frequency(k: float, m: float, k_onsite: float = 0.0) -> float:
    """Upper cut-off in cycles per unit time, omega_max/(2 pi) (= sqrt(k/m)/pi without on-site springs)."""
    return linear_chain_band(k, m, k_onsite)[1] / (2 * math.pi)


def evanescent_decay(k: float, m: float, omega: float, k_onsite: float = 0.0) -> tuple[float, float]:
    """Decay per site kappa and neighbour ratio u_{n+1}/u_n of a drive outside the pass band (§2).

    With u_n = r^n: r + 1/r = 2 + (k_onsite - m omega^2)/k. Above the band r = -e^(-kappa),
    cosh kappa = (m omega^2 - k_onsite)/(2k) - 1; below it (k_onsite > 0) r = +e^(-kappa),
    cosh kappa = 1 + (k_onsite - m omega^2)/(2k). ValueError inside the band.
    """
    lo, hi = linear_chain_band(k, m, k_onsite)
    if lo <= omega <= hi:
        raise ValueError(f"omega = {omega} lies in the pass band [{lo}, {hi}]: no evanescent decay")
    if omega > hi:
        kappa = math.acosh((m * omega**2 - k_onsite) / (2 * k) - 1)
        return kappa, -math.exp(-kappa)
    kappa = math.acosh(1 + (k_onsite - m * omega**2) / (2 * k))
    return kappa, math.exp(-kappa)
