"""Regressing received rewards on the past: the estimator of deconvolution Q-learning.

:class:`RewardRegression` keeps the sufficient statistics of the regression of each received
reward on the (state, action) pairs before it (:mod:`delayed_rl.compiled.deconvolution_statistics`),
in a direct or a hashed layout, and solves the least squares for the mean rewards ``R̂`` and,
when it is learned, the delay pmf. The statistics, the normal equations and the sizes are on the
docs' agents page (``docs/agents.md``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from delayed_rl._numba import jit as _jit
from delayed_rl.agents.common.hyperparameters import MAX_ABS_VALUE
from delayed_rl.compiled.deconvolution_statistics import Statistics, find_row, hash_slot, observe

__all__ = [
    "DENSE_SOLVE_PAIRS",
    "DIRECT_LIMIT",
    "STATISTICS_LIMIT",
    "RewardRegression",
    "project_to_simplex",
    "statistics_bytes",
]

STATISTICS_LIMIT = 256 * 2**20
"""The most bytes the co-occurrence counts may take, in either layout: 256 MiB.

GridWorld-9x9 with delays up to 50 steps takes 21 MiB (direct). In the hashed layout the table
grows with the couples seen; a run that would take it past the limit stops with an error that
names ``max_delay_estimate``.
"""
DIRECT_LIMIT = 64 * 2**20
"""The direct layout (``(K + 1)·P²`` counts, no lookups) is used up to this many bytes: 64 MiB."""
DENSE_SOLVE_PAIRS = 512
"""Up to this many (state, action) pairs ``R̂`` is solved by dense Cholesky; above, by sparse CG."""
_CG_TOLERANCE = 1e-10  # relative residual at which conjugate gradients stop
_CG_MAX_ITERATIONS = 2_000
_FIRST_ROWS = 1024  # the hashed table's first size
_EIGENVALUE_TOLERANCE = 1e-12  # relative change at which the power iteration stops
_EIGENVALUE_ITERATIONS = 1_000


@_jit
def _tail_products(p):
    """``T[u, v] = Σ_h p(h + u) p(h + v)`` over ``h = 1..K − max(u, v)``: rows after an end.

    The row ``h`` steps after a segment's end would weigh the window's pair ``u`` steps before
    the end by ``p(h + u)``; the sums over ``h`` of those rows' products, one per (u, v).
    """
    k1 = p.shape[0]
    t = np.zeros((k1, k1))
    for u in range(k1):
        for v in range(u, k1):
            total = 0.0
            for h in range(1, k1 - v):
                total += p[h + u] * p[h + v]
            t[u, v] = total
            t[v, u] = total
    return t


@_jit
def _add_coupling(vals, diag, keys, n_pairs, x, y, value):
    """Add ``value`` to ``A[x, y]`` and ``A[y, x]``: to the couple's row, or twice to ``A[x, x]``."""
    if x == y:
        diag[x] += 2.0 * value
        return
    row = find_row(keys, n_pairs, x, y)  # a window's couples occurred, (later, earlier) first
    if row < 0:
        row = find_row(keys, n_pairs, y, x)
    if row < 0:
        raise ValueError("a window couples two pairs the statistics never counted")
    vals[row] += value


@_jit
def _window_corrections(vals, diag, b, stats, windows, lengths, finals, flushed, p):
    """Subtract the rows after each window's segment end; swap flushed last rows for ψ rows.

    ``vals`` (one coupling per row of the statistics), ``diag`` and ``b`` are
    corrected in place for the ``p``-weighted normal equations; a flushed last row weighs the
    pair ``u`` steps back by ``P(D ≥ u)`` instead of ``p(u)``.
    """
    keys, n_pairs = stats.keys, stats.counters[5]
    tail = _tail_products(p)
    survival = np.zeros(p.shape[0])
    total = 0.0
    for k in range(p.shape[0] - 1, -1, -1):
        total += p[k]
        survival[k] = total
    for w in range(windows.shape[0]):
        length = lengths[w]
        window = windows[w]
        for u in range(length):
            x = window[u]
            change = -tail[u, u]
            if flushed[w]:
                change += survival[u] * survival[u] - p[u] * p[u]
                b[x] += finals[w] * survival[u]
            diag[x] += change
            for v in range(u + 1, length):
                change = -tail[u, v]
                if flushed[w]:
                    change += survival[u] * survival[v] - p[u] * p[v]
                if change != 0.0:
                    _add_coupling(vals, diag, keys, n_pairs, x, window[v], change)


@_jit
def _dot(a, b):
    """``Σ_i a[i] · b[i]`` in four running sums (a fixed order).

    Written out because numba compiles ``@`` and ``np.dot`` to BLAS calls that need SciPy,
    which is not a dependency; the sum also does not depend on which BLAS is installed.
    """
    s0 = s1 = s2 = s3 = 0.0
    n = a.shape[0]
    whole = n - n % 4
    for i in range(0, whole, 4):
        s0 += a[i] * b[i]
        s1 += a[i + 1] * b[i + 1]
        s2 += a[i + 2] * b[i + 2]
        s3 += a[i + 3] * b[i + 3]
    for i in range(whole, n):
        s0 += a[i] * b[i]
    return (s0 + s1) + (s2 + s3)


@_jit
def _matrix_vector(g, v):
    """``g @ v`` for a 2-d ``g``, each entry a :func:`_dot`."""
    out = np.empty(g.shape[0])
    for k in range(g.shape[0]):
        out[k] = _dot(g[k], v)
    return out


