"""A step's updates of MMQ's models, compiled: the rule of :mod:`delayed_rl.agents.mmq.mmq`.

:func:`update_models` makes the |Λ| updates of a step in one call over the episode's
:class:`~delayed_rl.agents.common.transition_ring.TransitionRing`, and :func:`model_weights`
computes each model's share of the reward under the credit options. They run the operations of
the numpy code they replaced in its order, so the tables are the same to the last bit; without
numba they run as Python.
"""

from __future__ import annotations

import numpy as np

from delayed_rl._numba import jit as _jit
from delayed_rl.agents.common.q_table import first_max

__all__ = ["FULL_CREDIT", "NO_OPTION", "model_weights", "update_models"]

FULL_CREDIT = np.zeros(0)
"""The ``weights`` of :func:`update_models` without the options (every model gets ``r``)."""
NO_OPTION = np.zeros(0)
"""The trace or the kernel of :func:`model_weights` when that option is off."""


@_jit
def model_weights(trace, decay, kernel, estimates, acting):
    """Each model's share of the reward ``r`` at a step (MMQ's credit options), compiled.

    The delay trace (empty: off) decays by ``decay`` and the acting model's entry becomes 1;
    model ``j``'s weight is ``kernel[|Λ[j] − Λ[acting]|]`` (empty: off) times its trace entry.
    """
    if trace.shape[0]:
        for j in range(trace.shape[0]):
            trace[j] *= decay
        trace[acting] = 1.0
        if not kernel.shape[0]:
            return trace
    weights = np.empty(estimates.shape[0])
    for j in range(estimates.shape[0]):
        weights[j] = kernel[abs(estimates[j] - estimates[acting])]
        if trace.shape[0]:
            weights[j] *= trace[j]
    return weights


@_jit
def update_models(
    q_flat, v_max, v_cell, history, back, n, t, mask, r, weights, alpha, gamma, terminal, n_actions
):
    """The updates of the first ``n`` models at a step, all targets first: one compiled call.

    Model ``j < n`` learns from the transition at ring position ``p = (t + back[j]) & mask``: it
    moves the cell ``hist_cell[p] + j·|A|`` towards ``r·weights[j] + γ·v_max[hist_s2[p]]``
    (``weights`` empty: ``r``; ``terminal``: model 0 does not bootstrap), every target read off
    the cache as it was before the step. Then the cache: the states whose cached cell fell are
    rescanned, and the entries that rose above their state's old max raise it, the last of equal
    ones taking the cell. These are the operations, in their order, of the numpy version this
    replaced, to the last bit.

    Args:
        q_flat: the Q-table, flat.
        v_max: each state's max over its row.
        v_cell: the flat index of an entry holding it.
        history: the ring, rows ``s``, ``s2`` and model 0's cell.
        back: per model, its transition's offset from ``t`` in the ring (``−λ̂``).
        n: how many models learn (the first ``n``).
        t: the episode step.
        mask: the ring's length minus one (a power of two minus one).
        r: the received reward.
        weights: each model's share of ``r`` (the options), or empty.
        alpha: the learning rate.
        gamma: the discount.
        terminal: model 0's transition is terminal.
        n_actions: |A|.
    """
    size = q_flat.shape[0] // v_max.shape[0]
    states = np.empty(n, np.int64)
    cells = np.empty(n, np.int64)
    values = np.empty(n)
    fell = np.zeros(n, np.bool_)
    rose = np.zeros(n, np.bool_)
    for j in range(n):
        p = (t + back[j]) & mask
        s = history[0, p]
        cell = history[2, p] + j * n_actions
        bootstrap = 0.0 if j == 0 and terminal else v_max[history[1, p]]
        credit = r * weights[j] if weights.shape[0] else r
        target = credit + gamma * bootstrap
        old = q_flat[cell]
        new = old + alpha * (target - old)
        q_flat[cell] = new
        states[j], cells[j], values[j] = s, cell, new
        fell[j] = v_cell[s] == cell and new < old
        rose[j] = new > v_max[s]
    for j in range(n):
        if fell[j]:
            s = states[j]
            v_max[s], v_cell[s] = first_max(q_flat, s * size, (s + 1) * size)
    for j in range(n):
        if rose[j] and values[j] > v_max[states[j]]:
            v_max[states[j]] = values[j]
    for j in range(n):
        if rose[j] and values[j] == v_max[states[j]]:
            v_cell[states[j]] = cells[j]
