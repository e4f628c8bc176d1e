"""The linear algebra of small oscillations, once: Hessian-vector products, top eigenpairs, Bloch bands.

Everything here works on operators given as functions, so it knows nothing about models and sits
low in the layering (docs/architecture.md): models use it to relax, ``stability`` for ω_max and
the fastest mode, ``linear`` and ``plan.domain`` for dispersion.

Hessian-vector product. For a force F = −∇E (or a gradient g = ∇E) the Hessian times x is the
central difference K x ≈ −(F(q + εx) − F(q − εx)) / 2ε with ε = ``FD_STEP`` / max|x| (error
O(ε²) from the third derivatives, O(u max|F| / ε) from round-off u).

Top eigenvalue. Small symmetric operators are assembled column by column and diagonalised
densely; larger ones by plain Lanczos (the top Ritz value, a lower bound converging like 1/m² in
the m iterations at a band edge), the top eigenvector by ARPACK. ``warm_lanczos`` is a few
fully reorthogonalised Lanczos steps from a given start (tracking a slowly changing top mode).

Bloch bands. A periodic lattice whose cell holds d DOFs couples DOF a of a cell to DOF b of the
cell displaced by r with the Hessian entry K; summing over partners,

    D_ab(k) = Σ K_{a, (b, r)} e^{i k·r},    D(k) x = ω² M x,

M the cell's diagonal mass (docs/physics.md §1.4 is its closed form for the rotating-squares
chain). ``read_cell`` collects those entries from Hessian columns, ``bloch_frequencies`` solves
the eigenproblem for wave vectors of any dimension.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.linalg import eigvalsh_tridiagonal

from flexmm._blas import single_blas_thread

FD_STEP = 1e-6  # central-difference step, relative to max |x|
DENSE_LIMIT = 400  # at most this many DOFs: assemble and diagonalise densely
LANCZOS_MAX_ITER = 600
LANCZOS_RTOL = 1e-6
SCATTER_LIMIT = 2**24  # entries × d² above which Bloch matrices are summed per wave vector, not by one product
UNSTABLE_TOL = 1e-10  # ω² below −UNSTABLE_TOL·max(1, max|ω²|) is an unstable mode (NaN frequency)

Operator = Callable[[np.ndarray], np.ndarray]


def fd_step(v: np.ndarray) -> float:
    """The central-difference step ε = FD_STEP / max|v| along v (0 for v = 0)."""
    scale = float(np.max(np.abs(v))) if np.size(v) else 0.0
    return FD_STEP / scale if scale > 0 else 0.0


def central_difference(fn: Operator, y: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(fn(y + εv) − fn(y − εv)) / 2ε, ε = ``fd_step(v)``: the derivative of ``fn`` along v (a
    Hessian-vector product when ``fn`` is a gradient). Zero for v = 0."""
    eps = fd_step(v)
    if eps == 0:
        return np.zeros(np.shape(y))
    return (fn(y + eps * v) - fn(y - eps * v)) / (2 * eps)


def force_hessian(force, args, q_ref: np.ndarray) -> Operator:
    """x ↦ K x at ``q_ref`` for a compiled ``force(q, args, out)`` (F = −∇E): the central
    difference −(F(q + εx) − F(q − εx)) / 2ε of ``central_difference``, into reused buffers."""
    q_ref = np.asarray(q_ref, float)
    fp, fm = np.zeros(q_ref.size), np.zeros(q_ref.size)

    def matvec(x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, float).ravel()
        eps = fd_step(x)
        if eps == 0:
            return np.zeros_like(x)
        force(q_ref + eps * x, args, fp)
        force(q_ref - eps * x, args, fm)
        return -(fp - fm) / (2 * eps)

    return matvec