@_jit
def _vector_matrix(v, g):
    """``v @ g`` for a 2-d ``g``: entry j sums ``v[k] · g[k, j]`` in the order of ``k``."""
    out = np.zeros(g.shape[1])
    for k in range(g.shape[0]):
        for j in range(g.shape[1]):
            out[j] += v[k] * g[k, j]
    return out


@_jit
def _lag_products(p):
    """``c(m) = Σ_k p(k) · p(k + m)`` for ``m = 0..K``, each a :func:`_dot`."""
    k1 = p.shape[0]
    out = np.empty(k1)
    for m in range(k1):
        out[m] = _dot(p[: k1 - m], p[m:])
    return out


@_jit
def _largest_eigenvalue(g, tolerance, max_iterations):
    """The largest eigenvalue of the symmetric positive semi-definite ``g``, by power iteration.

    From the unit vector of equal entries, the Rayleigh quotient ``vᵀ g v`` of the iterates,
    until it changes by at most ``tolerance`` of itself (or ``max_iterations``). It approaches
    the eigenvalue from below; a projected gradient with steps ``1 / λ`` still descends while
    ``λ`` is above half the true value. 0 for a zero matrix.
    """
    n = g.shape[0]
    v = np.full(n, 1.0 / np.sqrt(n))
    value = 0.0
    for _ in range(max_iterations):
        w = _matrix_vector(g, v)
        previous, value = value, _dot(v, w)
        norm = np.sqrt(_dot(w, w))
        if norm == 0.0:
            return 0.0
        v = w / norm
        if abs(value - previous) <= tolerance * abs(value):
            break
    return value


@_jit
def _coupled_product(later, earlier, vals, diag, v, out):
    """``out = A v`` for ``A = Σ_n vals[n] (e_later e_earlierᵀ + e_earlier e_laterᵀ) + diag(diag)``."""
    for i in range(v.shape[0]):
        out[i] = diag[i] * v[i]
    for n in range(vals.shape[0]):
        i, j, w = later[n], earlier[n], vals[n]
        out[i] += w * v[j]
        out[j] += w * v[i]


@_jit
def _conjugate_gradient(later, earlier, vals, diag, b, start, tolerance, max_iterations):
    """Solve ``A x = b`` (``A`` as in :func:`_coupled_product`, positive definite) from ``start``.

    Jacobi-preconditioned conjugate gradients, until the residual is below ``tolerance · |b|``.
    """
    n = b.shape[0]
    precondition = diag.copy()
    for m in range(vals.shape[0]):
        if later[m] == earlier[m]:
            precondition[later[m]] += 2.0 * vals[m]
    x = start.copy()
    product = np.zeros(n)
    _coupled_product(later, earlier, vals, diag, x, product)
    residual = b - product
    z = residual / precondition
    direction = z.copy()
    rz = _dot(residual, z)
    goal = tolerance * np.sqrt(_dot(b, b))
    for _ in range(max_iterations):
        if np.sqrt(_dot(residual, residual)) <= goal:
            break
        _coupled_product(later, earlier, vals, diag, direction, product)
        step = rz / _dot(direction, product)
        x += step * direction
        residual -= step * product
        z = residual / precondition
        rz_next = _dot(residual, z)
        direction = z + (rz_next / rz) * direction
        rz = rz_next
    return x


@_jit
def _couple(keys, row):
    """The key ``later·P + earlier`` of a row of statistics of hashed ``keys`` (-1: a free row)."""
    return keys[row] if keys.shape[0] else row


