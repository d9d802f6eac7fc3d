"""Action delay: the env executes an action sent a random number of steps earlier.

The third delay of the general delayed MDP (state, action and reward delays): the agent's
command travels to the actuator through a link that takes ``d_t`` steps, ``d_t`` drawn from a
:mod:`delayed_rl.delays` distribution. :class:`ActionDelay` wraps one env;
:class:`VectorActionDelay` is its ``gymnasium.vector`` twin. Both use :class:`ActionLine`, the
rule itself.
"""

from __future__ import annotations

import heapq
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv

from delayed_rl.delays import Delay, as_delay, delay_spec
from delayed_rl.wrappers._spec import JsonSpecMixin
from delayed_rl.wrappers.reward_delay import DelaySampler, check_max_delay
from delayed_rl.wrappers.vector import autoreset_mode, reset_mask, sub_env_seeds

__all__ = ["ActionDelay", "ActionLine", "VectorActionDelay", "neutral_action"]


def neutral_action(space: gym.Space) -> Any:
    """The action executed before any sent action has arrived, when none is given.

    ``Discrete``: its first action (``start``, usually 0); ``Box``: zeros, clipped into the box;
    ``MultiDiscrete``: each entry's first value (``start``); ``MultiBinary``: zeros.

    Raises:
        ValueError: any other space (give ``initial_action``).
    """
    if isinstance(space, spaces.Discrete):
        return space.dtype.type(space.start)
    if isinstance(space, spaces.Box):
        return np.clip(np.zeros(space.shape, space.dtype), space.low, space.high)
    if isinstance(space, spaces.MultiDiscrete):
        return np.array(space.start, dtype=space.dtype)
    if isinstance(space, spaces.MultiBinary):
        return np.zeros(space.shape, dtype=space.dtype)
    raise ValueError(
        f"initial_action must be given for an action space of type {type(space).__name__} "
        f"({space}): there is no neutral action to default to"
    )


def _check_action(space: gym.Space, action: Any, name: str) -> Any:
    """``action``, checked to be in ``space`` (an array is copied: it may be reused by the caller).

    Raises:
        ValueError: ``action`` is not in ``space``.
    """
    if isinstance(action, np.ndarray):
        action = action.copy()
    if not space.contains(action):
        raise ValueError(f"{name} must be an action of {space}, got {action!r}")
    return action


class ActionLine:
    """One env's actions in transit, and which of them is executed at each step.

    Step ``t`` (counted from 0 in each episode) sends ``a_t``, which arrives at step ``t + d_t``.
    The action executed at step ``t`` is the most recently *sent* action among those that have
    arrived by then (``i + d_i ≤ t``, largest ``i``): it stays in force until a later-sent
    action arrives. An action that arrives after a later-sent one is never executed (the
    actuator already obeys a newer command). Before the episode's first action arrives, the
    line executes ``initial_action``.

    Only the actions still in transit are kept (a heap by arrival step), so memory follows what
    is in flight, not the delay's bound.

    Args:
        initial_action: what to execute until the episode's first action arrives.

    Attributes:
        executed: the action in force (executed at the last step sent).
        executed_step: the episode step that sent it (``-1``: the initial action).
    """

    def __init__(self, initial_action: Any):
        self.initial_action = initial_action
        self.reset()

    def reset(self) -> None:
        """Start an episode: nothing in transit, the initial action in force."""
        self._in_transit: list[tuple[int, int, Any]] = []  # (arrival step, sent step, action)
        self._step = 0
        self.executed: Any = self.initial_action
        self.executed_step = -1  # the step that sent it (-1: the initial action)

    @property
    def in_transit(self) -> int:
        """How many sent actions have not arrived yet."""
        return len(self._in_transit)

    def send(self, action: Any, delay: int) -> Any:
        """Send this step's ``action`` with ``delay`` steps of transit; return the one executed.

        :attr:`executed_step` is then the step that sent it (``-1``: the initial action).
        """
        step = self._step
        self._step = step + 1
        if delay == 0 and not self._in_transit:  # the common undelayed case, no heap
            self.executed, self.executed_step = action, step
            return action
        heapq.heappush(self._in_transit, (step + delay, step, action))  # (arrival, sent) unique
        while self._in_transit and self._in_transit[0][0] <= step:
            _, sent, arrived = heapq.heappop(self._in_transit)
            if sent > self.executed_step:
                self.executed, self.executed_step = arrived, sent
        return self.executed


