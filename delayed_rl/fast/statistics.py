"""The sufficient statistics of deconvolution Q-learning's regression, and their compiled step.

:class:`~delayed_rl.agents.deconvolution.DeconvolutionQLearning` regresses each received reward
on the (state, action) pairs of the steps before it (see :mod:`delayed_rl.agents._regression`
for the model and the solves). :func:`observe` adds one step to the statistics; the Python path
calls it once a step, and the compiled loop (:func:`delayed_rl.fast.kernel.run_chunk`) inlines the
same function, so both paths keep identical statistics.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from delayed_rl.fast._numba import jit as _jit

__all__ = ["EMPTY_STATISTICS", "Statistics", "observe"]


class Statistics(NamedTuple):
    """The regression's sufficient statistics, as arrays (updated in place by :func:`observe`).

    Attributes:
        cooc: ``cooc[m, i, j]``, pair ``i`` followed ``m`` steps later by pair ``j`` (int32).
        by_lag: ``by_lag[k, i]``, the rewards received ``k`` steps after pair ``i``.
        window: the open segment's last pairs, the latest first.
        counters: ``[window length, steps, segment ends, flush, carry]``.
        end_windows: the windows of the segments that ended (the first ``counters[2]`` rows).
        end_lengths: their lengths.
        end_rewards: the reward of a flushed last step (kept apart from ``by_lag``).
        end_flushed: whether the segment's last step was flushed.
    """

    cooc: np.ndarray
    by_lag: np.ndarray
    window: np.ndarray
    counters: np.ndarray
    end_windows: np.ndarray
    end_lengths: np.ndarray
    end_rewards: np.ndarray
    end_flushed: np.ndarray


@_jit
def observe(stats, pair, reward, episode_end):
    """Add one step to the statistics: the pair acted in, the reward received, the episode end.

    The caller keeps room for one more segment end (``end_windows`` longer than
    ``counters[2]``); compiled runs and the Python path both step through this function.
    """
    window, counters = stats.window, stats.counters
    k_max = window.shape[0] - 1
    ends = episode_end and counters[4] == 0  # "carry": the stream is one segment
    flush_last = ends and counters[3] == 1
    n = min(counters[0], k_max)
    for u in range(n, 0, -1):  # shift the window: the new pair goes first
        window[u] = window[u - 1]
    window[0] = pair
    length = n + 1
    for m in range(length):
        stats.cooc[m, window[m], pair] += 1
        if not flush_last:
            stats.by_lag[m, window[m]] += reward
    counters[1] += 1
    if ends:
        e = counters[2]
        stats.end_windows[e, :] = window
        stats.end_lengths[e] = length
        stats.end_rewards[e] = reward if flush_last else 0.0
        stats.end_flushed[e] = flush_last
        counters[2] = e + 1
        length = 0
    counters[0] = length


EMPTY_STATISTICS = Statistics(
    np.zeros((1, 1, 1), dtype=np.int32),
    np.zeros((1, 1)),
    np.zeros(1, dtype=np.int64),
    np.zeros(5, dtype=np.int64),
    np.zeros((1, 1), dtype=np.int64),
    np.zeros(1, dtype=np.int64),
    np.zeros(1),
    np.zeros(1, dtype=np.bool_),
)
"""Statistics of nothing, for compiled runs without a reward model (their types, no content)."""