def dense_matrix(op: Operator, n: int, index: np.ndarray | None = None) -> np.ndarray:
    """The symmetric operator ``op`` on R^n assembled over ``index`` (default all), column by column,
    and symmetrised: shape (len(index), len(index))."""
    index = np.arange(n) if index is None else np.asarray(index)
    e = np.zeros(n)
    cols = []
    for j in index:
        e[j] = 1.0
        cols.append(op(e)[index])
        e[j] = 0.0
    a = np.column_stack(cols) if cols else np.zeros((0, 0))
    return 0.5 * (a + a.T)


def lanczos_max(op: Operator, n: int, *, max_iter: int = LANCZOS_MAX_ITER, rtol: float = LANCZOS_RTOL,
                seed: int = 0) -> float:
    """Largest eigenvalue of the symmetric operator ``op`` (n × n), by plain Lanczos.

    No reorthogonalisation: the top Ritz value still converges to λ_max (lost orthogonality only
    adds copies). Stops when it changes by less than ``rtol`` (relative) over 10 iterations, or
    after ``max_iter`` iterations.
    """
    rng = np.random.default_rng(seed)
    x = rng.standard_normal(n)
    x /= math.sqrt(np.sum(x * x))
    x_prev = np.zeros(n)
    alpha, beta = np.zeros(max_iter), np.zeros(max_iter)
    b, history, it = 0.0, [], 0
    while it < min(max_iter, n):
        k1 = min(it + 10, max_iter, n)
        for k in range(it, k1):
            w = op(x) - b * x_prev
            alpha[k] = float(np.sum(w * x))  # np.sum, not BLAS: a threaded dot spin-waits
            w -= alpha[k] * x
            b = beta[k] = math.sqrt(float(np.sum(w * w)))
            if b == 0.0:
                k1 = k + 1
                break
            x_prev, x = x, w / b
        it = k1
        top = float(eigvalsh_tridiagonal(alpha[:it], beta[: it - 1], select="i",
                                         select_range=(it - 1, it - 1))[0])
        history.append(top)
        if b <= 1e-14 * abs(top) or (len(history) > 1 and abs(top - history[-2]) <= rtol * abs(top)):
            break
    return history[-1]


def top_eigenvalue(op: Operator, n: int, index: np.ndarray | None = None,
                   dense_limit: int = DENSE_LIMIT) -> float:
    """Largest eigenvalue of the symmetric ``op`` restricted to the DOFs ``index`` (default all).

    ``op`` must vanish outside ``index`` (a mass-weighted operator with zero weight on held DOFs),
    so that Lanczos on the full space sees the same top eigenvalue (the rest adds zeros).
    """
    index = np.arange(n) if index is None else np.asarray(index)
    if index.size == 0:
        return 0.0
    if index.size <= dense_limit:
        with single_blas_thread():  # small dense problem: BLAS threads only cost
            return float(np.linalg.eigvalsh(dense_matrix(op, n, index))[-1])
    return lanczos_max(op, n)


def top_eigenpair(op: Operator, n: int, index: np.ndarray | None = None,
                  dense_limit: int = DENSE_LIMIT) -> tuple[float, np.ndarray]:
    """(λ_max, unit eigenvector (n,), zero outside ``index``) of the symmetric ``op`` on ``index``:
    dense for small problems, else ARPACK (``eigsh``) on the restricted operator."""
    from scipy.sparse.linalg import LinearOperator, eigsh

    index = np.arange(n) if index is None else np.asarray(index)
    if index.size <= dense_limit:
        with single_blas_thread():
            lam, vec = np.linalg.eigh(dense_matrix(op, n, index))
        lam, y = lam[-1], vec[:, -1]
    else:
        full = np.zeros(n)

        def matvec(y):
            full[:] = 0.0
            full[index] = np.ravel(y)
            return op(full)[index]

        sub = LinearOperator((index.size, index.size), matvec=matvec, dtype=float)
        v0 = np.random.default_rng(0).standard_normal(index.size)  # not orthogonal to a staggered mode
        lam, vec = eigsh(sub, k=1, which="LA", tol=1e-10, v0=v0)
        lam, y = lam[0], vec[:, 0]
    out = np.zeros(n)
    out[index] = y
    return float(lam), out


