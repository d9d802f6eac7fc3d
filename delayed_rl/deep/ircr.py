"""Iterative relative credit refinement (IRCR; Gangwani, Zhou and Peng, NeurIPS 2020), as published.

IRCR learns no reward network. Every stored transition's *guidance reward* is a credit of the
episode it belongs to, min–max normalised over the credits of the episodes in the buffer at
sample time, and half of every batch comes from a small heap of the episodes with the highest
returns (self-imitation). It reads only episode sums, so it is delay-agnostic: under a reward
delay that flushes its pending rewards at an episode's end, an episode's delivered rewards sum to
its return, whatever the delays.

:class:`IRCRReplayBuffer` follows the authors' code (tgangwani/GuidanceRewards) where SB3
allows; the class docstring lists where it cannot.
"""

from __future__ import annotations

from collections import deque
from typing import Any, NamedTuple

import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3.common.buffers import ReplayBuffer
from stable_baselines3.common.type_aliases import ReplayBufferSamples

from delayed_rl._validation import check_choice, check_int
from delayed_rl.deep.binding import calling_algorithm, env_was_reset, remember_episode_starts

__all__ = ["CREDITS", "IRCRReplayBuffer"]

CREDITS = ("mean", "return")
"""The values of :class:`IRCRReplayBuffer`'s ``credit``."""


class _HeapEpisode(NamedTuple):
    """One episode kept by the heap: its return (the priority), credit and transitions."""

    priority: float
    credit: float
    observations: np.ndarray
    actions: np.ndarray
    next_observations: np.ndarray
    dones: np.ndarray


