"""The pending rewards of many envs at once, for the vector twins of :class:`~delayed_rl.wrappers.RewardDelay`."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from delayed_rl._delay_line import delay_bound, draw_delays, exact_sum, regrow_ring, ring_size
from delayed_rl.delays import Delay
from delayed_rl.wrappers._delay_draws import BLOCK, delay_rng

__all__ = ["INITIAL_RING", "MAX_RING_ENTRIES", "RING_PER_STEP", "PendingRewards"]

_SAFE_MAGNITUDE = 2.0**1020
"""Below this, a sum of numbers whose magnitudes add up to it cannot pass float64's range."""

MAX_RING_ENTRIES = 1 << 22
"""The most ring slots the rings of one wrapper hold in all (float64: 32 MiB).

Each sub-env's ring is at most the largest power of two ``<= MAX_RING_ENTRIES // num_envs``
slots long (65 536 for 64 sub-envs, more than 400 times the thesis's longest mean delay, λ = 150).
A reward whose delay does not fit its ring is kept in a small dict keyed by due step instead (as
:class:`~delayed_rl.wrappers.RewardDelay` keeps all of them), so no delay is refused and memory
stays proportional to what is pending: ``Poisson(1e9)`` costs what ``Poisson(5)`` does."""

INITIAL_RING = 64
"""The rings' length at construction (shorter for a delay bounded below it); they grow to hold the
delays actually drawn, up to the limit set by :data:`MAX_RING_ENTRIES`."""

RING_PER_STEP = 8
"""How far a ring may outgrow the steps taken: at most ``8 × steps`` slots (rounded up to a power
of two), so a ring is never mostly empty space. A slot costs 8 bytes and a reward kept in a dict
about 100: past this the dict is the cheaper of the two."""