def warm_lanczos(op: Operator, x0: np.ndarray, iters: int) -> tuple[float, np.ndarray]:
    """(top Ritz value, its Ritz vector) after ``iters`` (≥ 2) Lanczos steps on ``op`` from ``x0``.

    Full reorthogonalisation (``iters`` is small). A start close to the top eigenvector makes the
    Ritz value, always a lower bound of λ_max, tight after a few steps.
    """
    n = x0.size
    m = max(2, iters)
    basis = np.zeros((m, n))
    alpha, beta = np.zeros(m), np.zeros(m)
    x = x0 / max(math.sqrt(float(np.sum(x0 * x0))), 1e-300)
    k_used = m
    for k in range(m):
        basis[k] = x
        r = op(x)
        alpha[k] = float(np.sum(r * x))
        r -= basis[: k + 1].T @ (basis[: k + 1] @ r)
        beta[k] = math.sqrt(float(np.sum(r * r)))
        if beta[k] <= 1e-14 * max(abs(alpha[k]), 1e-300):
            k_used = k + 1
            break
        x = r / beta[k]
    t = np.diag(alpha[:k_used]) + np.diag(beta[: k_used - 1], 1) + np.diag(beta[: k_used - 1], -1)
    lam, vec = np.linalg.eigh(t)
    return float(lam[-1]), basis[:k_used].T @ vec[:, -1]


@dataclass(frozen=True)
class BlochCell:
    """The couplings of a periodic lattice's cell of d DOFs: entry e couples cell DOF ``rows[e]`` to
    DOF ``cols[e]`` of the cell displaced by ``offsets[e]`` (dim,) with Hessian value ``values[e]``;
    ``mass`` (d,) the cell's diagonal mass."""

    rows: np.ndarray
    cols: np.ndarray
    offsets: np.ndarray
    values: np.ndarray
    mass: np.ndarray

    @property
    def size(self) -> int:
        return int(self.mass.size)

    @property
    def dim(self) -> int:
        return int(self.offsets.shape[1])


def read_cell(hessian: Operator, n: int, cell_dofs, dof_class: np.ndarray, positions: np.ndarray,
              mass, *, tol: float = 0.0, keep: Callable[[np.ndarray], np.ndarray] | None = None) -> BlochCell:
    """The ``BlochCell`` of a periodic lattice from the Hessian columns of one cell's DOFs.

    ``cell_dofs`` (d,): the DOF indices of the cell (their order is the cell's DOF order);
    ``dof_class`` (n,): the cell DOF (0..d−1) each DOF of the lattice is a copy of, −1 for DOFs
    outside the lattice; ``positions`` (n, dim): where each DOF sits (only differences count);
    ``mass`` (d,). Entries with |K| ≤ ``tol`` × max|column| are dropped (finite-difference noise),
    and so are partners for which ``keep(offsets)`` is False.
    """
    positions = np.asarray(positions, float).reshape(n, -1)
    e = np.zeros(n)
    rows, cols, offs, vals = [], [], [], []
    for a, dof in enumerate(cell_dofs):
        e[dof] = 1.0
        col = hessian(e)
        e[dof] = 0.0
        hit = np.flatnonzero((np.abs(col) > tol * max(np.max(np.abs(col)), 1e-300)) & (dof_class >= 0))
        off = positions[hit] - positions[dof]
        if keep is not None:
            sel = keep(off)
            hit, off = hit[sel], off[sel]
        rows.append(np.full(hit.size, a))
        cols.append(dof_class[hit])
        offs.append(off)
        vals.append(col[hit])
    return BlochCell(np.concatenate(rows), np.concatenate(cols), np.concatenate(offs),
                     np.concatenate(vals), np.asarray(mass, float))


