"""Regressing received rewards on the past: the estimator of deconvolution Q-learning.

With each reward delayed independently by ``d ~ p``, the reward received at step ``t`` satisfies
``E[y_t | history] = Σ_k p(k) · R(x_{t−k})``, with ``x_j`` the (state, action) pair of step ``j``
and ``R`` the unknown mean rewards: a linear model in ``R`` for a known ``p``, and in ``p`` for a
known ``R``. :class:`RewardRegression` keeps sufficient statistics of that regression, so a
least-squares solve never revisits the history:

- ``cooc[m, i, j]``: how often pair ``i`` was followed ``m`` steps later by pair ``j`` (``m`` in
  ``0..K``), within a segment (an episode, or the whole stream when pending rewards carry over);
- ``by_lag[k, i]``: the sum of the rewards received ``k`` steps after pair ``i``;
- the last ``K + 1`` pairs of every segment that ended (its *window*), and under ``"flush"`` the
  reward of its last step, which also carries every reward still pending (expected weight
  ``P(D ≥ k)`` for the pair ``k`` steps back, instead of ``p(k)``).

The normal equations follow: for rows ``φ_t = Σ_k p(k) e_{x_{t−k}}``,
``A = Σ_t φ_t φ_tᵀ = Σ_m c(m) (cooc[m] + cooc[m]ᵀ)`` (``c(m) = Σ_k p(k) p(k + m)``, the lag-0
term once), less the rows after each segment's end that this sum counts but that never happened,
and with each flushed last row replaced by its survival-weighted one; ``b = Σ_k p(k) by_lag[k]``
plus the flushed rows. For a learned ``p``, the same statistics give the Gram matrix of the
regression on ``p`` for a given ``R``; the two least-squares problems alternate, ``p`` on the
simplex (a delay distribution), ``R`` with a small ridge that pulls unvisited pairs to 0.

Each step costs ``O(K)`` (``K + 1`` counts and sums); memory is ``(K + 1)·P²`` 4-byte counts for
``P`` pairs, checked against :data:`STATISTICS_LIMIT` when the regression is built.
"""

from __future__ import annotations

import numpy as np

from delayed_rl.fast._numba import jit as _jit
from delayed_rl.fast.statistics import Statistics, observe

__all__ = ["STATISTICS_LIMIT", "RewardRegression", "project_to_simplex"]

STATISTICS_LIMIT = 256 * 2**20
"""The most bytes the co-occurrence counts may take (``(K + 1)·P²·4``): 256 MiB.

GridWorld-9x9 with delays up to 50 steps takes 21 MiB; an env with many (state, action) pairs
needs a shorter ``max_delay``, and the constructor says which.
"""


@_jit
def _lag_weighted_counts(cooc, weights):
    """``Σ_m weights[m] · cooc[m]`` for ``m >= 1``, and ``weights[0]`` times ``cooc[0]``'s diagonal.

    One pass over the counts, skipping lags of zero weight.
    """
    k1, n, _ = cooc.shape
    out = np.zeros((n, n))
    for m in range(1, k1):
        w = weights[m]
        if w == 0.0:
            continue
        for i in range(n):
            for j in range(n):  # no branch on zero counts: the loop vectorises
                out[i, j] += w * cooc[m, i, j]
    diagonal = np.zeros(n)
    for i in range(n):
        diagonal[i] = weights[0] * cooc[0, i, i]
    return out, diagonal


@_jit
def _lag_quadratic_forms(cooc, reward):
    """``q[m] = rewardᵀ · cooc[m] · reward`` for every lag ``m``."""
    k1, n, _ = cooc.shape
    q = np.zeros(k1)
    for m in range(k1):
        total = 0.0
        for i in range(n):
            ri = reward[i]
            if ri == 0.0:
                continue
            row = 0.0
            for j in range(n):  # no branch on zero counts: the loop vectorises
                row += cooc[m, i, j] * reward[j]
            total += ri * row
        q[m] = total
    return q


@_jit
def _window_corrections(a, b, windows, lengths, finals, flushed, p, survival):
    """Subtract the rows after each window's segment end; swap flushed last rows for ψ rows.

    ``a`` (P×P) and ``b`` (P) are corrected in place for the ``p``-weighted normal equations.
    """
    k_max = p.shape[0] - 1
    for w in range(windows.shape[0]):
        length = lengths[w]
        window = windows[w]
        for h in range(1, k_max + 1):  # rows h steps after the end: lags h..K reach the window
            for u in range(min(length, k_max + 1 - h)):
                wu = p[h + u]
                if wu == 0.0:
                    continue
                for v in range(min(length, k_max + 1 - h)):
                    a[window[u], window[v]] -= wu * p[h + v]
        if flushed[w]:
            for u in range(length):
                for v in range(length):
                    a[window[u], window[v]] += survival[u] * survival[v] - p[u] * p[v]
                b[window[u]] += finals[w] * survival[u]


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
        p = project_to_simplex(p - (g @ p - z) / scale)
    return p


