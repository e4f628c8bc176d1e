"""Dormand–Prince 5(4), adaptive, with dense output at the save times (docs/physics.md §3).

Same first-order form as ``rk4`` (y = (q, v) plus the two ledger integrals). Seven stages,
first-same-as-last (six force evaluations per accepted step), 5th-order solution, embedded
4th-order error estimate, local error control in the max norm over free DOFs

    err = max_k |h Σ_j e_j K_jk| / (atol + rtol max(|y_k|, |y'_k|)),   accept if err ≤ 1,
    h ← h min(5, max(0.2, 0.9 err^(−1/5)))   (no growth right after a rejection),

and the 4th-order continuous extension of Dormand & Prince (as in Hairer, Nørsett & Wanner,
*Solving ODEs I*, §II.6) to produce the state at the requested times without shortening steps.

Interface (``IntegratorSpec``): ``advance(..., t, h, nsteps, acc)`` returns the state at
t + nsteps·h. The adaptive state (internal y, FSAL slopes, dense coefficients, step size)
lives in ``acc[ACC_HEADER:]`` (``IntegratorSpec.new_acc``); the caller must not touch q, v
between calls. With a bare ``acc`` (2 slots, or no rtol) the method takes fixed steps of
size h — used by the order tests. Linear stability: |R(iy)| ≤ 1 only for y ≤ 0.997, and the
growth stays below 1e-4 per step up to y ≈ 1.2 (``stability.harmonic_limit``); error control
keeps adaptive runs stable.
"""

from __future__ import annotations

import math

import numpy as np

from flexmm._jit import jit
from flexmm.integrators.common import (
    ACC_DISSIPATED,
    ACC_WORK,
    ACC_FEVALS,
    ACC_HEADER,
    ACC_REJECTED,
    ACC_STEPS,
    acceleration,
    apply_prescribed,
)

# Butcher tableau (Dormand & Prince 1980); the 7th stage is at the new point (FSAL).
C = np.array([0.0, 1 / 5, 3 / 10, 4 / 5, 8 / 9, 1.0, 1.0])
A = np.zeros((7, 7))
A[1, :1] = [1 / 5]
A[2, :2] = [3 / 40, 9 / 40]
A[3, :3] = [44 / 45, -56 / 15, 32 / 9]
A[4, :4] = [19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729]
A[5, :5] = [9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656]
A[6, :6] = [35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84]
B = A[6].copy()
#: b − b̂ (5th minus embedded 4th order weights)
E = np.array([71 / 57600, 0.0, -71 / 16695, 71 / 1920, -17253 / 339200, 22 / 525, -1 / 40])
#: dense output: y(t + θh) = r1 + θ(r2 + (1−θ)(r3 + θ(r4 + (1−θ) r5))), r5 = h Σ d_j K_j
D = np.array([-12715105075 / 11282082432, 0.0, 87487479700 / 32700410799, -10690763975 / 1880347072,
              701980252875 / 199316789632, -1453857185 / 822651844, 69997945 / 29380423])
ORDER = 5

# Scalar slots of the adaptive state, after the common header.
S_RTOL, S_ATOL, S_MAX_STEP, S_T, S_H_NEXT, S_T_OLD, S_H_OLD, S_READY = range(ACC_HEADER, ACC_HEADER + 8)
S_ARRAYS = ACC_HEADER + 8
N_ARRAYS = 7  # y, K1 (FSAL) and the five dense-output coefficient vectors


def state_size(ndof: int) -> int:
    """Slots of the adaptive state after the common header."""
    return 8 + N_ARRAYS * (2 * ndof + 2)


@jit
def _slopes(args, terms, minv, damp, ts, y, ky, f, n):
    """K = dy/dt at (ts, y), y = [q (n), v (n), dissipated, work]; imposes prescribed DOFs on y."""
    q = y[:n]
    v = y[n : 2 * n]
    a = ky[n : 2 * n]
    power, diss = acceleration(args, terms, minv, damp, ts, q, v, f, a)
    ky[:n] = v
    ky[2 * n] = diss
    ky[2 * n + 1] = power