def bloch_matrices(cell: BlochCell, k) -> np.ndarray:
    """D(k), Hermitian (…, d, d), at wave vectors ``k`` (…, dim); for dim = 1, ``k`` (…) are phases."""
    k = np.asarray(k, float)
    if cell.dim == 1:
        k = k[..., None]
    d = cell.size
    phase = np.exp(1j * (k.reshape(-1, cell.dim) @ cell.offsets.T)) * cell.values  # (n_k, entries)
    if cell.values.size * d * d <= SCATTER_LIMIT:
        scatter = np.zeros((cell.values.size, d * d))
        scatter[np.arange(cell.values.size), cell.rows * d + cell.cols] = 1.0
        mat = (phase @ scatter).reshape(-1, d, d)
    else:  # a large cell: sum the entries of each wave vector into its matrix
        at = cell.rows * d + cell.cols
        mat = np.stack([np.bincount(at, p.real, d * d) + 1j * np.bincount(at, p.imag, d * d) for p in phase])
        mat = mat.reshape(-1, d, d)
    mat = 0.5 * (mat + np.conj(np.swapaxes(mat, 1, 2)))
    return mat.reshape(k.shape[:-1] + (d, d))


def bloch_eigen(cell: BlochCell, k, vectors: bool = False):
    """ω² (…, d) ascending at wave vectors ``k`` (see ``bloch_matrices``), and with ``vectors`` the
    mass-normalised mode shapes (…, d, d) (columns, x^H M x = 1)."""
    w = 1.0 / np.sqrt(cell.mass)
    a = w[:, None] * bloch_matrices(cell, k) * w[None, :]
    with single_blas_thread():  # small dense eigenproblems: BLAS threads only add overhead
        if not vectors:
            return np.linalg.eigvalsh(a)
        lam, vec = np.linalg.eigh(a)
    return lam, w[:, None] * vec


def bloch_frequencies(cell: BlochCell, k) -> np.ndarray:
    """ω(k) (…, d) ascending, from ``bloch_eigen``; unstable modes (ω² < 0 beyond round-off) are NaN."""
    lam = bloch_eigen(cell, k)
    floor = -UNSTABLE_TOL * max(1.0, float(np.max(np.abs(lam), initial=0.0)))
    return np.where(lam >= floor, np.sqrt(np.clip(lam, 0.0, None)), np.nan)



#: relative mismatch of a random Hessian-vector product against its rebuilding from the probes
#: above which the assumed band is wrong (central-difference noise is ~1e-9 of the product)
BAND_CHECK_TOL = 1e-6
#: the half-bandwidths (in sites) ``banded_bounds`` tries, and the most products it spends
BANDS = (1, 2, 4)
MAX_PROBES = 64
#: sites of the window whose principal submatrix gives the lower bound
WINDOW_SITES = 128


def _combs(op: Operator, n: int, ndof: int, band: int, window: np.ndarray | None = None):
    """For each colour (field f, residue c mod P = 2·band + 1) of the lattice DOFs (k < blocks·n is
    field k // n of site k % n): (f, c, op(comb)), comb 1 on field f at the sites ≡ c (mod P)
    (restricted to the sites ``window``). In the product, a lattice row of site s holds the
    entry of the comb's column at site s + d, the one d in [−band, band] with s + d ≡ c."""
    blocks, period = ndof // n, 2 * band + 1
    comb = np.zeros(ndof)
    for f in range(blocks):
        for c in range(period):
            sel = np.arange(c, n, period)
            if window is not None:
                sel = sel[(sel >= window[0]) & (sel <= window[-1])]
            comb[:] = 0.0
            comb[f * n + sel] = 1.0
            yield f, c, op(comb)