@_jit
def _row_couplings(stats, c):
    """Each row's coupling ``Σ_{m ≥ 1} c(m) · cooc[row, m]``, and the lag-0 diagonal ``c(0)·n``.

    A lag-0 count only ever pairs a step with itself, so it lies on ``A``'s diagonal.
    """
    cooc = stats.cooc
    n_pairs = stats.counters[5]
    vals = np.zeros(cooc.shape[0])
    diag = np.zeros(n_pairs)
    k1 = cooc.shape[1]
    for row in range(cooc.shape[0]):
        s0 = s1 = s2 = s3 = 0.0  # four running sums: a fixed order, four times the ILP
        m = 1
        while m + 4 <= k1:
            s0 += c[m] * cooc[row, m]
            s1 += c[m + 1] * cooc[row, m + 1]
            s2 += c[m + 2] * cooc[row, m + 2]
            s3 += c[m + 3] * cooc[row, m + 3]
            m += 4
        while m < k1:
            s0 += c[m] * cooc[row, m]
            m += 1
        vals[row] = (s0 + s1) + (s2 + s3)
        if cooc[row, 0]:
            diag[_couple(stats.keys, row) // n_pairs] += c[0] * cooc[row, 0]
    return vals, diag


@_jit
def _dense_matrix(stats, vals, diag):
    """``A = Σ_rows vals (e_later e_earlierᵀ + e_earlier e_laterᵀ) + diag(diag)``, dense."""
    n_pairs = stats.counters[5]
    a = np.zeros((n_pairs, n_pairs))
    for row in range(vals.shape[0]):
        if vals[row] != 0.0:
            key = _couple(stats.keys, row)
            later, earlier = key // n_pairs, key % n_pairs
            a[later, earlier] += vals[row]
            a[earlier, later] += vals[row]
    for x in range(n_pairs):
        a[x, x] += diag[x]
    return a


@_jit
def _factor_rows(u, first, count, n):
    """Finish rows ``first .. first + count - 1`` of :func:`_cholesky_factor`'s ``U``.

    Each row has had every row above ``first`` subtracted; the rows of the block above it are
    subtracted now, in order, then the row is divided by its diagonal's square root.

    Raises:
        ValueError: a diagonal is not positive (``a`` is not positive definite).
    """
    for r in range(first, first + count):
        row = u[r]
        for q in range(first, r):
            factor = u[q, r]
            above = u[q]
            for k in range(np.uint64(r), np.uint64(n)):  # unsigned: no negative-index wrap,
                row[k] -= factor * above[k]  # so the row's update compiles to vector code
        pivot = row[r]
        if not pivot > 0.0:
            raise ValueError("the normal equations are not positive definite")
        pivot = np.sqrt(pivot)
        row[r] = pivot
        for k in range(np.uint64(r + 1), np.uint64(n)):
            row[k] /= pivot


@_jit
def _cholesky_factor(a):
    """Overwrite the upper triangle of a symmetric positive definite ``a`` with ``U``, ``a = UᵀU``.

    Right-looking, by rows: row ``j`` of ``U`` is row ``j`` of what is left of ``a``, divided by
    the square root of its diagonal, and is then subtracted (times ``U[j, i]``) from every row
    ``i`` below it. Rows are finished four at a time, and each entry below them takes the four
    subtractions in a row (one pass over the rows below instead of four); every entry still
    takes its subtractions one by one, in the order of ``j``, so the result has the bits of the
    one-row order whatever the blocking, and no entry's sum is reordered to vectorize (each
    row update is an element-wise ``row -= factor · above``, compiled to vector code).
    """
    n = a.shape[0]
    j = 0
    while j + 4 <= n:
        _factor_rows(a, j, 4, n)
        u0, u1, u2, u3 = a[j], a[j + 1], a[j + 2], a[j + 3]
        for i in range(j + 4, n):
            f0, f1, f2, f3 = u0[i], u1[i], u2[i], u3[i]
            row = a[i]
            for k in range(np.uint64(i), np.uint64(n)):
                row[k] = (((row[k] - f0 * u0[k]) - f1 * u1[k]) - f2 * u2[k]) - f3 * u3[k]
        j += 4
    _factor_rows(a, j, n - j, n)


@_jit
def _cholesky_solve(a, b):
    """``x`` with ``a x = b`` for a symmetric positive definite ``a`` (overwritten), by Cholesky.

    Written out rather than LAPACK's: single-threaded, so a solve never waits on BLAS threads
    that compete with other work for the cores, and its result does not depend on their number
    or on which BLAS is installed.
    """
    _cholesky_factor(a)
    n = a.shape[0]
    x = b.copy()
    for i in range(n):  # Uᵀ y = b: y_i, then its share taken from the entries after it
        x[i] /= a[i, i]
        share = x[i]
        row = a[i]
        for k in range(np.uint64(i + 1), np.uint64(n)):
            x[k] -= share * row[k]
    for i in range(n - 1, -1, -1):  # U x = y
        total = x[i]
        for k in range(i + 1, n):
            total -= a[i, k] * x[k]
        x[i] = total / a[i, i]
    return x


@_jit
def _sparse_couplings(stats, vals):
    """The rows of non-zero coupling as ``(later, earlier, value)`` arrays (for CG)."""
    n_pairs = stats.counters[5]
    n = 0
    for row in range(vals.shape[0]):
        n += vals[row] != 0.0
    later = np.zeros(n, dtype=np.int64)
    earlier = np.zeros(n, dtype=np.int64)
    values = np.zeros(n)
    i = 0
    for row in range(vals.shape[0]):
        if vals[row] != 0.0:
            key = _couple(stats.keys, row)
            later[i], earlier[i], values[i] = key // n_pairs, key % n_pairs, vals[row]
            i += 1
    return later, earlier, values


@_jit
def _lag_quadratic_forms(stats, reward):
    """``q[m] = Σ_rows cooc[row, m] · R(later) · R(earlier)``: ``Rᵀ C_m R`` for every lag."""
    cooc = stats.cooc
    n_pairs = stats.counters[5]
    q = np.zeros(cooc.shape[1])
    for row in range(cooc.shape[0]):
        key = _couple(stats.keys, row)
        if key < 0:
            continue
        weight = reward[key // n_pairs] * reward[key % n_pairs]
        if weight != 0.0:
            for m in range(cooc.shape[1]):
                q[m] += weight * cooc[row, m]
    return q


@_jit
def _counts_at_lag(stats, lag):
    """``C[i, j]`` for one lag: pair ``i`` followed ``lag`` steps later by pair ``j``."""
    n_pairs = stats.counters[5]
    out = np.zeros((n_pairs, n_pairs), dtype=np.int64)
    for row in range(stats.cooc.shape[0]):
        key = _couple(stats.keys, row)
        if key >= 0 and stats.cooc[row, lag]:
            out[key % n_pairs, key // n_pairs] = stats.cooc[row, lag]
    return out


@_jit
def _delay_gram_corrections(g, z, windows, lengths, finals, flushed, reward):
    """The same corrections for the regression on ``p`` given the mean rewards ``reward``."""
    k_max = g.shape[0] - 1
    for w in range(windows.shape[0]):
        length = lengths[w]
        window = windows[w]
        for h in range(1, k_max + 1):
            for k in range(h, min(k_max + 1, h + length)):
                rk = reward[window[k - h]]
                for m in range(h, min(k_max + 1, h + length)):
                    g[k, m] -= rk * reward[window[m - h]]
        if flushed[w]:
            # the flushed last row: y_T ≈ Σ_m p(m) Σ_{u ≤ m} R(x_{T−u}); the p-row replaced
            zf = np.zeros(k_max + 1)
            zp = np.zeros(k_max + 1)
            total = 0.0
            for m in range(k_max + 1):
                if m < length:
                    total += reward[window[m]]
                    zp[m] = reward[window[m]]
                zf[m] = total
            for k in range(k_max + 1):
                z[k] += finals[w] * zf[k]
                for m in range(k_max + 1):
                    g[k, m] += zf[k] * zf[m] - zp[k] * zp[m]


@_jit
def project_to_simplex(v: np.ndarray) -> np.ndarray:
    """The Euclidean projection of ``v`` onto the probability simplex (Held et al.'s algorithm)."""
    u = np.sort(v)[::-1]
    cumulative = np.cumsum(u) - 1.0
    theta = cumulative[0]
    for rho in range(v.size):
        if u[rho] - cumulative[rho] / (rho + 1.0) > 0:
            theta = cumulative[rho] / (rho + 1.0)
    return np.maximum(v - theta, 0.0)


@_jit
def _projected_gradient(g, z, start, scale, iterations):
    """Minimise ``½ pᵀGp − zᵀp`` over the simplex from ``start``, with steps ``1 / scale``."""
    p = start.copy()
    for _ in range(iterations):
        p = project_to_simplex(p - (_matrix_vector(g, p) - z) / scale)
    return p


def statistics_bytes(n_pairs: int, max_delay_estimate: int) -> int:
    """The bytes :class:`RewardRegression` starts with, and its solves' workspace, before any.

    The counts (the direct layout's ``(K + 1)·P²`` int32 while they fit :data:`DIRECT_LIMIT`,
    else the hashed table's first rows), the reward sums ``by_lag`` (``(K + 1)·P`` float64),
    the windows and the warm start; a solve's dense matrices (three ``P × P`` float64 up to
    :data:`DENSE_SOLVE_PAIRS` pairs, else a few vectors of ``P``) and the delay's Gram matrix
    (three ``(K + 1)²`` float64). A hashed table then grows with the couples seen, up to
    :data:`STATISTICS_LIMIT`.

    Args:
        n_pairs: ``P``, the (state, action) pairs.
        max_delay_estimate: ``K``.
    """
    k1 = max_delay_estimate + 1
    direct = k1 * n_pairs * n_pairs * 4
    counts = direct if direct <= DIRECT_LIMIT else _FIRST_ROWS * (k1 * 4 + 8)
    solve = 24 * n_pairs * (n_pairs if n_pairs <= DENSE_SOLVE_PAIRS else 4) + 24 * k1 * k1
    return counts + 8 * k1 * n_pairs + 8 * n_pairs + 16 * k1 + solve


class RewardRegression:
    """Sufficient statistics of the reward-on-past regression, and its least-squares solves.

    Args:
        n_pairs: how many (state, action) pairs (``|S|·|A|``).
        max_delay_estimate: ``K``, the longest delay modelled.
        flush: the last step of an ending segment carries every pending reward (the reward-delay
            wrapper's ``"flush"``); ``False`` for ``"drop"`` (those rewards never come).
        carry: pending rewards carry over episode ends (``"carry"``): the stream is one segment.
        layout: ``"direct"``, ``"hashed"`` or ``None`` (default: direct while its counts fit
            :data:`DIRECT_LIMIT`).

    Raises:
        ValueError: the direct layout would take more than :data:`STATISTICS_LIMIT` bytes, or
            ``layout`` is unknown.
    """

    def __init__(
        self,
        n_pairs: int,
        max_delay_estimate: int,
        flush: bool = True,
        carry: bool = False,
        layout: str | None = None,
    ):
        k = max_delay_estimate + 1
        direct = k * n_pairs * n_pairs * 4
        if layout is None:
            layout = "direct" if direct <= DIRECT_LIMIT else "hashed"
        if layout not in ("direct", "hashed"):
            raise ValueError(f"layout must be 'direct', 'hashed' or None, got {layout!r}")
        if layout == "direct" and direct > STATISTICS_LIMIT:
            raise ValueError(
                f"max_delay_estimate={max_delay_estimate} with {n_pairs} (state, action) pairs needs "
                f"{direct / 2**20:,.0f} MiB of co-occurrence counts in the direct layout, more "
                f"than the limit of {STATISTICS_LIMIT / 2**20:.0f} MiB: choose a shorter "
                "max_delay_estimate or the hashed layout"
            )
        self.n_pairs, self.max_delay_estimate, self.flush, self.carry = (
            n_pairs,
            max_delay_estimate,
            flush,
            carry,
        )
        rows = n_pairs * n_pairs if layout == "direct" else _FIRST_ROWS
        keys = np.zeros(0, np.int64) if layout == "direct" else np.full(rows, -1, np.int64)
        self.stats = Statistics(
            np.zeros((rows, k), dtype=np.int32),
            keys,
            np.zeros((k, n_pairs)),
            np.zeros(k, dtype=np.int64),
            np.array([0, 0, 0, int(flush), int(carry), n_pairs, 0], dtype=np.int64),
            np.zeros((1, k), dtype=np.int64),
            np.zeros(1, dtype=np.int64),
            np.zeros(1),
            np.zeros(1, dtype=np.bool_),
        )
        self._last_rewards = np.zeros(n_pairs)  # the conjugate gradients' warm start

    @property
    def layout(self) -> str:
        """``"direct"`` or ``"hashed"`` (see :mod:`delayed_rl.compiled.deconvolution_statistics`)."""
        return "hashed" if self.stats.keys.size else "direct"

    @property
    def steps(self) -> int:
        """How many steps the statistics hold."""
        return int(self.stats.counters[1])

    @property
    def nbytes(self) -> int:
        """The bytes the co-occurrence rows take (counts and, hashed, keys)."""
        return self.stats.cooc.nbytes + self.stats.keys.nbytes

    def counts(self, lag: int) -> np.ndarray:
        """``C[i, j]``: how often pair ``i`` was followed ``lag`` steps later by pair ``j``."""
        return _counts_at_lag(self.stats, lag)

    def reserve(self, steps: int) -> None:
        """Make room for ``steps`` more steps: their segment ends and, hashed, their new rows.

        Raises:
            ValueError: the hashed table would grow past :data:`STATISTICS_LIMIT` (the message
                names ``max_delay_estimate``).
        """
        stats = self.stats
        needed = int(stats.counters[2]) + steps
        if needed > stats.end_lengths.shape[0]:
            size = max(needed, 2 * stats.end_lengths.shape[0])
            grown = [np.zeros((size,) + a.shape[1:], dtype=a.dtype) for a in stats[5:]]
            for new, old in zip(grown, stats[5:], strict=True):
                new[: old.shape[0]] = old
            stats = stats._replace(
                end_windows=grown[0],
                end_lengths=grown[1],
                end_rewards=grown[2],
                end_flushed=grown[3],
            )
        if stats.keys.size:  # at most half full after the steps' new rows
            rows = 2 * (int(stats.counters[6]) + steps * (self.max_delay_estimate + 1))
            if rows > stats.keys.size:
                size = 1 << (rows - 1).bit_length()
                nbytes = size * (stats.cooc.shape[1] * 4 + 8)
                if nbytes > STATISTICS_LIMIT:
                    raise ValueError(
                        f"max_delay_estimate={self.max_delay_estimate}: the co-occurrence rows of "
                        f"{self.steps:,} steps over {self.n_pairs} (state, action) pairs would "
                        f"take {nbytes / 2**20:,.0f} MiB, more than the limit of "
                        f"{STATISTICS_LIMIT / 2**20:.0f} MiB: choose a shorter max_delay_estimate"
                    )
                keys, cooc = _rehash(stats.keys, stats.cooc, size)
                stats = stats._replace(keys=keys, cooc=cooc)
        self.stats = stats

    def state(self) -> dict[str, np.ndarray]:
        """The statistics as arrays (for a model file), the end arrays cut to their use."""
        ends = int(self.stats.counters[2])
        return {
            name: (value[:ends] if index >= 5 else value).copy()
            for index, (name, value) in enumerate(zip(Statistics._fields, self.stats, strict=True))
        }

    def restore(self, arrays: dict[str, np.ndarray], prefix: str = "") -> None:
        """Restore what :meth:`state` returned, checking every array's shape, type and values.

        Either layout loads, whichever the agent would choose; so do the statistics of earlier
        versions (counts as ``cooc[m, i, j]``, five counters, no keys). The checks: each array
        has the shape and dtype the statistics of ``K`` and ``P`` have; the counts and keys take
        at most :data:`STATISTICS_LIMIT` bytes; the counters are in range (the window's length
        within ``K + 1``, as many segment ends as arrays of them, the episode-end mode this
        one, the hashed table's rows in use counted and at most half of it); the lag-0 counts
        add up to the step count (one a step); counts are ``>= 0`` and a free hashed row holds
        none; every window holds pairs of the env, an ended window's length is in
        ``1..K + 1``, every end is flushed exactly under ``"flush"`` (none under ``"carry"``,
        whose stream never ends) and only a flushed one holds a reward; the reward sums are
        finite and within the step count times
        :data:`~delayed_rl.agents.common.hyperparameters.MAX_ABS_VALUE` (each sums at most one reward
        a step). Nothing is restored unless every check passes.

        Args:
            arrays: the arrays, by the names of :class:`~delayed_rl.compiled.deconvolution_statistics.Statistics`.
            prefix: what the messages put before those names (a model file's
                ``"regression_"``).

        Raises:
            ValueError: an array is missing, of the wrong shape or type, or out of range (the
                message names it).
        """
        _check_present(arrays, prefix)
        arrays = _upgraded(dict(arrays), self.n_pairs)
        rows = _table_rows(arrays, self.n_pairs, prefix)
        self._check_types(arrays, rows, prefix)
        arrays = {
            name: arrays[name].astype(ours.dtype, copy=False) for name, ours in self._fields()
        }
        _check_bytes(arrays["cooc"], arrays["keys"], prefix)
        counters = arrays["counters"]
        self._check_counters(counters, arrays["end_lengths"].shape[0], prefix)
        steps, used = int(counters[1]), int(counters[6])
        _check_counts(arrays["cooc"], steps, prefix)
        _check_table(arrays["keys"], arrays["cooc"], used, self.n_pairs, prefix)
        self._check_windows(arrays, prefix)
        _check_reward_sums(arrays, steps, prefix)
        self.stats = Statistics(*(arrays[name].copy() for name in Statistics._fields))
        self.reserve(1)

    def _check_types(self, arrays: dict[str, Any], rows: int, prefix: str) -> None:
        """Refuse an array that is not of the dtype and shape of this regression's statistics.

        The shapes follow from ``K``, ``P``, the counts' ``rows`` (:func:`_table_rows`) and the
        end arrays' length; a byte order other than the machine's is accepted.

        Raises:
            ValueError: naming the first array of :class:`Statistics`' order that is not.
        """
        k1, n_pairs = self.max_delay_estimate + 1, self.n_pairs
        ends = arrays["end_lengths"].shape[0]
        shapes = {
            "cooc": (rows, k1),
            "keys": arrays["keys"].shape,
            "by_lag": (k1, n_pairs),
            "window": (k1,),
            "counters": (7,),
            "end_windows": (ends, k1),
            "end_lengths": (ends,),
            "end_rewards": (ends,),
            "end_flushed": (ends,),
        }
        for name, ours in self._fields():
            value = arrays[name]
            if (
                not isinstance(value, np.ndarray)
                or value.dtype.newbyteorder("=") != ours.dtype
                or value.shape != shapes[name]
            ):
                got = (
                    f"{value.dtype} array of shape {value.shape}"
                    if isinstance(value, np.ndarray)
                    else repr(value)
                )
                per_end = f" (one row per {prefix}end_lengths entry)" if "end_" in name else ""
                raise ValueError(
                    f"{prefix}{name} must be a {ours.dtype} array of shape {shapes[name]}"
                    f"{per_end}, got {got}"
                )

    def _check_counters(self, counters: np.ndarray, ends: int, prefix: str) -> None:
        """Refuse counters out of range, or of another episode-end mode than this one's.

        Raises:
            ValueError: the window's length is not in ``0..K + 1``, the steps are negative, the
                segment ends are not ``ends`` (the end arrays' length) or the pairs not ``P``;
                or the flush and carry flags are not this regression's.
        """
        k1, n_pairs = self.max_delay_estimate + 1, self.n_pairs
        length, steps, n_ends, flush, carry, pairs, _ = (int(v) for v in counters)
        if not 0 <= length <= k1 or steps < 0 or n_ends != ends or pairs != n_pairs:
            raise ValueError(
                f"{prefix}counters must be [window length in 0..{k1}, steps >= 0, segment ends "
                f"= {ends} (the end arrays' length), flush, carry, pairs = {n_pairs}, rows in "
                f"use], got {counters.tolist()}"
            )
        if (flush, carry) != (int(self.flush), int(self.carry)):
            raise ValueError(
                f"{prefix}counters' flush and carry ({flush}, {carry}) disagree with the "
                f"episode-end mode ({int(self.flush)}, {int(self.carry)})"
            )

    def _check_windows(self, arrays: dict[str, np.ndarray], prefix: str) -> None:
        """Refuse windows that do not hold the env's pairs, or segment ends this mode cannot have.

        Raises:
            ValueError: a window holds a pair outside ``0..P − 1``, an ended window's length is
                outside ``1..K + 1``, a carried-over stream has an end, or an end is not flushed
                exactly under ``"flush"``.
        """
        k1, n_pairs = self.max_delay_estimate + 1, self.n_pairs
        indices = np.concatenate([arrays["window"], arrays["end_windows"].ravel()])
        if indices.size and (indices.min() < 0 or indices.max() >= n_pairs):
            raise ValueError(
                f"{prefix}window and {prefix}end_windows must hold pairs in 0..{n_pairs - 1}"
            )
        lengths, flushed = arrays["end_lengths"], arrays["end_flushed"]
        ends = lengths.shape[0]
        if ends and (lengths.min() < 1 or lengths.max() > k1):
            raise ValueError(f"{prefix}end_lengths must hold lengths in 1..{k1}")
        if self.carry and ends:
            raise ValueError(f"{prefix}end_lengths: a carried-over stream has no segment ends")
        if np.any(flushed != self.flush):
            raise ValueError(
                f"{prefix}end_flushed must be {self.flush} for every end (the episode-end mode)"
            )

    def _fields(self) -> list[tuple[str, Any]]:
        """``(name, array)`` of each statistic, in :class:`Statistics`' order."""
        return list(zip(Statistics._fields, self.stats, strict=True))

    # ------------------------------------------------------------------ observing
    def observe(self, pair: int, reward: float, episode_end: bool) -> None:
        """Add one step: the pair acted in, the reward received, whether the episode ended."""
        self.reserve(1)
        observe(self.stats, pair, reward, episode_end)

    def _windows(self) -> tuple[np.ndarray, ...]:
        """The ended segments' windows, and the open segment's (it ends, for now, here)."""
        stats = self.stats
        ends = int(stats.counters[2])
        return (
            np.vstack([stats.end_windows[:ends], stats.window[None, :]]),
            np.append(stats.end_lengths[:ends], stats.counters[0]),
            np.append(stats.end_rewards[:ends], 0.0),
            np.append(stats.end_flushed[:ends], False),
        )

    # ------------------------------------------------------------------ solving
    def _couplings(self, pmf: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The normal equations for the mean rewards as ``(vals, diag, b)``.

        ``A = Σ_rows vals[row] (e_later e_earlierᵀ + e_earlier e_laterᵀ) + diag(diag)``, one
        coupling per row of the statistics.
        """
        c = _lag_products(pmf)
        vals, diag = _row_couplings(self.stats, c)
        b = _vector_matrix(pmf, self.stats.by_lag)
        _window_corrections(vals, diag, b, self.stats, *self._windows(), pmf)
        return vals, diag, b

    def normal_equations(self, pmf: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(A, b)`` of the least-squares problem for the mean rewards, given the delay pmf.

        ``A`` dense (``P × P``): for inspection and the dense solve.
        """
        vals, diag, b = self._couplings(pmf)
        return self._dense(vals, diag), b

    def _dense(self, vals: np.ndarray, diag: np.ndarray) -> np.ndarray:
        """The dense ``A`` of :meth:`_couplings`' ``(vals, diag)``."""
        if self.layout == "hashed":
            return _dense_matrix(self.stats, vals, diag)
        half = vals.reshape(self.n_pairs, self.n_pairs)  # the direct layout: row later·P + earlier
        a = half + half.T
        a[np.diag_indices_from(a)] += diag
        return a

    @property
    def mean_reward(self) -> float:
        """The mean reward received per step so far (0 before any step)."""
        stats = self.stats
        ends = int(stats.counters[2])
        total = stats.by_lag[0].sum() + stats.end_rewards[:ends].sum()
        return float(total / self.steps) if self.steps else 0.0

    def solve_rewards(self, pmf: np.ndarray, ridge: float, prior: float = 0.0) -> np.ndarray:
        """The ridge least-squares mean rewards ``R̂`` (one per pair) for the delay pmf.

        Minimises ``Σ_t (y_t − φ_tᵀ R)² + ridge · |R − prior|²``: a pair with little evidence
        stays near ``prior``.
        """
        vals, diag, b = self._couplings(pmf)
        b = b + ridge * prior
        if self.n_pairs <= DENSE_SOLVE_PAIRS:
            rewards = _cholesky_solve(self._dense(vals, diag + ridge), b)
        else:
            rewards = _conjugate_gradient(
                *_sparse_couplings(self.stats, vals),
                diag + ridge,
                b,
                self._last_rewards,
                _CG_TOLERANCE,
                _CG_MAX_ITERATIONS,
            )
        self._last_rewards = rewards
        return rewards.copy()

    def delay_gram(self, reward: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(G, z)`` of the least-squares problem for the pmf, given the mean rewards."""
        k = self.max_delay_estimate
        q = _lag_quadratic_forms(self.stats, reward)
        lags = np.abs(np.subtract.outer(np.arange(k + 1), np.arange(k + 1)))
        g = q[lags]
        z = _matrix_vector(self.stats.by_lag, reward)
        _delay_gram_corrections(g, z, *self._windows(), reward)
        return g, z

    def solve_delay(
        self, reward: np.ndarray, start: np.ndarray, iterations: int = 300
    ) -> np.ndarray:
        """The pmf on ``0..K`` that best explains the received rewards given ``reward``.

        Projected gradient on the simplex, from ``start``, with the step set by ``G``'s largest
        eigenvalue (so each step decreases the squared error), found by power iteration in a
        fixed order (no LAPACK or BLAS, whose kernels differ between CPUs).
        """
        g, z = self.delay_gram(reward)
        scale = _largest_eigenvalue(g, _EIGENVALUE_TOLERANCE, _EIGENVALUE_ITERATIONS)
        if not scale > 0:
            return start
        return _projected_gradient(g, z, start, scale, iterations)


@_jit
def _rehash(keys, cooc, size):
    """The hashed table's rows moved into a table of ``size`` rows (a power of two)."""
    new_keys = np.full(size, -1, dtype=np.int64)
    new_cooc = np.zeros((size, cooc.shape[1]), dtype=np.int32)
    for row in range(keys.shape[0]):
        key = keys[row]
        if key == -1:
            continue
        slot = hash_slot(new_keys, key)
        new_keys[slot] = key
        new_cooc[slot] = cooc[row]
    return new_keys, new_cooc


@_jit
def _all_found(keys):
    """Whether a lookup of every key in the hashed table ``keys`` finds it where it is."""
    for row in range(keys.shape[0]):
        if keys[row] != -1 and hash_slot(keys, keys[row]) != row:
            return False
    return True


def _upgraded(arrays: dict[str, Any], n_pairs: int) -> dict[str, Any]:
    """Statistics saved by earlier versions (``cooc[m, i, j]``, no keys) in today's layout."""
    cooc = arrays.get("cooc")
    if "keys" in arrays or not isinstance(cooc, np.ndarray) or cooc.ndim != 3:
        return arrays
    arrays["cooc"] = np.ascontiguousarray(cooc.transpose(2, 1, 0)).reshape(-1, cooc.shape[0])
    arrays["keys"] = np.zeros(0, dtype=np.int64)
    counters = np.asarray(arrays["counters"])
    if counters.shape == (5,):
        arrays["counters"] = np.append(counters, [n_pairs, 0]).astype(counters.dtype)
    return arrays


def _check_present(arrays: dict[str, Any], prefix: str) -> None:
    """Refuse statistics with an array missing (``keys`` may be, in an earlier version's).

    Raises:
        ValueError: naming the missing arrays (``keys`` when only it is, the counts not being
            an earlier version's ``cooc[m, i, j]``).
    """
    missing = [name for name in Statistics._fields if name not in arrays and name != "keys"]
    if missing or ("keys" not in arrays and np.ndim(arrays.get("cooc")) != 3):
        raise ValueError(f"missing statistics: {[prefix + name for name in missing or ['keys']]}")


def _table_rows(arrays: dict[str, Any], n_pairs: int, prefix: str) -> int:
    """The rows the counts must have: the hashed table's, or the direct layout's ``P²``.

    First the arrays the other shapes follow from are checked: the keys (empty for the direct
    layout), the end lengths (one per segment end) and the counts' rows against the keys.

    Raises:
        ValueError: ``keys`` is not a 1-d int64 array of a power-of-two length (or empty),
            ``end_lengths`` is not 1-d, or a 2-d ``cooc`` has other rows than the keys say.
    """
    keys = arrays["keys"]
    if not isinstance(keys, np.ndarray) or keys.dtype != np.int64 or keys.ndim != 1:
        raise ValueError(f"{prefix}keys must be a 1-d int64 array")
    hashed = keys.size > 0
    if hashed and keys.size & (keys.size - 1):
        raise ValueError(f"{prefix}keys must have a power-of-two length, got {keys.size}")
    end_lengths, cooc = arrays["end_lengths"], arrays["cooc"]
    if not isinstance(end_lengths, np.ndarray) or end_lengths.ndim != 1:
        raise ValueError(
            f"{prefix}end_lengths must be a 1-d int64 array (one length per segment end)"
        )
    rows = keys.size if hashed else n_pairs * n_pairs
    if isinstance(cooc, np.ndarray) and cooc.ndim == 2 and cooc.shape[0] != rows:
        raise ValueError(
            f"{prefix}cooc has {cooc.shape[0]} rows but {prefix}keys says {rows} ("
            + (f"a hashed table of {rows} rows)" if hashed else f"the direct layout's {rows})")
        )
    return rows


def _check_bytes(cooc: np.ndarray, keys: np.ndarray, prefix: str) -> None:
    """Refuse counts and keys that take more than :data:`STATISTICS_LIMIT` bytes.

    Raises:
        ValueError: naming the MiB they take and the limit.
    """
    nbytes = cooc.nbytes + keys.nbytes
    if nbytes > STATISTICS_LIMIT:
        raise ValueError(
            f"{prefix}cooc and {prefix}keys take {nbytes / 2**20:,.0f} MiB, more than the "
            f"limit of STATISTICS_LIMIT = {STATISTICS_LIMIT / 2**20:.0f} MiB "
            "(delayed_rl.agents.deconvolution.regression.STATISTICS_LIMIT)"
        )


def _check_counts(cooc: np.ndarray, steps: int, prefix: str) -> None:
    """Refuse negative counts, or lag-0 counts that do not add up to ``steps`` (one a step).

    Raises:
        ValueError: a count is negative or the lag-0 counts' sum is not ``steps``.
    """
    if np.any(cooc < 0):
        raise ValueError(f"{prefix}cooc must hold counts >= 0")
    if int(cooc[:, 0].sum(dtype=np.int64)) != steps:
        raise ValueError(
            f"{prefix}cooc's lag-0 counts must add up to the step count {steps} (one a "
            f"step, {prefix}counters[1]), got {int(cooc[:, 0].sum(dtype=np.int64))}"
        )


def _check_table(keys: np.ndarray, cooc: np.ndarray, used: int, n_pairs: int, prefix: str) -> None:
    """Refuse a hashed table lookups would not read back, or a direct layout counting rows in use.

    Hashed: ``used`` (``counters[6]``) counts the keys in use, at most half the table; each key
    names a couple of the env's pairs and sits where a lookup finds it; a free row holds no
    counts. Direct: ``used`` is 0.

    Raises:
        ValueError: naming the first of those that fails.
    """
    if not keys.size:
        if used:
            raise ValueError(f"{prefix}counters[6] must be 0 in the direct layout, got {used}")
        return
    in_use = keys != -1
    if used != int(in_use.sum()) or 2 * used > keys.size:
        raise ValueError(
            f"{prefix}counters[6] (the hashed table's rows in use) must be the number "
            f"of {prefix}keys in use ({int(in_use.sum())}, at most half of "
            f"{keys.size}), got {used}"
        )
    if np.any(keys[in_use] < 0) or np.any(keys[in_use] >= n_pairs * n_pairs):
        raise ValueError(f"{prefix}keys: a key names a couple outside the env's pairs")
    if not _all_found(keys):
        raise ValueError(f"{prefix}keys: the hashed table's keys are not where lookups find them")
    if np.any(cooc[~in_use]):
        raise ValueError(f"{prefix}cooc: a free row of the hashed table holds counts")


def _check_reward_sums(arrays: dict[str, np.ndarray], steps: int, prefix: str) -> None:
    """Refuse reward sums that are not finite or too large, or a reward at an end not flushed.

    Each sum holds at most one reward a step, so its bound is the step count (at least 1) times
    :data:`~delayed_rl.agents.common.hyperparameters.MAX_ABS_VALUE`.

    Raises:
        ValueError: ``by_lag`` or ``end_rewards`` holds a sum out of bounds, or an end that is
            not flushed holds a reward.
    """
    bound = max(steps, 1) * MAX_ABS_VALUE
    for name in ("by_lag", "end_rewards"):
        sums = arrays[name]
        if not np.all(np.isfinite(sums)) or np.any(np.abs(sums) > bound):
            raise ValueError(
                f"{prefix}{name} must hold finite reward sums within the step count times "
                f"{MAX_ABS_VALUE.text}"
            )
    if np.any(arrays["end_rewards"][~arrays["end_flushed"]]):
        raise ValueError(f"{prefix}end_rewards: only a flushed end holds a reward")
