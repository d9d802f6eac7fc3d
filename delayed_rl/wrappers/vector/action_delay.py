"""The ``gymnasium.vector`` twin of :class:`~delayed_rl.wrappers.ActionDelay`."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import concatenate, create_empty_array

from delayed_rl.delays import Delay, as_delay
from delayed_rl.wrappers._delay_draws import DelaySampler, check_max_delay
from delayed_rl.wrappers._samples import as_action, copy_sample
from delayed_rl.wrappers._spec import record_arguments
from delayed_rl.wrappers.action_delay import ActionLine, checked_action, neutral_action
from delayed_rl.wrappers.vector._sub_envs import (
    autoreset_mode,
    reset_inner,
    unbatch_actions,
)


class VectorActionDelay(gym.vector.VectorWrapper, gym.utils.RecordConstructorArgs):
    """Delays each sub-env's actions independently, with the rule of :class:`~delayed_rl.wrappers.ActionDelay`.

    Every sub-env has its own :class:`~delayed_rl.wrappers.action_delay.ActionLine` and delay
    stream. ``reset(seed=s)`` gives sub-env ``i`` the seed ``s + i``, so that it executes
    exactly the actions an :class:`~delayed_rl.wrappers.ActionDelay` reset with that seed would.
    A sub-env's line restarts with its episode, under each autoreset mode (under ``NEXT_STEP``
    the action given for the reset step is not sent). Actions are batched as in
    ``gymnasium.vector`` and copied as :class:`~delayed_rl.wrappers.ActionDelay` copies them.
    ``docs/semantics.md`` (vector envs) has the rules in full.

    ``info`` holds, with Gymnasium's ``_key`` masks, ``executed_action`` (the batch of actions
    executed), ``executed_action_step`` and ``drawn_action_delay`` (for the sub-envs that sent an
    action at this step).

    Args:
        env: a Gymnasium ``VectorEnv``.
        delay: a :class:`~delayed_rl.delays.Delay`, its ``to_dict()`` description, or a number
            read as a Poisson mean.
        initial_action: one sub-env's initial action (``None``: the neutral action of its
            action space, :func:`~delayed_rl.wrappers.action_delay.neutral_action`).
        max_delay: clip delays to at most this many steps (``None``: unbounded).

    Raises:
        TypeError, ValueError: as :class:`~delayed_rl.wrappers.ActionDelay`, and for an unknown autoreset mode.

    Example:
        >>> import gymnasium as gym
        >>> import numpy as np
        >>> from delayed_rl.delays import Constant
        >>> envs = VectorActionDelay(gym.make_vec("Pendulum-v1", num_envs=2), Constant(1))
        >>> _ = envs.reset(seed=0)
        >>> *_, info = envs.step(np.array([[1.0], [2.0]], dtype=np.float32))
        >>> info["executed_action"].tolist(), info["executed_action_step"].tolist()  # the neutral
        ([[0.0], [0.0]], [-1, -1])
        >>> *_, info = envs.step(np.array([[0.5], [0.5]], dtype=np.float32))
        >>> info["executed_action"].tolist(), info["drawn_action_delay"].tolist()  # one step late
        ([[1.0], [2.0]], [1, 1])
    """

    def __init__(
        self,
        env: VectorEnv,
        delay: Delay | float,
        initial_action: Any = None,
        max_delay: int | None = None,
    ):
        record_arguments(self, delay=delay, initial_action=initial_action, max_delay=max_delay)
        gym.vector.VectorWrapper.__init__(self, env)
        self.delay = as_delay(delay)
        self.max_delay = check_max_delay(max_delay)
        space = env.single_action_space
        if initial_action is None:
            initial_action = neutral_action(space)
        self.initial_action = as_action(space, initial_action, "initial_action")
        self.autoreset_mode = autoreset_mode(env)
        self.lines = [ActionLine(copy_sample(self.initial_action)) for _ in range(self.num_envs)]
        self._samplers = [
            DelaySampler(self.delay, self.max_delay, "action") for _ in range(self.num_envs)
        ]
        self._resetting = np.zeros(self.num_envs, dtype=bool)

    def reset(self, *, seed: int | list[int] | None = None, options: dict[str, Any] | None = None):
        """Reset all sub-envs, or those in ``options["reset_mask"]``, and their lines.

        Raises:
            TypeError, ValueError: ``seed`` is not ``None``, an integer ``>= 0`` or a list of
                ``num_envs`` of them (or ``None``).
        """
        seeds, envs, obs, info = reset_inner(self.env, seed, options)
        for i in np.flatnonzero(envs):
            if seeds[i] is not None:
                self._samplers[i].seed(seeds[i])
            self.lines[i].reset()
        self._resetting[envs] = False
        return obs, info

    def step(self, actions):
        """Send each sub-env's action; step them with the actions executed now.

        Raises:
            TypeError: ``actions`` is not a batch of the action space's form (see the class
                docstring).
            ValueError: it does not hold one action per sub-env, or a sub-env's action is not
                in the single action space (the message names ``actions[i]``).
        """
        space = self.single_action_space
        given = unbatch_actions(self, actions)
        executed = list(given)  # the reset step's sub-envs ignore the action given
        sent_steps = np.full(self.num_envs, -1, dtype=np.int64)
        delays = np.zeros(self.num_envs, dtype=np.int64)
        sending = ~self._resetting
        for i in np.flatnonzero(sending).tolist():
            action = checked_action(space, given[i], f"actions[{i}]")
            delays[i] = self._samplers[i]()
            executed[i] = self.lines[i].send(action, int(delays[i]))
            sent_steps[i] = self.lines[i].executed_step
        batch = self._batch(executed)  # new arrays: the lines' actions are not handed out
        report = copy_sample(batch)  # another: the inner env may edit its batch in place
        obs, rewards, terminated, truncated, info = self.env.step(batch)
        ended = np.asarray(terminated) | np.asarray(truncated)
        if self.autoreset_mode == AutoresetMode.NEXT_STEP:
            self._resetting = ended & sending
            for i in np.flatnonzero(~sending):  # this was the reset step: a new episode
                self.lines[i].reset()
        elif self.autoreset_mode == AutoresetMode.SAME_STEP:
            for i in np.flatnonzero(ended):
                self.lines[i].reset()
        for key, values in (
            ("executed_action", report),
            ("executed_action_step", sent_steps),
            ("drawn_action_delay", delays),
        ):
            info[key], info["_" + key] = values, sending.copy()
        return obs, rewards, terminated, truncated, info

    def _batch(self, actions: list[Any]) -> Any:
        """One batch (new arrays) of the sub-envs' ``actions`` (``gymnasium.vector.utils``).

        Raises:
            ValueError: the actions do not stack into a batch of the action space (an action
                given for a sub-env at its reset step, which is not checked, of the wrong
                shape).
        """
        space = self.single_action_space
        try:
            return concatenate(space, actions, create_empty_array(space, self.num_envs))
        except (TypeError, ValueError) as error:
            raise ValueError(
                f"actions must be a batch of {self.num_envs} actions of {space}, got actions "
                f"that do not stack into one ({error}): {actions!r}"
            ) from None