def _offsets(n: int, band: int, c: int):
    """(d, rows): for each offset d in [−band, band], the slice of sites s ≡ c − d (mod 2·band + 1)
    with 0 ≤ s + d < n (the rows whose entry in colour c's product is the column at s + d)."""
    period = 2 * band + 1
    for d in range(-band, band + 1):
        first = (c - d) % period
        while first + d < 0:
            first += period
        last = n - 1 - max(d, 0)  # s + d ≤ n − 1
        yield d, slice(first, last + 1, period)


def banded_row_sums(op: Operator, n: int, ndof: int, band: int, seed: int = 0) -> np.ndarray | None:
    """Σ_j |A_ij| over the columns j of each field (and of the extra DOFs) for every row i of the
    symmetric operator ``op`` on R^ndof: shape (blocks + 1, ndof), the last row the extra DOFs'
    columns; from (2·band + 1)·blocks + extras products, or None when ``op`` is not banded that way.

    Assumed: a lattice DOF (``_combs``) couples only lattice DOFs of sites at most ``band`` apart,
    and extra DOFs (k ≥ blocks·n, each probed alone). A comb's product holds in row i the one
    entry A_ik of its column k near site(i) (colouring of a banded sparse matrix: Curtis, Powell
    & Reid 1974). The assumption is checked, not trusted: A x for a random x is rebuilt from the
    products and compared with ``op(x)``; a coupling outside the band makes them differ at O(1),
    and a mismatch above ``BAND_CHECK_TOL`` returns None.
    """
    return _banded_pass(op, n, ndof, band, seed)[0]


def _banded_pass(op: Operator, n: int, ndof: int, band: int, seed: int = 0,
                 window: np.ndarray | None = None) -> tuple[np.ndarray | None, np.ndarray | None]:
    """``banded_row_sums`` and, with ``window`` (consecutive sites), the principal submatrix over
    its lattice DOFs (``banded_window``) read from the same products."""
    blocks = ndof // n if n else 0
    lat = blocks * n
    if n < 2 * band + 1 or lat == 0:
        return None, None
    x = np.random.default_rng(seed).standard_normal(ndof)
    rebuilt, sums = np.zeros(ndof), np.zeros((blocks + 1, ndof))
    sub = None if window is None else np.zeros((blocks * window.size, blocks * window.size))
    for f, c, y in _combs(op, n, ndof, band):
        if sub is not None:
            _window_entries(sub, y, n, blocks, band, f, c, window)
        sums[f, :lat] += np.abs(y[:lat])
        xf = x[f * n : (f + 1) * n]
        for g in range(blocks):
            yg, rg = y[g * n : (g + 1) * n], rebuilt[g * n : (g + 1) * n]
            for d, rows in _offsets(n, band, c):
                cols = slice(rows.start + d, rows.stop + d, rows.step)
                rg[rows] += yg[rows] * xf[cols]
    e = np.zeros(ndof)
    for k in range(lat, ndof):  # extra DOFs: row k = column k (symmetric)
        e[k] = 1.0
        y = op(e)
        e[k] = 0.0
        sums[-1, :lat] += np.abs(y[:lat])
        rebuilt[:lat] += y[:lat] * x[k]
        for g in range(blocks):
            sums[g, k] = float(np.sum(np.abs(y[g * n : (g + 1) * n])))
        sums[-1, k] = float(np.sum(np.abs(y[lat:])))
        rebuilt[k] = float(np.sum(y * x))
    ax = op(x)
    if float(np.max(np.abs(ax - rebuilt))) > BAND_CHECK_TOL * max(float(np.max(np.abs(ax))), 1e-300):
        return None, None
    return sums, None if sub is None else 0.5 * (sub + sub.T)