class IRCRReplayBuffer(ReplayBuffer):
    """SB3's ``ReplayBuffer`` whose batches are IRCR's: guidance rewards, half from the best episodes.

    Pass it as ``replay_buffer_class`` of SAC, TD3 or DQN (Box or Discrete observations).

    **Episodes.** A transition becomes sampleable when its episode ends (a ``done`` of SB3's
    vector env: terminated or truncated); the open episode's transitions are stored but never
    sampled. When an episode ends, its *credit* is fixed: its mean delivered reward (``credit=
    "mean"``, the authors' code) or their sum (``"return"``, the paper's episodic return and the
    port in Stilwell-Git/Randomized-Return-Decomposition); the two agree up to scale when all
    episodes have one length. Its return (the sum) is its priority for the heap. An episode the
    algorithm cuts short by resetting its env (SB3's ``learn()`` does when it starts again with
    ``reset_num_timesteps=True``) never becomes sampleable: the rewards pending at the reset are
    lost to it, so its sum is not its return.

    **The heap** keeps the ``heap_episodes`` episodes with the highest returns seen (copies: the
    ring may overwrite them). A finished episode enters when the heap has room, or replaces the
    lowest-return episode when its return is at least that one's (ties: the one in the earliest
    slot, as the authors' ``heapq`` of ``[priority, slot]`` does).

    **A batch** of ``batch_size`` transitions: ``batch_size − batch_size // 2`` drawn uniformly
    from the finished transitions still in the ring, ``batch_size // 2`` from the heap's. Each
    reward is the guidance ``(c − c_min) / (c_max − c_min)`` of its episode's credit ``c``, with
    ``c_min`` and ``c_max`` over the episodes with a transition still in the ring and those in the
    heap. ``dones`` exclude time-limit truncations (SB3's ``handle_timeout_termination``, as the
    authors' rollouts do). Guidance is not scaled by a ``VecNormalize`` (it is already in
    [0, 1]); observations are normalised as SB3 normalises them.

    Batches are drawn from NumPy's global generator, as SB3's buffers draw them, so a seeded
    algorithm draws the same batches.

    **Before the first batch** the buffer needs a finished episode: until then :meth:`sample`
    raises ``RuntimeError``; set the algorithm's ``learning_starts`` to a few episodes' steps.
    While every credit held is the same, every guidance reward is 1: before two episodes' credits
    differ (a sparse task's first episodes, all of return 0), and if they all become equal again.
    The authors run two exploration episodes and assert ``c_min < c_max``, which stops their run
    there; a run here goes on, with guidance that carries nothing until two credits differ
    (``distinct_credits_seen`` says whether they have).

    **Where SB3 differs from the authors' code.**

    - The authors draw ``batch_size`` transitions from the ring and as many from the heap (512 +
      512 with their SAC); here ``batch_size`` is the whole batch, so pass twice their size
      (``batch_size=1024``) to match them.
    - The ring's transitions are drawn with replacement (as SB3 draws), where the authors draw
      without; the heap's without replacement when it holds enough, as theirs.
    - The ring keeps transitions, not whole episodes: the authors add an episode at its end and
      roll the oldest out; here the open episode's transitions take ring rows as they come (they
      are not sampled until it ends). Their other settings (SAC with ``tau=0.001``,
      ``learning_rate=3e-4``, initial temperature 0.1, a 300k-transition buffer, γ = 0.99) are
      the algorithm's arguments.
    - Their SAC differs from SB3's where SB3 has no argument for it: the temperature learns at
      1e-4 (SB3: the one ``learning_rate``), the critic's loss is the smooth L1 (SB3: squared
      error), gradients are clipped to norm 1, and the policy's log-std is bounded to [−5, 2]
      (SB3: [−20, 2]).

    Args:
        buffer_size, observation_space, action_space, device, n_envs: as SB3's ``ReplayBuffer``.
        optimize_memory_usage: must be False (the heap copies next observations).
        handle_timeout_termination: as SB3's ``ReplayBuffer``.
        heap_episodes: how many of the best episodes the heap keeps (the authors': 10), an
            integer >= 1.
        credit: ``"mean"`` or ``"return"`` (see above).

    Raises:
        TypeError: a ``Dict`` observation space, or an argument of the wrong type.
        ValueError: ``optimize_memory_usage=True``, ``heap_episodes < 1``, an unknown
            ``credit``.

    Example:
        >>> import gymnasium as gym
        >>> from stable_baselines3 import SAC
        >>> from delayed_rl.wrappers import RewardDelay
        >>> env = RewardDelay(gym.make("Pendulum-v1"), 20)  # Poisson(20) delays, flushed
        >>> agent = SAC("MlpPolicy", env, replay_buffer_class=IRCRReplayBuffer,
        ...             learning_starts=1000, batch_size=512, seed=0)
    """

    def __init__(
        self,
        buffer_size: int,
        observation_space: Any,
        action_space: Any,
        device: torch.device | str = "auto",
        n_envs: int = 1,
        optimize_memory_usage: bool = False,
        handle_timeout_termination: bool = True,
        *,
        heap_episodes: int = 10,
        credit: str = "mean",
    ):
        if isinstance(observation_space, spaces.Dict):
            raise TypeError(
                f"IRCRReplayBuffer takes a Box or Discrete observation_space, got "
                f"{observation_space!r}"
            )
        if optimize_memory_usage:
            raise ValueError(
                "IRCRReplayBuffer needs optimize_memory_usage=False (its heap copies the next "
                "observations), got True"
            )
        self.heap_episodes = check_int("heap_episodes", heap_episodes, 1, 2**20)
        self.credit = check_choice("credit", credit, CREDITS)
        super().__init__(
            buffer_size,
            observation_space,
            action_space,
            device,
            n_envs=n_envs,
            optimize_memory_usage=False,
            handle_timeout_termination=handle_timeout_termination,
        )
        self.credits = np.zeros((self.buffer_size, self.n_envs))
        self.steps_added = 0
        self.episodes: deque[tuple[int, int, int, float]] = deque()
        self.heap: list[_HeapEpisode] = []
        self._episode_first = np.zeros(self.n_envs, dtype=np.int64)
        self._episode_sum = np.zeros(self.n_envs)
        self._cut_spans: list[deque[tuple[int, int]]] = [deque() for _ in range(self.n_envs)]
        self._heap_arrays: tuple[np.ndarray, ...] | None = None
        self._bounds: tuple[float, float] | None = None
        self.distinct_credits_seen = False
        algorithm = calling_algorithm("_setup_model")
        if algorithm is not None:
            remember_episode_starts(self, algorithm)

    def __setstate__(self, state: dict[str, Any]) -> None:
        # a buffer pickled before cuts were kept had none
        state.setdefault("_cut_spans", [deque() for _ in range(state["n_envs"])])
        self.__dict__.update(state)
        algorithm = calling_algorithm("load_replay_buffer")
        if algorithm is not None:
            remember_episode_starts(self, algorithm)

    # ------------------------------------------------------------------ storing
    @property
    def oldest(self) -> int:
        """The first step (counted over ``add`` calls) still in the ring."""
        return max(0, self.steps_added - self.buffer_size)

    def add(self, obs, next_obs, action, reward, done, infos) -> None:  # noqa: D417
        """Store the transition as SB3 does; an episode that ends here gets its credit.

        When the algorithm reset its env since the last step (:func:`~.binding.env_was_reset`),
        the open episodes are cut first: their transitions are never sampled.
        """
        if env_was_reset(self):
            self._cut_open_episodes()
        super().add(obs, next_obs, action, reward, done, infos)
        step = self.steps_added
        self.steps_added = step + 1
        self._episode_sum += np.asarray(reward, dtype=np.float64).reshape(self.n_envs)
        for env in np.flatnonzero(np.asarray(done).reshape(self.n_envs)).tolist():
            self._finish(env, int(self._episode_first[env]), step + 1)
            self._episode_first[env] = step + 1
            self._episode_sum[env] = 0.0
        while self.episodes and self.episodes[0][2] <= self.oldest:
            self.episodes.popleft()
            self._bounds = None
        for spans in self._cut_spans:
            while spans and spans[0][1] <= self.oldest:
                spans.popleft()

    def _cut_open_episodes(self) -> None:
        """Leave each sub-env's open episode unfinished for good: it was reset mid-way."""
        for env, first in enumerate(self._episode_first.tolist()):
            if first < self.steps_added:
                self._cut_spans[env].append((first, self.steps_added))
                self._episode_first[env] = self.steps_added
                self._episode_sum[env] = 0.0

    def _finish(self, env: int, first: int, stop: int) -> None:
        """Give the episode of sub-env ``env`` over steps ``first .. stop − 1`` its credit."""
        total = float(self._episode_sum[env])
        credit = total / (stop - first) if self.credit == "mean" else total
        rows = np.arange(max(first, stop - self.buffer_size), stop) % self.buffer_size
        self.credits[rows, env] = credit
        self.episodes.append((env, first, stop, credit))
        self._bounds = None
        self._offer(total, credit, rows, env)

    def _offer(self, priority: float, credit: float, rows: np.ndarray, env: int) -> None:
        """Put the episode in the heap if it has room or the episode beats its lowest return."""
        if len(self.heap) < self.heap_episodes:
            slot = len(self.heap)
        else:
            slot = min(range(len(self.heap)), key=lambda i: (self.heap[i].priority, i))
            if priority < self.heap[slot].priority:
                return
        dones = self.dones[rows, env] * (1 - self.timeouts[rows, env])
        episode = _HeapEpisode(
            priority,
            credit,
            self.observations[rows, env].copy(),
            self.actions[rows, env].copy(),
            self.next_observations[rows, env].copy(),
            dones.astype(np.float32),
        )
        if slot == len(self.heap):
            self.heap.append(episode)
        else:
            self.heap[slot] = episode
        self._heap_arrays = None

    # ------------------------------------------------------------------ guidance
    def credit_bounds(self) -> tuple[float, float] | None:
        """``(c_min, c_max)`` over the episodes in the ring and the heap (``None``: none yet)."""
        if self._bounds is None:
            credits = [credit for *_, credit in self.episodes]
            credits += [episode.credit for episode in self.heap]
            if not credits:
                return None
            self._bounds = (min(credits), max(credits))
            self.distinct_credits_seen |= self._bounds[0] < self._bounds[1]
        return self._bounds

    def guidance(self, credits: np.ndarray) -> np.ndarray:
        """The guidance rewards of episodes with ``credits`` (see the class docstring).

        Raises:
            RuntimeError: no episode has finished.
        """
        bounds = self.credit_bounds()
        if bounds is None:
            raise RuntimeError(
                "IRCRReplayBuffer cannot normalise guidance rewards yet: no episode has "
                "finished; raise the algorithm's learning_starts to a few episodes' steps"
            )
        low, high = bounds
        if high == low:
            return np.ones_like(credits)
        return (credits - low) / (high - low)

    # ------------------------------------------------------------------ sampling
    def _ring_draw(self, count: int) -> tuple[np.ndarray, np.ndarray]:
        """``count`` (row, sub-env) pairs drawn uniformly from the finished transitions."""
        oldest = self.oldest
        spans = [[(max(first, oldest), stop) for first, stop in cut] for cut in self._cut_spans]
        holes = np.array([sum(stop - first for first, stop in cut) for cut in spans], np.int64)
        finished = np.maximum(0, self._episode_first - oldest) - holes
        cumulative = np.cumsum(finished)
        if cumulative[-1] == 0:
            raise RuntimeError(
                "IRCRReplayBuffer has no finished episode to sample: raise the algorithm's "
                "learning_starts to a few episodes' steps"
            )
        # NumPy's global generator, as SB3's buffers draw: the algorithm's seed seeds it
        draws = np.random.randint(0, cumulative[-1], size=count)  # noqa: NPY002
        envs = np.searchsorted(cumulative, draws, side="right")
        steps = oldest + draws - (cumulative[envs] - finished[envs])
        for env in np.flatnonzero(holes).tolist():  # skip the cut episodes' steps, in order
            mine = envs == env
            for first, stop in spans[env]:
                steps[mine] += np.where(steps[mine] >= first, stop - first, 0)
        return steps % self.buffer_size, envs

    def _heap_draw(self, count: int) -> tuple[np.ndarray, ...]:
        """``count`` heap transitions: without replacement when it holds enough."""
        if self._heap_arrays is None:
            fields = zip(*(episode[2:] for episode in self.heap), strict=True)
            arrays = [np.concatenate(field) for field in fields]
            lengths = [len(episode.dones) for episode in self.heap]
            credits = np.repeat([episode.credit for episode in self.heap], lengths)
            self._heap_arrays = (*arrays, credits)
        size = len(self._heap_arrays[-1])
        if size >= count:
            picks = np.random.choice(size, size=count, replace=False)  # noqa: NPY002
        else:
            picks = np.random.randint(0, size, size=count)  # noqa: NPY002
        return tuple(array[picks] for array in self._heap_arrays)

    def sample(self, batch_size: int, env: Any = None) -> ReplayBufferSamples:
        """A batch: ``batch_size − batch_size // 2`` from the ring, the rest from the heap.

        Raises:
            RuntimeError: no finished episode.
        """
        rows, envs = self._ring_draw(batch_size - batch_size // 2)
        heap_obs, heap_actions, heap_next, heap_dones, heap_credits = self._heap_draw(
            batch_size // 2
        )
        credits = np.concatenate([self.credits[rows, envs], heap_credits])
        rewards = self.guidance(credits).astype(np.float32)
        dones = self.dones[rows, envs] * (1 - self.timeouts[rows, envs])
        data = (
            self._normalize_obs(np.concatenate([self.observations[rows, envs], heap_obs]), env),
            np.concatenate([self.actions[rows, envs], heap_actions]),
            self._normalize_obs(
                np.concatenate([self.next_observations[rows, envs], heap_next]), env
            ),
            np.concatenate([dones, heap_dones]).reshape(-1, 1),
            rewards.reshape(-1, 1),
        )
        return ReplayBufferSamples(*tuple(map(self.to_torch, data)))
