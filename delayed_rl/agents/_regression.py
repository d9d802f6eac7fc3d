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

from delayed_rl.fast.kernel import HAVE_NUMBA

__all__ = ["STATISTICS_LIMIT", "RewardRegression", "project_to_simplex"]

STATISTICS_LIMIT = 256 * 2**20
"""The most bytes the co-occurrence counts may take (``(K + 1)·P²·4``): 256 MiB.

GridWorld-9x9 with delays up to 50 steps takes 21 MiB; an env with many (state, action) pairs
needs a shorter ``max_delay``, and the constructor says which.
"""

if HAVE_NUMBA:
    import numba

    _jit = numba.njit(cache=True, nogil=True)
else:  # pragma: no cover - numba is a core dependency

    def _jit(function):
        return function


@_jit
def _observe(cooc, by_lag, window, length, x, y, flush_last):
    """Count pair ``x`` after the segment's ``window`` (most recent first) and credit ``y``.

    ``window[:length]`` holds the segment's last pairs, ``window[0]`` the latest. Returns the
    new length. ``flush_last``: the step ends a flushed segment, whose reward is kept apart.
    """
    k_max = window.shape[0] - 1
    n = min(length, k_max)
    for u in range(n, 0, -1):  # shift the window: the new pair goes first
        window[u] = window[u - 1]
    window[0] = x
    length = n + 1
    for m in range(length):
        cooc[m, window[m], x] += 1
        if not flush_last:
            by_lag[m, window[m]] += y
    return length


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


def project_to_simplex(v: np.ndarray) -> np.ndarray:
    """The Euclidean projection of ``v`` onto the probability simplex (Held et al.'s algorithm)."""
    u = np.sort(v)[::-1]
    cumulative = np.cumsum(u) - 1.0
    index = np.arange(1, v.size + 1)
    rho = np.nonzero(u - cumulative / index > 0)[0][-1]
    return np.maximum(v - cumulative[rho] / (rho + 1.0), 0.0)


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
        self.cooc = np.zeros((max_delay + 1, n_pairs, n_pairs), dtype=np.int32)
        self.by_lag = np.zeros((max_delay + 1, n_pairs))
        self.window = np.zeros(max_delay + 1, dtype=np.int64)
        self.length = 0
        self.end_windows = np.zeros((0, max_delay + 1), dtype=np.int64)
        self.end_lengths = np.zeros(0, dtype=np.int64)
        self.end_rewards = np.zeros(0)
        self.end_flushed = np.zeros(0, dtype=np.bool_)
        self.steps = 0

    _STATE = (
        "cooc",
        "by_lag",
        "window",
        "end_windows",
        "end_lengths",
        "end_rewards",
        "end_flushed",
    )

    def state(self) -> dict[str, np.ndarray]:
        """The statistics as arrays (for a model file)."""
        arrays = {name: getattr(self, name).copy() for name in self._STATE}
        arrays["counters"] = np.array([self.length, self.steps], dtype=np.int64)
        return arrays

    def restore(self, arrays: dict[str, np.ndarray]) -> None:
        """Restore what :meth:`state` returned, checking every array's shape and type.

        Raises:
            ValueError: an array is missing, of the wrong shape or type, or out of range.
        """
        for name in self._STATE:
            value, ours = arrays[name], getattr(self, name)
            if value.dtype != ours.dtype or value.shape[1:] != ours.shape[1:]:
                raise ValueError(f"{name} must be a {ours.dtype} array like {ours.shape}")
            if name in ("cooc", "by_lag", "window") and value.shape != ours.shape:
                raise ValueError(f"{name} must have shape {ours.shape}, got {value.shape}")
        ends = arrays["end_windows"].shape[0]
        if any(arrays[name].shape != (ends,) for name in self._STATE[4:]):
            raise ValueError("the end_* arrays disagree on the number of segment ends")
        indices = np.concatenate([arrays["window"], arrays["end_windows"].ravel()])
        if indices.size and (indices.min() < 0 or indices.max() >= self.n_pairs):
            raise ValueError("a window holds a pair outside the env's pairs")
        length, steps = (int(v) for v in arrays["counters"])
        if not 0 <= length <= self.max_delay + 1 or steps < 0:
            raise ValueError(f"counters out of range: {length}, {steps}")
        for name in self._STATE:
            setattr(self, name, arrays[name].copy())
        self.length, self.steps = length, steps

    # ------------------------------------------------------------------ observing
    def observe(self, pair: int, reward: float, episode_end: bool) -> None:
        """Add one step: the pair acted in, the reward received, whether the episode ended."""
        ends = episode_end and not self.carry
        flush_last = ends and self.flush
        self.length = _observe(
            self.cooc, self.by_lag, self.window, self.length, pair, reward, flush_last
        )
        self.steps += 1
        if ends:
            self._close_segment(reward if flush_last else 0.0, flush_last)

    def _close_segment(self, final_reward: float, flushed: bool) -> None:
        self.end_windows = np.vstack([self.end_windows, self.window[None, :]])
        self.end_lengths = np.append(self.end_lengths, self.length)
        self.end_rewards = np.append(self.end_rewards, final_reward)
        self.end_flushed = np.append(self.end_flushed, flushed)
        self.length = 0

    def _windows(self) -> tuple[np.ndarray, ...]:
        """The ended segments' windows, and the open segment's (it ends, for now, here)."""
        windows = np.vstack([self.end_windows, self.window[None, :]])
        lengths = np.append(self.end_lengths, self.length)
        return (
            windows,
            lengths,
            np.append(self.end_rewards, 0.0),
            np.append(self.end_flushed, False),
        )

    # ------------------------------------------------------------------ solving
    def normal_equations(self, pmf: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(A, b)`` of the least-squares problem for the mean rewards, given the delay pmf."""
        k = self.max_delay
        c = np.array([pmf[: k + 1 - m] @ pmf[m:] for m in range(k + 1)])
        counts = np.zeros((self.n_pairs, self.n_pairs))
        for m in range(1, k + 1):
            if c[m] != 0.0:
                counts += c[m] * self.cooc[m]
        a = counts + counts.T
        a[np.diag_indices_from(a)] += c[0] * np.diagonal(self.cooc[0])
        b = pmf @ self.by_lag
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
        q = np.array([reward @ (self.cooc[m] @ reward) for m in range(k + 1)])
        lags = np.abs(np.subtract.outer(np.arange(k + 1), np.arange(k + 1)))
        g = q[lags]
        z = self.by_lag @ reward
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
        p = start.copy()
        for _ in range(iterations):
            p = project_to_simplex(p - (g @ p - z) / scale)
        return p