def _window_entries(a: np.ndarray, y: np.ndarray, n: int, blocks: int, band: int, f: int, c: int,
                    window: np.ndarray) -> None:
    """Write into ``a`` the entries of colour (f, c)'s product ``y`` whose row and column both lie
    on the sites ``window`` (consecutive)."""
    w, lo = window.size, int(window[0])
    for g in range(blocks):
        for d, rows in _offsets(n, band, c):
            first, stop = max(lo, lo - d, rows.start), min(lo + w, lo + w - d, rows.stop)
            first = rows.start + -(-(first - rows.start) // rows.step) * rows.step  # ≡ rows.start
            s = np.arange(first, stop, rows.step)
            a[g * w + s - lo, f * w + s + d - lo] = y[g * n + s]


def banded_window(op: Operator, n: int, ndof: int, band: int, window: np.ndarray) -> np.ndarray:
    """The principal submatrix of the banded symmetric ``op`` (``banded_row_sums``) over the lattice
    DOFs of the consecutive sites ``window``, field-major: shape (blocks·w, blocks·w)."""
    blocks = ndof // n
    a = np.zeros((blocks * window.size, blocks * window.size))
    for f, c, y in _combs(op, n, ndof, band, window):
        _window_entries(a, y, n, blocks, band, f, c, window)
    return 0.5 * (a + a.T)


def banded_bounds(op: Operator, n: int, ndof: int, tight: float = math.inf) -> tuple[float, float] | None:
    """(lower, upper) bounds of λ_max of a banded symmetric ``op`` (``banded_row_sums``), or None
    when it is not banded within ``BANDS`` for at most ``MAX_PROBES`` products.

    Upper: Gershgorin for D⁻¹ A D (same eigenvalues, any positive diagonal D), λ_max ≤
    max_i Σ_j |A_ij| d_j / d_i, the smaller of d = 1 and d constant per field at the RMS of the
    field in the lower bound's eigenvector (near the optimum for a lattice whose fastest mode
    mixes fields in a fixed ratio; extra DOFs d = 1). Lower: λ_max of the principal submatrix
    over ``WINDOW_SITES`` sites (Cauchy interlacing: a principal submatrix's eigenvalues lie
    within the whole's), read from the same products for the middle of the lattice, and, when
    upper > ``tight`` × lower, also probed about the row of the largest sum. Both rigorous up to
    the central differences' error (~1e-9); the cost is O(band · fields) products, not the
    O(100)–O(1000) of Lanczos.
    """
    blocks = ndof // n if n else 0
    for band in BANDS:
        if (2 * band + 1) * blocks * 2 + (ndof - blocks * n) + 1 > MAX_PROBES:
            return None
        sums, sub = _banded_pass(op, n, ndof, band, window=_window_about(n // 2, n))
        if sums is None:
            continue
        lower, upper = _bounds(sums, sub, n)
        if upper > tight * lower:
            top = int(np.argmax(sums.sum(axis=0)))
            window = _window_about(top % n if top < blocks * n else 0, n)
            lower, upper = max((lower, upper), _bounds(sums, banded_window(op, n, ndof, band, window), n))
        return lower, upper
    return None


def _window_about(centre: int, n: int) -> np.ndarray:
    lo = min(max(centre - WINDOW_SITES // 2, 0), max(n - WINDOW_SITES, 0))
    return np.arange(lo, min(lo + WINDOW_SITES, n))


def _bounds(sums: np.ndarray, sub: np.ndarray, n: int) -> tuple[float, float]:
    """(λ_max of the window ``sub``, the Gershgorin bound: plain, or scaled by the window's top
    eigenvector, whichever is smaller) — see ``banded_bounds``."""
    blocks, ndof = sums.shape[0] - 1, sums.shape[1]
    with single_blas_thread():
        lam, vec = np.linalg.eigh(sub)
    total = sums.sum(axis=0)
    upper = float(np.max(total))
    d = np.sqrt(np.mean(vec[:, -1].reshape(blocks, -1) ** 2, axis=1))
    if np.all(d > 0):
        d = np.append(d / d.max(), 1.0)
        own = np.append(np.repeat(d[:-1], n), np.ones(ndof - blocks * n))  # d_i of each row
        upper = min(upper, float(np.max(d @ sums / own)))
    return float(lam[-1]), upper