class PendingRewards:
    """The pending rewards of ``num_envs`` independent reward delays, advanced together with numpy.

    Each env has its own clock (it advances only on the steps that env really takes), its own
    delay generator (one stream per env, seeded by :meth:`seed`) and its own ring of
    pending rewards. The rings start short (:data:`INITIAL_RING`) and grow, keeping what is
    pending in place, when a longer delay is drawn; a delay longer than the largest ring allowed
    (:data:`MAX_RING_ENTRIES`, :data:`RING_PER_STEP`) puts its reward in a per-env dict keyed by
    due step.

    Each env's pending sum is kept as a running sum (exactly 0 once nothing is pending, as in
    :class:`RewardDelay`); the amounts flushed or dropped by :meth:`clear` are exact sums rounded
    once. A sum beyond float64's range raises ``ValueError``.

    Args:
        num_envs: how many envs.
        delay: the delay distribution.
        max_delay: clip delays to at most this many steps (``None``: unbounded).
    """

    def __init__(self, num_envs: int, delay: Delay, max_delay: int | None):
        self.num_envs = num_envs
        self.delay = delay
        self.max_delay = max_delay
        per_env = max(1, MAX_RING_ENTRIES // max(1, num_envs))
        self.max_ring = 1 << (per_env.bit_length() - 1)  # a power of two <= per_env
        bound = delay_bound(delay, max_delay)
        length = min(ring_size(min(bound, INITIAL_RING - 1) + 1), self.max_ring)
        self.ring = np.zeros((num_envs, length))
        self.clock = np.zeros(num_envs, dtype=np.int64)
        self.rows = np.arange(num_envs)
        self._pending = np.zeros(num_envs)  # running sums, as RewardDelay._pending
        self._nonzero = np.zeros(num_envs, dtype=np.int64)  # nonzero slots in each ring
        self._magnitude = np.zeros(num_envs)  # >= the sum of |r| pending: bounds every sum
        self.far: list[dict[int, float]] = [{} for _ in range(num_envs)]  # beyond the ring
        self._far_envs: set[int] = set()  # the envs whose ``far`` dict is not empty
        # unseeded streams take their entropy at their first draw (:meth:`_stream`)
        self.rngs: list[np.random.Generator | None] = [None] * num_envs
        self._block = np.zeros((BLOCK, num_envs), dtype=np.int64)  # column i: env i's delays
        self._next = np.full(num_envs, BLOCK, dtype=np.int64)  # BLOCK: draw a new block
        self._sync: int | None = BLOCK  # while every env is at the same ``_next``: that index

    def seed(self, seeds: Sequence[int | None]) -> None:
        """Restart env ``i``'s delay stream from ``seeds[i]``; a ``None`` entry leaves it going.

        Env ``i`` seeded with ``s`` draws the delays of a :class:`RewardDelay` reset with
        ``seed=s``.
        """
        self._unsync()
        for i, seed in enumerate(seeds):
            if seed is not None:
                self.rngs[i] = delay_rng(seed)
                self._next[i] = BLOCK
        self._resync()

    @property
    def pending(self) -> np.ndarray:
        """Each env's sum of rewards emitted but not yet delivered (a copy)."""
        return self._pending.copy()

    def _unsync(self) -> None:
        """Write the shared block index back to ``_next``: the envs may part from here."""
        if self._sync is not None:
            self._next[:] = self._sync
            self._sync = None

    def _resync(self) -> None:
        """Share one block index again if every env is at the same one."""
        if self.num_envs and (self._next == self._next[0]).all():
            self._sync = int(self._next[0])

    def _stream(self, i: int) -> np.random.Generator:
        """Env ``i``'s delay generator; an unseeded one takes fresh entropy at its first draw."""
        if self.rngs[i] is None:
            self.rngs[i] = delay_rng(None)
        return self.rngs[i]

    def _draw(self, active: np.ndarray, every: bool) -> np.ndarray:
        """This step's delays: the next of each active env's stream, 0 for the others."""
        if every and self._sync is not None:  # the common case: one row of the block
            if self._sync == BLOCK:  # once every 1024 steps
                for i in range(self.num_envs):
                    self._block[:, i] = draw_delays(
                        self.delay, self._stream(i), BLOCK, self.max_delay
                    )
                self._sync = 0
            delays = self._block[self._sync].copy()
            self._sync += 1
            return delays
        self._unsync()
        empty = active & (self._next == BLOCK)
        if empty.any():  # once every 1024 steps of each env
            for i in np.flatnonzero(empty):
                self._block[:, i] = draw_delays(self.delay, self._stream(i), BLOCK, self.max_delay)
            self._next[empty] = 0
        delays = np.where(active, self._block[np.minimum(self._next, BLOCK - 1), self.rows], 0)
        self._next += active
        self._resync()
        return delays

    def step(
        self, rewards: np.ndarray, active: np.ndarray, ended: np.ndarray, on_episode_end: str
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """One step of every env: schedule ``rewards``, deliver what is due, settle ended episodes.

        This is the reward-delay rule of :class:`~delayed_rl.wrappers.RewardDelay`, for every
        env at once. Envs with ``active`` False (an autoreset step) emit nothing, deliver
        nothing, keep their clocks and draw no delay; their delay is reported as 0. The active
        envs whose episode ``ended`` at this step settle what is still pending:
        ``on_episode_end="flush"`` adds it to what they deliver, ``"drop"`` discards it,
        ``"carry"`` keeps it.

        A step refused with ``ValueError`` changes nothing: the rings, clocks and delay
        streams are as they were before it, so conservation holds and later steps work.

        Returns:
            ``(delivered, delays, settled)``: ``settled`` is each env's amount flushed (included
            in ``delivered``) or dropped, 0 for the envs that did not end, or ``None`` when no
            active env's episode ended or under ``"carry"``.

        Raises:
            ValueError: a reward is NaN or infinite, or the rewards due at one step, all those
                pending in an env, or those an env delivers at its episode's end sum to more
                than float64 can hold.
        """
        rewards = np.asarray(rewards, dtype=np.float64)
        active = np.asarray(active, dtype=bool)
        every = bool(active.all())
        ended = np.asarray(ended, dtype=bool)
        if not every:
            ended = ended & active
        with np.errstate(over="ignore", invalid="ignore"):  # overflows are checked here
            check = float(rewards.sum())  # one scalar test: NaN or inf if a reward is
            if check - check and not np.isfinite(rewards).all():  # (x − x is 0 if x is finite)
                bad = np.flatnonzero(~np.isfinite(rewards)).tolist()
                raise ValueError(
                    f"sub-envs {bad} returned non-finite rewards {rewards[bad].tolist()}; "
                    "the reward delay refuses to keep them"
                )
            # Only sums of magnitudes near float64's range can overflow: then, and only then,
            # the state is saved, to be put back if the step is refused (an infinite bound is
            # risky too).
            magnitude = np.abs(rewards)
            risky = float((self._magnitude + magnitude).max(initial=0.0)) >= _SAFE_MAGNITUDE
            saved = self._save() if risky else None
            try:
                delivered, delays = self._push(rewards, active, magnitude, every)
                settled = None
                if on_episode_end != "carry" and ended.any():
                    settled = self.clear(ended)
                    if on_episode_end == "flush":
                        delivered = delivered + settled
                        if not np.isfinite(delivered).all():
                            self._overflow(
                                np.flatnonzero(~np.isfinite(delivered)),
                                "the rewards delivered at the episode's last step (due then, "
                                "plus the flushed rest)",
                            )
            except ValueError:
                if saved is not None:
                    self._restore(saved)
                raise
        return delivered, delays, settled

    def _save(self) -> tuple:
        """Everything :meth:`step` changes (copies), for :meth:`_restore`."""
        return (
            self.ring.copy(),
            self.clock.copy(),
            self._pending.copy(),
            self._nonzero.copy(),
            self._magnitude.copy(),
            [dict(book) for book in self.far],
            set(self._far_envs),
            self._block.copy(),
            self._next.copy(),
            self._sync,
            [self._stream(i).bit_generator.state for i in range(self.num_envs)],
        )

    def _restore(self, saved: tuple) -> None:
        """Put back the state :meth:`_save` saved."""
        (
            self.ring,
            self.clock,
            self._pending,
            self._nonzero,
            self._magnitude,
            self.far,
            self._far_envs,
            self._block,
            self._next,
            self._sync,
            states,
        ) = saved
        for rng, state in zip(self.rngs, states, strict=True):
            rng.bit_generator.state = state

    def _push(
        self, rewards: np.ndarray, active: np.ndarray, magnitude: np.ndarray, every: bool
    ) -> tuple[np.ndarray, np.ndarray]:
        """Schedule and deliver (:meth:`step`), the rewards known to be finite.

        ``magnitude`` is ``|rewards|``, which :meth:`step` computed for its risk check, and
        ``every`` whether every env is active.
        """
        if not every:
            rewards = np.where(active, rewards, 0.0)
        delays = self._draw(active, every)
        longest = int(delays.max(initial=0))
        if longest >= self.ring.shape[1]:
            self._make_room(delays)
        mask = self.ring.shape[1] - 1  # ring lengths are powers of two: ``& mask`` is ``% length``
        if every and longest <= mask:  # the common case: every env schedules into its ring
            rows, slots, added = self.rows, (self.clock + delays) & mask, rewards
        else:
            far = delays > mask
            near = active & ~far
            rows = self.rows[near]
            slots = (self.clock[near] + delays[near]) & mask
            added = rewards[near]
            if far.any():
                self._push_far(np.flatnonzero(far & (rewards != 0.0)), rewards, delays)
        old = self.ring[rows, slots]
        new = old + added
        check = float(new.sum())  # one scalar test for the batch: NaN or inf if any entry is
        if check - check and not np.all(np.isfinite(new)):  # (x - x is 0 for every finite x)
            self._overflow(rows[~np.isfinite(new)], "the rewards due at one step")
        self.ring[rows, slots] = new
        if len(rows) == self.num_envs:
            self._nonzero += new != 0.0
            self._nonzero -= old != 0.0
        else:
            self._nonzero[rows] += (new != 0.0).astype(np.int64) - (old != 0.0)
        self._pending += rewards
        self._magnitude += magnitude if every else np.where(active, magnitude, 0.0)
        now = self.clock & mask
        if every:
            delivered = self.ring[self.rows, now]
            self.ring[self.rows, now] = 0.0
        else:
            delivered = np.where(active, self.ring[self.rows, now], 0.0)
            self.ring[self.rows[active], now[active]] = 0.0
        self._nonzero -= delivered != 0.0
        if self._far_envs:
            self._deliver_far(active, delivered)
        self._pending -= delivered
        check = float(self._pending.sum())  # as above: one scalar test before the exact check
        if check - check and not np.all(np.isfinite(self._pending)):
            for i in np.flatnonzero(~np.isfinite(self._pending)):
                self._pending[i] = self._exact(i)
        if not self._nonzero.all():
            empty = self._nonzero == 0
            for i in self._far_envs:
                empty[i] = False
            self._pending[empty] = 0.0  # exactly 0 once nothing is pending
            self._magnitude[empty] = 0.0
        self.clock += active
        return delivered, delays

    def _push_far(self, envs: np.ndarray, rewards: np.ndarray, delays: np.ndarray) -> None:
        """File the rewards of ``envs`` (delays beyond their rings) by due step in ``far``."""
        for i in envs.tolist():
            when = int(self.clock[i]) + int(delays[i])  # a Python int: no int64 overflow
            book = self.far[i]
            value = book.get(when, 0.0) + float(rewards[i])
            if value - value:  # NaN: the sum passed float64's range
                self._overflow([i], "the rewards due at one step")
            book[when] = value
            self._far_envs.add(i)

    def _deliver_far(self, active: np.ndarray, delivered: np.ndarray) -> None:
        """Add what ``far`` holds for this step to ``delivered`` (in place)."""
        for i in list(self._far_envs):
            if not active[i]:
                continue
            book = self.far[i]
            value = book.pop(int(self.clock[i]), None)
            if value is not None:
                total = delivered[i] + value
                if total - total:  # NaN: the sum passed float64's range
                    self._overflow([i], "the rewards due at one step")
                delivered[i] = total
            if not book:
                self._far_envs.discard(i)

    def _exact(self, env: int) -> float:
        """The exact pending sum of ``env``, rounded once (``ValueError`` beyond float64)."""
        row = self.ring[env]
        values = [*row[row != 0.0].tolist(), *self.far[env].values()]
        return exact_sum(values, f"sub-env {env}'s pending rewards")

    def _overflow(self, envs: Sequence[int] | np.ndarray, what: str) -> None:
        """Raise the ``ValueError`` for a sum of ``what`` beyond float64's range in ``envs``."""
        raise ValueError(
            f"{what} of sub-envs {list(map(int, envs))} sum to more than float64 can hold; "
            "rescale the env's rewards"
        )

    def clear(self, envs: np.ndarray) -> np.ndarray:
        """Empty the rings (and dicts) of the envs selected by the boolean mask ``envs``.

        Returns:
            Each env's exact pending sum (rounded once), 0 for the envs not selected.

        Raises:
            ValueError: a selected env's pending rewards sum beyond float64's range.
        """
        envs = np.asarray(envs, dtype=bool)
        amounts = np.zeros(self.num_envs)
        for i in np.flatnonzero(envs).tolist():
            if self._nonzero[i] or i in self._far_envs:
                amounts[i] = self._exact(i)
            self.far[i].clear()
            self._far_envs.discard(i)
        self.ring[envs] = 0.0
        self._nonzero[envs] = 0
        self._pending[envs] = 0.0
        self._magnitude[envs] = 0.0
        return amounts

    def _make_room(self, delays: np.ndarray) -> None:
        """Lengthen the rings for this step's longest delay that a ring allowed can hold.

        A ring may grow to at most :data:`RING_PER_STEP` slots per step taken (and at most
        ``max_ring``): a few long delays early on (``Geometric(1e-9)``) go to the dicts rather
        than make rings that would stay nearly empty.
        """
        steps = int(self.clock.max(initial=0)) + 1
        allowed = min(self.max_ring, max(INITIAL_RING, ring_size(RING_PER_STEP * steps)))
        fitting = delays[delays < allowed]
        longest = int(fitting.max(initial=0))
        if longest >= self.ring.shape[1]:
            self.ring = regrow_ring(self.ring, self.clock, ring_size(longest + 1))

    def __repr__(self) -> str:
        return (
            f"PendingRewards(num_envs={self.num_envs}, delay={self.delay!r}, "
            f"max_delay={self.max_delay!r}, ring={self.ring.shape[1]}, "
            f"far={sum(map(len, self.far))})"
        )