@jit
def _step(args, terms, minv, damp, t, h, y, K, ys, y_new, f, n):
    """One DP5 step from y (K[0] = slopes at y); 5th-order result in y_new, its slopes in K[6]."""
    m = y.shape[0]
    for s in range(1, 7):
        target = y_new if s == 6 else ys
        for k in range(m):
            acc = 0.0
            for j in range(s):
                acc += A[s, j] * K[j, k]
            target[k] = y[k] + h * acc
        _slopes(args, terms, minv, damp, t + C[s] * h, target, K[s], f, n)


@jit
def _error(K, y, y_new, h, minv, rtol, atol, n):
    """Max-norm scaled error estimate over the free DOFs (q and v), ledger excluded."""
    err = 0.0
    for part in range(2):
        for i in range(n):
            if minv[i] <= 0.0:
                continue
            k = part * n + i
            e = 0.0
            for j in range(7):
                e += E[j] * K[j, k]
            sc = atol + rtol * max(abs(y[k]), abs(y_new[k]))
            err = max(err, abs(h * e) / sc)
    return err


@jit
def _dense_coefficients(y, y_new, K, h, r):
    """r (5, m): coefficients of the continuous extension on the step just taken."""
    for k in range(y.shape[0]):
        d = y_new[k] - y[k]
        r[0, k] = y[k]
        r[1, k] = d
        r[2, k] = h * K[0, k] - d
        r[3, k] = d - h * K[6, k] - r[2, k]
        s = 0.0
        for j in range(7):
            s += D[j] * K[j, k]
        r[4, k] = h * s


@jit
def _interpolate(r, theta, out):
    th1 = 1.0 - theta
    for k in range(out.shape[0]):
        out[k] = r[0, k] + theta * (r[1, k] + th1 * (r[2, k] + theta * (r[3, k] + th1 * r[4, k])))


@jit
def _initial_step(args, terms, minv, damp, t, y, k1, rtol, atol, n, f):
    """Starting step from the sizes of y, y' and y'' (Hairer, Nørsett & Wanner §II.4)."""
    d0 = 0.0
    d1 = 0.0
    for k in range(2 * n):
        sc = atol + rtol * abs(y[k])
        d0 = max(d0, abs(y[k]) / sc)
        d1 = max(d1, abs(k1[k]) / sc)
    h0 = 1e-6 if d0 < 1e-5 or d1 < 1e-5 else 0.01 * d0 / d1
    y1 = y + h0 * k1
    k2 = np.empty_like(y)
    _slopes(args, terms, minv, damp, t + h0, y1, k2, f, n)
    d2 = 0.0
    for k in range(2 * n):
        d2 = max(d2, abs(k2[k] - k1[k]) / (atol + rtol * abs(y[k])))
    d2 /= h0
    big = max(d1, d2)
    h1 = max(1e-6, h0 * 1e-3) if big <= 1e-15 else (0.01 / big) ** (1.0 / ORDER)
    return min(100.0 * h0, h1)


@jit
def _fixed(args, q, v, f, minv, damp, terms, t, h, nsteps, acc):
    """Fixed steps of size h (no error control): the 5th-order solution of each step."""
    n = q.shape[0]
    m = 2 * n + 2
    y = np.empty(m)
    y[:n] = q
    y[n : 2 * n] = v
    y[2 * n] = acc[ACC_DISSIPATED]
    y[2 * n + 1] = acc[ACC_WORK]
    K = np.empty((7, m))
    ys = np.empty(m)
    y_new = np.empty(m)
    _slopes(args, terms, minv, damp, t, y, K[0], f, n)
    for _ in range(nsteps):
        _step(args, terms, minv, damp, t, h, y, K, ys, y_new, f, n)
        y[:] = y_new
        K[0] = K[6]
        t += h
    q[:] = y[:n]
    v[:] = y[n : 2 * n]
    acc[ACC_DISSIPATED] = y[2 * n]
    acc[ACC_WORK] = y[2 * n + 1]
    if acc.shape[0] > ACC_STEPS:
        acc[ACC_FEVALS] += 1 + 6 * nsteps
        acc[ACC_STEPS] += nsteps
    return t


