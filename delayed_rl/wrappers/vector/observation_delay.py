"""The ``gymnasium.vector`` twin of :class:`~delayed_rl.wrappers.ObservationDelay`."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import iterate

from delayed_rl.delays import Delay
from delayed_rl.wrappers._delay_draws import DelaySampler
from delayed_rl.wrappers._samples import batch_of_copies, copy_sample
from delayed_rl.wrappers._spec import record_arguments
from delayed_rl.wrappers.observation_delay import (
    new_arrival_rule,
    observation_delay_settings,
)
from delayed_rl.wrappers.vector._sub_envs import (
    autoreset_mode,
    reset_inner,
)


class VectorObservationDelay(gym.vector.VectorWrapper, gym.utils.RecordConstructorArgs):
    """Delays each sub-env's observations independently, with the rule of :class:`~delayed_rl.wrappers.ObservationDelay`.

    Every sub-env has its own arrival rule (``arrival``) and delay stream. ``reset(seed=s)``
    gives sub-env ``i`` the seed ``s + i`` (``reset(seed=[s0, s1, ...])`` its entry), so that
    it shows exactly the observations of an :class:`~delayed_rl.wrappers.ObservationDelay`
    reset with that seed, and reports the same ``info`` entries. A sub-env's rule restarts with
    its episode, whose first observation is shown undelayed, under each autoreset mode; under
    ``SAME_STEP``, ``info["final_obs"]`` holds the delayed observation shown at the last step,
    not the undelayed one. Everything handed out is a copy. ``docs/semantics.md`` (vector envs)
    has the rules in full.

    ``info`` holds, with Gymnasium's ``_key`` masks (set for the sub-envs stepped or reset),
    ``observation_age`` (an ``int64`` array, each sub-env's age of the observation it shows) and
    ``arrived_observations`` (an object array of each sub-env's tuple of the ``(i, o_i)`` it
    received at this step); under ``SAME_STEP``, the ending step's are in ``info["final_info"]``.

    Args:
        env: a Gymnasium ``VectorEnv``.
        delay: a :class:`~delayed_rl.delays.Delay`, its ``to_dict()`` description, or a number
            read as a Poisson mean.
        max_delay: clip delays to at most this many steps (``None``: unbounded).
        arrival: the arrival rule, ``"stale"`` or ``"network"`` (see :class:`~delayed_rl.wrappers.ObservationDelay`).

    Raises:
        TypeError, ValueError: as :class:`~delayed_rl.wrappers.ObservationDelay`; ``ValueError``
            also for an env whose ``metadata["autoreset_mode"]`` is not a
            ``gymnasium.vector.AutoresetMode``.

    Example:
        >>> from delayed_rl.delays import Constant
        >>> envs = gym.make_vec("CartPole-v1", num_envs=2, vectorization_mode="sync")
        >>> envs = VectorObservationDelay(envs, Constant(1), arrival="network")
        >>> _ = envs.reset(seed=0)
        >>> info = envs.step(np.array([0, 1]))[-1]
        >>> info["observation_age"].tolist(), [len(got) for got in info["arrived_observations"]]
        ([1, 1], [0, 0])
    """

    def __init__(
        self,
        env: VectorEnv,
        delay: Delay | float,
        max_delay: int | None = None,
        arrival: str = "stale",
    ):
        record_arguments(self, delay=delay, max_delay=max_delay, arrival=arrival)
        gym.vector.VectorWrapper.__init__(self, env)
        self.delay, self.max_delay, self.arrival, self.history = observation_delay_settings(
            delay, max_delay, arrival
        )
        self.autoreset_mode = autoreset_mode(env)
        self.rules = [new_arrival_rule(self.arrival, self.history) for _ in range(self.num_envs)]
        self._samplers = [
            DelaySampler(self.delay, self.max_delay, "observation") for _ in range(self.num_envs)
        ]
        self._shown: list[Any] = [None] * self.num_envs  # what each sub-env shows now
        self._resetting = np.zeros(self.num_envs, dtype=bool)

    def reset(self, *, seed: int | list[int] | None = None, options: dict[str, Any] | None = None):
        """Reset all sub-envs, or those in ``options["reset_mask"]``, and their rules.

        The reset sub-envs show their ``o_0`` undelayed, with ``info["observation_age"]`` 0 and
        ``info["arrived_observations"]`` ``((0, o_0),)`` (masked to them); each one's delay
        stream is reseeded with its own seed (see the class docstring).

        Raises:
            TypeError, ValueError: ``seed`` is not ``None``, an integer ``>= 0`` or a list of
                ``num_envs`` of them (or ``None``).
        """
        seeds, envs, obs, info = reset_inner(self.env, seed, options)
        rows = list(iterate(self.env.observation_space, obs))
        arrived = np.full(self.num_envs, None, dtype=object)
        for i in np.flatnonzero(envs).tolist():
            if seeds[i] is not None:
                self._samplers[i].seed(seeds[i])
            arrived[i] = self._start(i, rows[i])
        self._resetting[envs] = False
        delays = np.zeros(self.num_envs, dtype=np.int64)
        self._report(info, delays, arrived, envs)
        return batch_of_copies(self.single_observation_space, self._shown), info

    def step(self, actions):
        """Step every sub-env; each shows an older observation (see the class docstring)."""
        obs, rewards, terminated, truncated, info = self.env.step(actions)
        rows = list(iterate(self.env.observation_space, obs))
        ended = np.asarray(terminated) | np.asarray(truncated)
        same_step = self.autoreset_mode == AutoresetMode.SAME_STEP
        delays = np.zeros(self.num_envs, dtype=np.int64)
        arrived = np.full(self.num_envs, None, dtype=object)
        final_delays, final_arrived = delays.copy(), arrived.copy()
        final_obs = info["final_obs"].copy() if same_step and ended.any() else None
        for i in range(self.num_envs):
            if self._resetting[i]:  # NEXT_STEP's reset step: the new episode's o_0
                arrived[i] = self._start(i, rows[i])
                continue
            last = same_step and ended[i]  # then rows[i] is the next episode's o_0
            made = info["final_obs"][i] if last else rows[i]
            age, shown, got = self.rules[i].receive(copy_sample(made), self._samplers[i]())
            self._shown[i] = shown
            report = (age, tuple((index, copy_sample(o)) for index, o in got))
            if last:
                final_obs[i] = copy_sample(shown)
                final_delays[i], final_arrived[i] = report
                arrived[i] = self._start(i, rows[i])
            else:
                delays[i], arrived[i] = report
        if self.autoreset_mode == AutoresetMode.NEXT_STEP:
            self._resetting = ended & ~self._resetting
        if final_obs is not None:
            info["final_obs"] = final_obs
            final_info = info.setdefault("final_info", {})
            self._report(final_info, final_delays, final_arrived, ended)
            info["_final_info"] = np.asarray(info.get("_final_info", ended)) | ended
        self._report(info, delays, arrived, np.ones(self.num_envs, dtype=bool))
        return (
            batch_of_copies(self.single_observation_space, self._shown),
            rewards,
            terminated,
            truncated,
            info,
        )

    def _start(self, i: int, first: Any) -> tuple[tuple[int, Any]]:
        """Start sub-env ``i``'s episode at ``first`` (``o_0``); return ``((0, o_0),)``, a copy."""
        first = copy_sample(first)  # the inner env's batch may be reused
        self.rules[i].reset(first)
        self._shown[i] = first
        return ((0, copy_sample(first)),)

    @staticmethod
    def _report(
        info: dict[str, Any], delays: np.ndarray, arrived: np.ndarray, mask: np.ndarray
    ) -> None:
        """Store ``observation_age`` and ``arrived_observations`` in ``info``, masked."""
        for key, values in (("observation_age", delays), ("arrived_observations", arrived)):
            info[key], info["_" + key] = values, mask.copy()
