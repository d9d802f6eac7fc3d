"""The stream a reward model learns from: each sub-env's recent transitions, in order.

:class:`TransitionHistory` keeps them, with the finished and the cut episodes.
"""

from __future__ import annotations

from collections import deque
from typing import Any

import numpy as np

from delayed_rl._validation import Limit, check_int
from delayed_rl.deep.encoding import SpaceEncoding

__all__ = ["MAX_HISTORY_BYTES", "TransitionHistory"]

MAX_HISTORY_BYTES = Limit(2**34, "MAX_HISTORY_BYTES", __name__, "2**34")
"""The most memory a history's arrays may take (16 GiB): a larger ``capacity`` is refused."""


class TransitionHistory:
    """The last ``capacity`` steps of ``n_envs`` sub-envs, oldest overwritten first.

    A :class:`TransitionHistory` keeps the last ``capacity`` steps of ``n_envs`` sub-envs that step
    together (a vector env): per step and sub-env the observation, the action, the reward delivered
    and whether the episode ended there. It also keeps the finished episodes still wholly inside it
    (their sub-env, first step and length, and the sum of their delivered rewards), which the
    episode-sum baselines sample. Steps are counted from the first one added (``steps_added``);
    the history holds steps ``max(0, steps_added − capacity) .. steps_added − 1``.

    An episode the algorithm cut short by resetting its env mid-episode (SB3's ``learn()`` does, by
    default, when it starts again) ends at its last step added (:meth:`TransitionHistory.cut`). It
    is marked in ``episode_cut`` and is not a finished episode: under a reward delay the rewards
    still pending at the reset were lost, so its delivered sum is not its return.

    With ``keep_next`` it also keeps each step's next observation (``next_obs``: the one the step
    led to, the terminal one at an episode's end), for models that read ``s′``.

    ``undelayed`` holds ``info["undelayed_reward"]`` where a step's ``info`` had it (NaN where not),
    for diagnostics only: nothing a model learns from reads it.

    Args:
        observations: the observation space's encoding.
        actions: the action space's encoding.
        n_envs: how many sub-envs step together.
        capacity: how many steps (of every sub-env) are kept.
        keep_next: also keep each step's next observation.

    Attributes:
        obs, action, reward, episode_end, episode_cut, undelayed: the ring's arrays, indexed
            ``[step % capacity, env]`` (``obs`` and ``action`` are dicts of arrays for a ``Dict``
            space: read them with :meth:`observations_at` and :meth:`actions_at`).
        next_obs: the next observations, likewise (``None`` without ``keep_next``).
        episodes: the finished episodes wholly inside the ring (from :attr:`first_whole`),
            in order of first step, as ``(env, first_step, length, delivered_sum)``.
        steps_added: how many steps were added.
    """

    def __init__(
        self,
        observations: SpaceEncoding,
        actions: SpaceEncoding,
        n_envs: int,
        capacity: int,
        keep_next: bool = False,
    ):
        self.n_envs = check_int("n_envs", n_envs, 1)
        self.capacity = check_int("capacity", capacity, 1)
        obs_bytes = observations.value_bytes * (2 if keep_next else 1)
        per_step = n_envs * (obs_bytes + actions.value_bytes + 8 + 1 + 1 + 8)
        if per_step * self.capacity > MAX_HISTORY_BYTES:
            raise ValueError(
                f"capacity must keep the history's size at most {MAX_HISTORY_BYTES.text}, got "
                f"{capacity} steps of {n_envs} sub-envs at {per_step // n_envs} bytes a "
                "transition"
            )
        self.observations, self.actions = observations, actions
        self.obs = observations.empty(self.capacity, n_envs)
        self.next_obs = observations.empty(self.capacity, n_envs) if keep_next else None
        self.action = actions.empty(self.capacity, n_envs)
        self.reward = np.zeros((self.capacity, n_envs))
        self.episode_end = np.zeros((self.capacity, n_envs), dtype=bool)
        self.episode_cut = np.zeros((self.capacity, n_envs), dtype=bool)
        self.undelayed = np.full((self.capacity, n_envs), np.nan)
        self.episodes: deque[tuple[int, int, int, float]] = deque()
        self.steps_added = 0
        self._episode_first = np.zeros(n_envs, dtype=np.int64)
        self._episode_sum = np.zeros(n_envs)

    @property
    def oldest(self) -> int:
        """The first step still held."""
        return max(0, self.steps_added - self.capacity)

    def add(
        self,
        obs: np.ndarray,
        action: np.ndarray,
        reward: np.ndarray,
        episode_end: np.ndarray,
        undelayed: np.ndarray,
        next_obs: np.ndarray | None = None,
    ) -> None:
        """Append one step of every sub-env (arrays checked by the caller, one row a sub-env).

        ``next_obs`` is kept when the history keeps next observations (and ignored otherwise).
        """
        step = self.steps_added
        row = step % self.capacity
        self.observations.put(self.obs, row, obs)
        if self.next_obs is not None:
            self.observations.put(self.next_obs, row, next_obs)
        self.actions.put(self.action, row, action)
        self.reward[row] = reward
        self.episode_end[row] = episode_end
        self.episode_cut[row] = False
        self.undelayed[row] = undelayed
        self._episode_sum += reward
        self.steps_added = step + 1
        episodes = self.episodes
        for env in np.flatnonzero(episode_end):
            first = int(self._episode_first[env])
            # kept in order of first step (with several sub-envs an episode can end after one
            # that began later), so that the episodes cut by the ring are the first ones
            later = 0
            while later < len(episodes) and episodes[-1 - later][1] > first:
                later += 1
            episode = (int(env), first, step + 1 - first, float(self._episode_sum[env]))
            episodes.insert(len(episodes) - later, episode)
            self._episode_first[env] = step + 1
            self._episode_sum[env] = 0.0
        while episodes and episodes[0][1] < self.first_whole:
            episodes.popleft()

    def __setstate__(self, state: dict[str, Any]) -> None:
        # a history pickled before cuts were kept (in an SB3 buffer or algorithm file) had none
        state.setdefault("episode_cut", np.zeros_like(state["episode_end"]))
        self.__dict__.update(state)

    def cut(self, envs: np.ndarray) -> None:
        """End the open episodes of sub-envs ``envs`` at the last step added: they were reset.

        A sub-env whose last step ended its episode (or that has no step) has nothing to cut.
        The cut episode is marked in ``episode_cut`` and left out of :attr:`episodes`.
        """
        if not self.steps_added:
            return
        last = self.steps_added - 1
        for env in np.asarray(envs, dtype=np.int64).reshape(-1).tolist():
            if self._episode_first[env] <= last:
                self.episode_cut[last % self.capacity, env] = True
                self._episode_first[env] = self.steps_added
                self._episode_sum[env] = 0.0

    @property
    def first_whole(self) -> int:
        """The earliest first step of an episode the ring shows whole.

        Once steps were overwritten, an episode that began at :attr:`oldest` is not known to
        have begun there (the end before it is gone): an episode must begin after it.
        """
        oldest = self.oldest
        return oldest + 1 if oldest > 0 else 0

    def rows(self, first: int, stop: int) -> np.ndarray:
        """The ring rows of steps ``first .. stop − 1`` (all held)."""
        return np.arange(first, stop) % self.capacity

    def observations_at(self, rows: np.ndarray, envs: np.ndarray) -> Any:
        """The stored observations at ``[rows, envs]``, flattened to one batch."""
        return self.observations.flat(self.observations.take(self.obs, (rows, envs)))

    def next_observations_at(self, rows: np.ndarray, envs: np.ndarray) -> Any:
        """The stored next observations at ``[rows, envs]``, flattened to one batch."""
        return self.observations.flat(self.observations.take(self.next_obs, (rows, envs)))

    def actions_at(self, rows: np.ndarray, envs: np.ndarray) -> Any:
        """The stored actions at ``[rows, envs]``, flattened to one batch."""
        return self.actions.flat(self.actions.take(self.action, (rows, envs)))

    def episode_ids(self, env: int, first: int, stop: int) -> np.ndarray:
        """An id per step ``first .. stop − 1`` of sub-env ``env``: equal within an episode.

        An episode cut short (:meth:`cut`) is an episode of its own.
        """
        rows = self.rows(first, stop)
        ends = self.episode_end[rows, env] | self.episode_cut[rows, env]
        return np.concatenate(([0], np.cumsum(ends[:-1])))