class ActionDelay(JsonSpecMixin, gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Executes, at step ``t``, the action sent ``d_t`` steps earlier, ``d_t`` drawn from ``delay``.

    The rule (:class:`ActionLine`): the action sent at step ``t`` arrives at step ``t + d_t``; the
    env executes, at each step, the latest-sent action that has arrived — actions arriving out of
    order after a later-sent one are never executed — and, before the episode's first action
    arrives, ``initial_action``. A constant delay ``k`` (``Constant(k)``) is the classic
    constant-delay MDP: step ``t`` executes ``a_{t−k}``, and ``initial_action`` for ``t < k``.
    Actions still in transit when an episode ends are discarded by the next ``reset()``.

    Every action sent is checked against the action space (an action that would never be
    executed is still refused if it is invalid). ``info`` is the inner env's plus
    ``info["executed_action"]`` (the action the env executed), ``info["executed_action_step"]``
    (the episode step that sent it, ``-1`` for ``initial_action``) and ``info["action_delay"]``
    (``d_t``, the transit time drawn for this step's action). Seeded by ``reset(seed=...)`` from
    an independent delay stream, as :class:`~delayed_rl.wrappers.RewardDelay`.

    Args:
        env: the env whose actions to delay.
        delay: a :class:`~delayed_rl.delays.Delay`, its ``to_dict()`` description, or a number
            read as a Poisson mean.
        initial_action: executed until the episode's first action arrives; ``None``: the
            space's neutral action (:func:`neutral_action`: 0 for ``Discrete``, zeros for
            ``Box``).
        max_delay: clip delays to at most this many steps (``None``: unbounded).

    Raises:
        TypeError: ``delay`` is neither a ``Delay`` nor a number, or ``max_delay`` is not an
            integer.
        ValueError: ``delay`` is not a valid Poisson mean, ``max_delay`` is negative,
            ``initial_action`` is not in the action space, or it is ``None`` for a space without
            a neutral action.

    Example:
        >>> import gymnasium as gym
        >>> from delayed_rl.delays import Constant
        >>> env = ActionDelay(gym.make("CartPole-v1"), Constant(2), initial_action=0)
        >>> _ = env.reset(seed=0)
        >>> [env.step(a)[-1]["executed_action"] for a in (1, 1, 0, 1)]
        [0, 0, 1, 1]
    """

    def __init__(
        self,
        env: gym.Env,
        delay: Delay | float,
        initial_action: Any = None,
        max_delay: int | None = None,
    ):
        gym.utils.RecordConstructorArgs.__init__(
            self, delay=delay_spec(delay), initial_action=initial_action, max_delay=max_delay
        )
        gym.Wrapper.__init__(self, env)
        self.delay = as_delay(delay)
        self.max_delay = check_max_delay(max_delay)
        if initial_action is None:
            initial_action = neutral_action(env.action_space)
        self.initial_action = _check_action(env.action_space, initial_action, "initial_action")
        self._sampler = DelaySampler(self.delay, self.max_delay)
        self.line = ActionLine(self.initial_action)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Reset the env and the line (actions in transit are discarded); ``seed`` reseeds it."""
        obs, info = self.env.reset(seed=seed, options=options)
        if seed is not None:
            self._sampler.seed(seed)
        self.line.reset()
        return obs, info

    def step(self, action):
        """Send ``action``; step the env with the action executed now (see the class docstring)."""
        action = _check_action(self.action_space, action, "action")
        delay = self._sampler()
        executed = self.line.send(action, delay)
        obs, reward, terminated, truncated, info = self.env.step(executed)
        info["executed_action"] = executed
        info["executed_action_step"] = self.line.executed_step
        info["action_delay"] = delay
        return obs, reward, terminated, truncated, info


class VectorActionDelay(gym.vector.VectorWrapper, gym.utils.RecordConstructorArgs):
    """Delays each sub-env's actions independently, with the rule of :class:`ActionDelay`.

    Every sub-env has its own :class:`ActionLine` and delay stream (seeded as
    :class:`~delayed_rl.wrappers.VectorRewardDelay` seeds them: ``reset(seed=s)`` gives sub-env
    ``i`` the seed ``s + i``, so it executes exactly the actions an :class:`ActionDelay` reset
    with ``seed=s + i`` would). A sub-env's line restarts with its episode: under the
    ``NEXT_STEP`` autoreset mode at the reset step that follows an episode's end (the action
    given for that step is not sent: the sub-env ignores it), under ``SAME_STEP`` right after
    the ending step, under ``DISABLED`` when ``reset(options={"reset_mask": ...})`` resets it.

    ``info`` holds, with Gymnasium's ``_key`` masks, ``executed_action`` (the batch of actions
    executed), ``executed_action_step`` and ``action_delay`` (for the sub-envs that sent an
    action at this step).

    Args:
        env: a Gymnasium ``VectorEnv``.
        delay: a :class:`~delayed_rl.delays.Delay`, its ``to_dict()`` description, or a number
            read as a Poisson mean.
        initial_action: one sub-env's initial action (``None``: the neutral action of its
            action space, :func:`neutral_action`).
        max_delay: clip delays to at most this many steps (``None``: unbounded).

    Raises:
        TypeError, ValueError: as :class:`ActionDelay`, and for an unknown autoreset mode.
    """

    def __init__(
        self,
        env: VectorEnv,
        delay: Delay | float,
        initial_action: Any = None,
        max_delay: int | None = None,
    ):
        gym.utils.RecordConstructorArgs.__init__(
            self, delay=delay_spec(delay), initial_action=initial_action, max_delay=max_delay
        )
        gym.vector.VectorWrapper.__init__(self, env)
        self.delay = as_delay(delay)
        self.max_delay = check_max_delay(max_delay)
        space = env.single_action_space
        if initial_action is None:
            initial_action = neutral_action(space)
        self.initial_action = _check_action(space, initial_action, "initial_action")
        self.autoreset_mode = autoreset_mode(env)
        self.lines = [ActionLine(self.initial_action) for _ in range(self.num_envs)]
        self._samplers = [DelaySampler(self.delay, self.max_delay) for _ in range(self.num_envs)]
        self._resetting = np.zeros(self.num_envs, dtype=bool)

    def reset(self, *, seed: int | list[int] | None = None, options: dict[str, Any] | None = None):
        """Reset all sub-envs, or those in ``options["reset_mask"]``, and their lines.

        Raises:
            TypeError, ValueError: ``seed`` is not ``None``, an integer ``>= 0`` or a list of
                ``num_envs`` of them (or ``None``).
        """
        seeds = sub_env_seeds(seed, self.num_envs)
        envs = reset_mask(options, self.num_envs)
        obs, info = self.env.reset(seed=seed, options=options)
        for i in np.flatnonzero(envs):
            if seeds[i] is not None:
                self._samplers[i].seed(seeds[i])
            self.lines[i].reset()
        self._resetting[envs] = False
        return obs, info

    def step(self, actions):
        """Send each sub-env's action; step them with the actions executed now."""
        space = self.single_action_space
        executed = np.array(actions, copy=True)
        sent_steps = np.full(self.num_envs, -1, dtype=np.int64)
        delays = np.zeros(self.num_envs, dtype=np.int64)
        sending = ~self._resetting
        for i in np.flatnonzero(sending):
            action = _check_action(space, actions[i], f"actions[{i}]")
            delays[i] = self._samplers[i]()
            executed[i] = self.lines[i].send(action, int(delays[i]))
            sent_steps[i] = self.lines[i].executed_step
        obs, rewards, terminated, truncated, info = self.env.step(executed)
        ended = np.asarray(terminated) | np.asarray(truncated)
        if self.autoreset_mode == AutoresetMode.NEXT_STEP:
            self._resetting = ended & sending
            for i in np.flatnonzero(~sending):  # this was the reset step: a new episode
                self.lines[i].reset()
        elif self.autoreset_mode == AutoresetMode.SAME_STEP:
            for i in np.flatnonzero(ended):
                self.lines[i].reset()
        for key, values in (
            ("executed_action", executed),
            ("executed_action_step", sent_steps),
            ("action_delay", delays),
        ):
            info[key], info["_" + key] = values, sending.copy()
        return obs, rewards, terminated, truncated, info
