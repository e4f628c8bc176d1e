"""Coefficients of higher-order symplectic splittings, run by ``splitting.make_splitting_advance``.

``BLANES_MOAN_6`` is SRKN₁₁ᵇ of S. Blanes & P. C. Moan, "Practical symplectic partitioned
Runge–Kutta and Runge–Kutta–Nyström methods", J. Comput. Appl. Math. 142, 313–330 (2002),
Table 3: a symmetric kick-first splitting

    K(b₁h) D(a₁h) K(b₂h) … D(a₅h) K(b₆h) D(a₆h) K(b₆h) D(a₅h) … K(b₁h),
    b₆ = ½ − (b₁ + … + b₅),   a₆ = 1 − 2(a₁ + … + a₅),

of order 6 for q'' = F(q)/m, with 11 force evaluations per step (the last kick's force serves
the next step's first). It is a Runge–Kutta–Nyström method: its order conditions use
[K, [K, [K, D]]] = 0, true only when the kick depends on q alone, so velocity-dependent forces
(damping, dashpots, friction) are refused. Its harmonic-oscillator map is stable for hω < π
(first resonance band 3.14144–3.14232, growth ≤ 4.4e-4 per step), again from 3.1423 to 6.3479
and from 6.3493 to 9.0736.

Evaluated and not kept (LEGO soliton work–precision, 1e-8 final error): the Verlet compositions
s9odr6a and s17odr8a of Kahan & Li (Math. Comp. 66, 1089 (1997)) cost 3× and 2× more force
evaluations than this method at equal error, and have stable steps above unstable bands too.
"""

from __future__ import annotations

#: kicks b₁…b₅ and drifts a₁…a₅ of SRKN₁₁ᵇ, as published
BLANES_MOAN_6_B = (0.0414649985182624, 0.198128671918067, -0.0400061921041533, 0.0752539843015807,
                   -0.0115113874206879)
BLANES_MOAN_6_A = (0.123229775946271, 0.290553797799558, -0.127049212625417, -0.246331761062075,
                   0.357208872795928)


def mirrored(half: tuple, middle: float | None = None) -> tuple:
    """half + (middle,) + reversed(half): a symmetric sequence (``middle`` None: even length)."""
    return tuple(half) + (() if middle is None else (middle,)) + tuple(reversed(half))


def blanes_moan_6() -> tuple[tuple, tuple]:
    """(kicks, drifts) of SRKN₁₁ᵇ (module docstring): 12 kicks, 11 drifts."""
    b6 = 0.5 - sum(BLANES_MOAN_6_B)
    a6 = 1.0 - 2.0 * sum(BLANES_MOAN_6_A)
    return mirrored(BLANES_MOAN_6_B + (b6,)), mirrored(BLANES_MOAN_6_A, a6)
