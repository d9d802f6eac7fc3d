"""The sufficient statistics of deconvolution Q-learning's regression, and their compiled step.

:class:`Statistics` holds them, in a direct or a hashed layout (the model and the solves are
:mod:`delayed_rl.agents.deconvolution.regression`'s). :func:`observe` adds one step; the Python
path calls it once a step, and the compiled loop (:func:`delayed_rl.compiled.kernel.run_chunk`)
inlines the same function, so both paths keep identical statistics.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from delayed_rl._numba import jit as _jit

__all__ = ["Statistics", "find_row", "observe", "hash_slot"]

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)  # Fibonacci hashing: 2**64 / the golden ratio
_SHIFT = np.uint64(32)  # the hash's upper half indexes the table (up to 2**32 rows)


class Statistics(NamedTuple):
    """The regression's sufficient statistics, as arrays (updated in place by :func:`observe`).

    The counts of "pair ``i`` followed ``m`` steps later by pair ``j``" are kept as rows of
    ``K + 1`` lags, one row per ordered couple ``(j, i)`` — the later pair first, so that the
    ``K + 1`` counts a step adds all fall in the current pair's block of rows. Two layouts share
    this type: *direct* (``keys`` empty), where the row of ``(j, i)`` is ``j·P + i`` (``P²``
    rows, no lookups); and *hashed* (``keys`` of a power-of-two length), a row only for each
    couple that occurred, found by open addressing (linear probing from the upper bits of a
    multiplicative hash of ``j·P + i``; ``-1`` marks a free slot), so memory follows the couples
    seen, not ``P²``: the layout for envs with many pairs. The caller keeps the table at most
    half full (:meth:`~delayed_rl.agents.deconvolution.regression.RewardRegression.reserve`).

    Attributes:
        cooc: ``cooc[row, m]``, how often the row's earlier pair was followed ``m`` steps later
            by its later pair (int32; rows as above).
        keys: the hashed layout's keys (``j·P + i`` per row, ``-1`` free); empty: direct layout.
        by_lag: ``by_lag[k, i]``, the rewards received ``k`` steps after pair ``i``.
        window: the open segment's last pairs, the latest first.
        counters: ``[window length, steps, segment ends, flush, carry, P, rows in use]``.
        end_windows: the windows of the segments that ended (the first ``counters[2]`` rows).
        end_lengths: their lengths.
        end_rewards: the reward of a flushed last step (kept apart from ``by_lag``).
        end_flushed: whether the segment's last step was flushed.
    """

    cooc: np.ndarray
    keys: np.ndarray
    by_lag: np.ndarray
    window: np.ndarray
    counters: np.ndarray
    end_windows: np.ndarray
    end_lengths: np.ndarray
    end_rewards: np.ndarray
    end_flushed: np.ndarray


@_jit
def hash_slot(keys, key):
    """Where ``key`` is or would go in the hashed table ``keys`` (a power-of-two length)."""
    mask = keys.shape[0] - 1
    i = np.int64((np.uint64(key) * _GOLDEN) >> _SHIFT) & mask
    while keys[i] != key and keys[i] != -1:
        i = (i + 1) & mask
    return i


@_jit
def find_row(keys, n_pairs, later, earlier):
    """The row of the couple (``later``, ``earlier``), or -1 if it never occurred.

    ``keys`` are the statistics' hashed keys (empty: the direct layout).

    Takes the arrays it needs rather than the :class:`Statistics` tuple: a compiled call that
    passes the whole tuple pays a reference count per array, per call.
    """
    key = later * n_pairs + earlier
    if keys.shape[0] == 0:
        return key
    i = hash_slot(keys, key)
    return i if keys[i] == key else -1


@_jit
def observe(stats, pair, reward, episode_end):
    """Add one step to the statistics: the pair acted in, the reward received, the episode end.

    The caller keeps room for one more segment end (``end_windows`` longer than
    ``counters[2]``) and, in the hashed layout, for ``K + 1`` more rows; compiled runs and the
    Python path both step through this function.
    """
    window, counters = stats.window, stats.counters
    k_max = window.shape[0] - 1
    n_pairs = counters[5]
    ends = episode_end and counters[4] == 0  # "carry": the stream is one segment
    flush_last = ends and counters[3] == 1
    n = min(counters[0], k_max)
    for u in range(n, 0, -1):  # shift the window: the new pair goes first
        window[u] = window[u - 1]
    window[0] = pair
    length = n + 1
    base = pair * n_pairs
    keys, cooc = stats.keys, stats.cooc
    hashed = keys.shape[0] > 0
    for m in range(length):
        row = base + window[m]
        if hashed:  # the couple's row, claimed if new (the caller kept room)
            key = row
            row = hash_slot(keys, key)
            if keys[row] == -1:
                keys[row] = key
                counters[6] += 1
        cooc[row, m] += 1
    if reward != 0.0 and not flush_last:  # (adding ±0 changes no sum: all start at +0.0)
        by_lag = stats.by_lag
        for m in range(length):
            by_lag[m, window[m]] += reward
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