class RewardRegression:
    """Sufficient statistics of the reward-on-past regression, and its least-squares solves.

    Args:
        n_pairs: how many (state, action) pairs (``|S|·|A|``).
        max_delay: ``K``, the longest delay modelled.
        flush: the last step of an ending segment carries every pending reward (the reward-delay
            wrapper's ``"flush"``); ``False`` for ``"drop"`` (those rewards never come).
        carry: pending rewards carry over episode ends (``"carry"``): the stream is one segment.

    Raises:
        ValueError: the counts would take more than :data:`STATISTICS_LIMIT` bytes.
    """

    def __init__(self, n_pairs: int, max_delay: int, flush: bool = True, carry: bool = False):
        size = (max_delay + 1) * n_pairs * n_pairs * 4
        if size > STATISTICS_LIMIT:
            raise ValueError(
                f"max_delay={max_delay} with {n_pairs} (state, action) pairs needs "
                f"{size / 2**20:,.0f} MiB of co-occurrence counts, more than the limit of "
                f"{STATISTICS_LIMIT / 2**20:.0f} MiB: choose a shorter max_delay"
            )
        self.n_pairs, self.max_delay, self.flush, self.carry = n_pairs, max_delay, flush, carry
        k = max_delay + 1
        self.stats = Statistics(
            np.zeros((k, n_pairs, n_pairs), dtype=np.int32),
            np.zeros((k, n_pairs)),
            np.zeros(k, dtype=np.int64),
            np.array([0, 0, 0, int(flush), int(carry)], dtype=np.int64),
            np.zeros((1, k), dtype=np.int64),
            np.zeros(1, dtype=np.int64),
            np.zeros(1),
            np.zeros(1, dtype=np.bool_),
        )

    @property
    def steps(self) -> int:
        """How many steps the statistics hold."""
        return int(self.stats.counters[1])

    @property
    def cooc(self) -> np.ndarray:
        """``cooc[m, i, j]``: pair ``i`` followed ``m`` steps later by pair ``j``."""
        return self.stats.cooc

    def reserve(self, ends: int) -> None:
        """Make room for ``ends`` more segment ends (the end arrays double as they fill)."""
        stats = self.stats
        needed = int(stats.counters[2]) + ends
        if needed <= stats.end_lengths.shape[0]:
            return
        size = max(needed, 2 * stats.end_lengths.shape[0])
        grown = [np.zeros((size,) + array.shape[1:], dtype=array.dtype) for array in stats[4:]]
        for new, old in zip(grown, stats[4:], strict=True):
            new[: old.shape[0]] = old
        self.stats = stats._replace(
            end_windows=grown[0], end_lengths=grown[1], end_rewards=grown[2], end_flushed=grown[3]
        )

    def state(self) -> dict[str, np.ndarray]:
        """The statistics as arrays (for a model file), the end arrays cut to their use."""
        ends = int(self.stats.counters[2])
        return {
            name: (value[:ends] if index >= 4 else value).copy()
            for index, (name, value) in enumerate(zip(Statistics._fields, self.stats, strict=True))
        }

    def restore(self, arrays: dict[str, np.ndarray]) -> None:
        """Restore what :meth:`state` returned, checking every array's shape and type.

        Raises:
            ValueError: an array is missing, of the wrong shape or type, or out of range.
        """
        ends = arrays["end_lengths"].shape[0]
        for index, (name, ours) in enumerate(zip(Statistics._fields, self.stats, strict=True)):
            value = arrays[name]
            shape = (ends,) + ours.shape[1:] if index >= 4 else ours.shape
            if value.dtype != ours.dtype or value.shape != shape:
                raise ValueError(f"{name} must be a {ours.dtype} array of shape {shape}")
        counters = arrays["counters"]
        length, steps, n_ends, flush, carry = (int(v) for v in counters)
        if not 0 <= length <= self.max_delay + 1 or steps < 0 or n_ends != ends:
            raise ValueError(f"counters out of range: {counters.tolist()}")
        if (flush, carry) != (int(self.flush), int(self.carry)):
            raise ValueError("counters disagree with the episode-end mode")
        indices = np.concatenate([arrays["window"], arrays["end_windows"].ravel()])
        if indices.size and (indices.min() < 0 or indices.max() >= self.n_pairs):
            raise ValueError("a window holds a pair outside the env's pairs")
        if np.any(arrays["cooc"] < 0) or not np.all(np.isfinite(arrays["by_lag"])):
            raise ValueError("negative counts or non-finite reward sums")
        self.stats = Statistics(*(arrays[name].copy() for name in Statistics._fields))
        self.reserve(1)

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
    def normal_equations(self, pmf: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(A, b)`` of the least-squares problem for the mean rewards, given the delay pmf."""
        k = self.max_delay
        c = np.array([pmf[: k + 1 - m] @ pmf[m:] for m in range(k + 1)])
        counts, diagonal = _lag_weighted_counts(self.stats.cooc, c)
        a = counts + counts.T
        a[np.diag_indices_from(a)] += diagonal
        b = pmf @ self.stats.by_lag
        survival = np.cumsum(pmf[::-1])[::-1]
        _window_corrections(a, b, *self._windows(), pmf, survival)
        return a, b

    def solve_rewards(self, pmf: np.ndarray, ridge: float) -> np.ndarray:
        """The ridge least-squares mean rewards ``R̂`` (one per pair) for the delay pmf."""
        a, b = self.normal_equations(pmf)
        a[np.diag_indices_from(a)] += ridge
        return np.linalg.solve(a, b)

    def delay_gram(self, reward: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(G, z)`` of the least-squares problem for the pmf, given the mean rewards."""
        k = self.max_delay
        q = _lag_quadratic_forms(self.stats.cooc, reward)
        lags = np.abs(np.subtract.outer(np.arange(k + 1), np.arange(k + 1)))
        g = q[lags]
        z = self.stats.by_lag @ reward
        _delay_gram_corrections(g, z, *self._windows(), reward)
        return g, z

    def solve_delay(
        self, reward: np.ndarray, start: np.ndarray, iterations: int = 300
    ) -> np.ndarray:
        """The pmf on ``0..K`` that best explains the received rewards given ``reward``.

        Projected gradient on the simplex, from ``start``, with the step set by ``G``'s largest
        eigenvalue (so each step decreases the squared error).
        """
        g, z = self.delay_gram(reward)
        scale = np.linalg.eigvalsh(g)[-1]
        if not scale > 0:
            return start
        return _projected_gradient(g, z, start, scale, iterations)
