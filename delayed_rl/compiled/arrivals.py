"""Who emitted each pending reward: the compiled twin of ``info["reward_arrivals"]``.

:class:`~delayed_rl.agents.OracleQLearning` credits every delayed reward to the transition that
emitted it. On the Python path it reads the wrapper's record; on the compiled path the loop
(:func:`delayed_rl.compiled.kernel.run_chunk`) keeps the record itself, in :class:`Arrivals`;
:func:`regrow` moves it to a longer ring and pool.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from delayed_rl._delay_line import ring_size
from delayed_rl._numba import jit as _jit

__all__ = ["Arrivals", "regrow"]


class Arrivals(NamedTuple):
    """The pending transitions and their rewards, by emission clock and by due slot.

    A *pool* of the last ``P`` transitions, indexed by the run's clock ``e`` (slot
    ``e & (P − 1)``), holds each transition ``(s, a, s′, terminated)``, its reward and the clock
    ``due`` of the step that delivers it (``-1`` once delivered or dropped); per slot of the
    delay ring, a list holds the transitions due there, oldest first (``head`` and ``tail`` hold
    clocks, ``link`` the next clock of the same list; ``-1`` ends a list). A transition is
    pending from its step to its due step, fewer steps than the delay ring's length ``B``, so a
    pool of ``P ≥ B`` slots never overwrites a pending transition; ``P`` is also at least the
    oracle's history (``held``), so a transition it may still credit is always there.

    Attributes:
        head: per slot of the delay ring, the clock of the oldest transition due there (``-1``).
        tail: per slot, the clock of the newest (``-1``).
        link: per pool slot, the clock of the next transition due at the same step (``-1``).
        due: per pool slot, the clock of the step that delivers its reward (``-1``: not pending).
        value: per pool slot, the transition's reward.
        s: per pool slot, the transition's state.
        a: its action.
        s2: its next state.
        terminated: whether it was terminal.
        order: scratch room for one step's arrivals (pool-sized).
        held: how many of the most recent transitions the oracle credits (its history's length,
            as on the Python path); an arrival of an older one is ignored.
    """

    head: np.ndarray
    tail: np.ndarray
    link: np.ndarray
    due: np.ndarray
    value: np.ndarray
    s: np.ndarray
    a: np.ndarray
    s2: np.ndarray
    terminated: np.ndarray
    order: np.ndarray
    held: int

    @classmethod
    def empty(cls, ring: int, held: int) -> Arrivals:
        """No pending transitions, for a delay ring of ``ring`` slots and history ``held``."""
        pool = ring_size(max(ring, held))
        lists = [np.full(ring, -1, np.int64) for _ in range(2)]
        slots = [np.full(pool, -1, np.int64) for _ in range(2)]
        transition = [np.zeros(pool, np.int64) for _ in range(3)]
        return cls(
            *lists, *slots, np.zeros(pool), *transition, np.zeros(pool, np.bool_),
            np.zeros(pool, np.int64), int(held),
        )  # fmt: skip


def regrow(arrivals: Arrivals, clock: int, ring: int) -> Arrivals:
    """``arrivals`` for a delay ring of ``ring`` slots: the same pending transitions, the same order.

    Args:
        arrivals: the record (left unchanged).
        clock: the run's clock: the next step's (every transition before it is in the pool).
        ring: the new delay ring's length (a power of two, at least the old one's).
    """
    grown = Arrivals.empty(ring, arrivals.held)
    _move(arrivals, grown, clock)
    return grown


@_jit
def _move(old, new, clock):
    """Copy ``old``'s pool into ``new``'s by clock, and list the pending ones in ``new``'s ring."""
    old_mask = old.due.shape[0] - 1
    new_mask = new.due.shape[0] - 1
    ring_mask = new.head.shape[0] - 1
    for e in range(max(0, clock - old_mask - 1), clock):
        i, j = e & old_mask, e & new_mask
        new.value[j], new.s[j], new.a[j] = old.value[i], old.s[i], old.a[i]
        new.s2[j], new.terminated[j], new.due[j] = old.s2[i], old.terminated[i], old.due[i]
        if old.due[i] >= clock:  # pending: append to its due slot's list (clocks ascending)
            _append(new, old.due[i] & ring_mask, e)


@_jit
def _append(arrivals, slot, e):
    """Append clock ``e`` to the list of the transitions due at ring slot ``slot``."""
    if arrivals.head[slot] < 0:
        arrivals.head[slot] = e
    else:
        arrivals.link[arrivals.tail[slot] & (arrivals.due.shape[0] - 1)] = e
    arrivals.tail[slot] = e


@_jit
def record(arrivals, clock, due, s, a, s2, terminated, value):
    """Remember the transition of step ``clock`` and its reward, due at step ``due``."""
    pool_mask = arrivals.due.shape[0] - 1
    p = clock & pool_mask
    arrivals.s[p], arrivals.a[p], arrivals.s2[p] = s, a, s2
    arrivals.terminated[p], arrivals.value[p], arrivals.due[p] = terminated, value, due
    arrivals.link[p] = -1
    _append(arrivals, due & (arrivals.head.shape[0] - 1), clock)


@_jit
def take_due(arrivals, clock):
    """Put the clocks of the transitions due at step ``clock`` in ``order``; return how many."""
    pool_mask = arrivals.due.shape[0] - 1
    slot = clock & (arrivals.head.shape[0] - 1)
    e = arrivals.head[slot]
    n = 0
    while e >= 0:
        arrivals.order[n] = e
        n += 1
        p = e & pool_mask
        arrivals.due[p] = -1
        e = arrivals.link[p]
    arrivals.head[slot] = -1
    arrivals.tail[slot] = -1
    return n


@_jit
def end_pending(arrivals, clock, deliver):
    """At the episode's end (step ``clock``): every pending transition arrives now or is dropped.

    With ``deliver``, their clocks (those due at ``clock`` included) go in ``order``, oldest
    first, and the count is returned; otherwise they are dropped and 0 is returned.
    """
    pool_mask = arrivals.due.shape[0] - 1
    n = 0
    for e in range(max(0, clock - arrivals.head.shape[0] + 1), clock + 1):
        p = e & pool_mask
        if arrivals.due[p] >= clock:
            arrivals.due[p] = -1
            if deliver:
                arrivals.order[n] = e
                n += 1
    arrivals.head[:] = -1
    arrivals.tail[:] = -1
    return n