@jit
def dopri5_advance(args, q, v, f, minv, damp, terms, t, h, nsteps, acc):
    """Return the state at t + nsteps·h, stepping adaptively (or fixed steps without state)."""
    n = q.shape[0]
    m = 2 * n + 2
    if nsteps <= 0:
        return t
    if acc.shape[0] < S_ARRAYS + N_ARRAYS * m or acc[S_RTOL] <= 0.0:
        return _fixed(args, q, v, f, minv, damp, terms, t, h, nsteps, acc)
    rtol, atol, h_max = acc[S_RTOL], acc[S_ATOL], acc[S_MAX_STEP]
    arrays = acc[S_ARRAYS : S_ARRAYS + N_ARRAYS * m].reshape((N_ARRAYS, m))
    y = arrays[0]
    k1 = arrays[1]
    r = arrays[2:]
    t_end = t + h * nsteps
    if acc[S_READY] == 0.0:
        y[:n] = q
        y[n : 2 * n] = v
        y[2 * n] = acc[ACC_DISSIPATED]
        y[2 * n + 1] = acc[ACC_WORK]
        _slopes(args, terms, minv, damp, t, y, k1, f, n)
        acc[S_H_NEXT] = _initial_step(args, terms, minv, damp, t, y, k1, rtol, atol, n, f)
        acc[ACC_FEVALS] += 2
        acc[S_T] = t
        acc[S_READY] = 1.0
    K = np.empty((7, m))
    ys = np.empty(m)
    y_new = np.empty(m)
    tn = acc[S_T]
    hn = acc[S_H_NEXT]
    rejected = False
    while tn < t_end:
        if h_max > 0.0:
            hn = min(hn, h_max)
        if hn < 1e-13 * max(1.0, abs(tn)):
            q[:] = np.nan  # step size underflow: report as a failed (non-finite) state
            return t_end
        K[0] = k1
        _step(args, terms, minv, damp, tn, hn, y, K, ys, y_new, f, n)
        acc[ACC_FEVALS] += 6
        err = _error(K, y, y_new, hn, minv, rtol, atol, n)
        if err <= 1.0:  # NaN compares False: rejected, the step shrinks until it underflows
            if tn + hn >= t_end:
                _dense_coefficients(y, y_new, K, hn, r)
                acc[S_T_OLD] = tn
                acc[S_H_OLD] = hn
            tn += hn
            y[:] = y_new
            k1[:] = K[6]
            acc[ACC_STEPS] += 1
            fac = 5.0 if err == 0.0 else min(5.0, max(0.2, 0.9 * err ** (-1.0 / ORDER)))
            hn *= min(fac, 1.0) if rejected else fac
            rejected = False
        else:
            acc[ACC_REJECTED] += 1
            fac = 0.2 if not math.isfinite(err) else max(0.2, 0.9 * err ** (-1.0 / ORDER))
            hn *= fac
            rejected = True
    acc[S_T] = tn
    acc[S_H_NEXT] = hn
    out = np.empty(m)
    if tn == t_end:
        out[:] = y
    else:
        _interpolate(r, (t_end - acc[S_T_OLD]) / acc[S_H_OLD], out)
    q[:] = out[:n]
    v[:] = out[n : 2 * n]
    acc[ACC_DISSIPATED] = out[2 * n]
    acc[ACC_WORK] = out[2 * n + 1]
    apply_prescribed(q, v, t_end, terms.drv_dof, terms.drv_mode, terms.drv_shape, terms.drv_prm)
    return t_end
