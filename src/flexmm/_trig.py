"""A vectorisable ``sincos`` for compiled kernels (about 1 ns per call instead of ~25 ns).

Without Intel SVML, numba lowers ``math.sin``/``math.cos`` to scalar libm calls, which
stops LLVM from vectorising any loop that contains them. This version is branch-free
(quadrant choice by selects), so loops over sites vectorise:

    k = round(2x/π),  r = x − k π/2   (Cody–Waite, π/2 split in three parts),  z = r²,
    sin r = r + r z P(z),   cos r = 1 − z/2 + z² Q(z)   (P and Q of degree 5 in z),

with |r| ≤ π/4, then (sin x, cos x) = (s, c), (c, −s), (−s, −c), (−c, s) for k mod 4 = 0, 1,
2, 3. P and Q are near-minimax polynomials of the relative errors of sin r and cos r on
|r| ≤ π/4: weighted least squares on 300 Chebyshev nodes in z, reweighted (Lawson) towards
equal ripple, in 40-digit arithmetic (mpmath, offline), then rounded to double. Their own error
is 4e-18 (sin) and 6e-20 (cos) relative, so what remains is the rounding of the Horner sums.
The reduction and the Horner steps are explicit fused multiply-adds (``_jit.fma``: one rounding
each on a CPU with FMA, and half the instructions): measured on 4e5 points of |r| ≤ π/4 against
long double, 0.68 ulp (sin) and 0.85 ulp (cos) at most, against 0.74 and 1.12 ulp with a
separate multiply and add (what a CPU without FMA computes). k·HI and k·MID are exact, so their
fused subtractions round as the separate ones did. Over x: a few ulp of max(1, |x|·1e-4) for
|x| ≲ 1e5 (tests/integrators/test_trig_and_parallel_kernels.py); beyond ~3e6 the reduction is
no longer exact (no Payne–Hanek), which no lattice angle reaches.
"""

from __future__ import annotations

import math

import numpy as np

from flexmm._jit import fma, jit

# π/2 = HI + MID + LO to 1e-37; HI and MID have 31 and 32 significant bits, so k·HI and k·MID
# are exact for |k| < 2^21 (|x| ≲ 3e6)
_PIO2_HI = 1.5707963267341256e00
_PIO2_MID = 6.077100506303966e-11
_PIO2_LO = 2.0222662487959506e-21
_TWO_OVER_PI = 0.6366197723675814

# P(z) and Q(z) of the module docstring (near −1/3!, 1/5!, … and 1/4!, −1/6!, …: Taylor's)
_P0, _P1, _P2, _P3, _P4, _P5 = (-0.1666666666666663, 0.008333333333322118, -0.00019841269829589097,
                                2.7557313621255042e-06, -2.5050747744886762e-08, 1.5896229223823605e-10)
_Q0, _Q1, _Q2, _Q3, _Q4, _Q5 = (0.041666666666666595, -0.0013888888888873056, 2.480158728885084e-05,
                                -2.755731417907392e-07, 2.08757008145203e-09, -1.135853521688412e-11)


@jit  # the three-part reduction relies on the written order (no reassociation: flexmm._jit)
def sincos(x):
    """(sin x, cos x) to ~1 ulp for |x| ≲ 1e5, branch-free so that loops vectorise."""
    kf = math.floor(fma(x, _TWO_OVER_PI, 0.5))
    r = fma(-kf, _PIO2_LO, fma(-kf, _PIO2_MID, fma(-kf, _PIO2_HI, x)))
    z = r * r
    p = fma(z, fma(z, fma(z, fma(z, fma(z, _P5, _P4), _P3), _P2), _P1), _P0)
    s = fma(r * z, p, r)
    q = fma(z, fma(z, fma(z, fma(z, fma(z, _Q5, _Q4), _Q3), _Q2), _Q1), _Q0)
    c = fma(z, fma(z, q, -0.5), 1.0)
    k = np.int64(kf) & 3
    odd = (k & 1) != 0
    sv = c if odd else s
    cv = s if odd else c
    sv = -sv if (k & 2) != 0 else sv
    cv = -cv if ((k + 1) & 2) != 0 else cv
    return sv, cv
