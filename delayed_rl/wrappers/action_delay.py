"""Action delay: the env executes an action sent a random number of steps earlier.

The third delay of the general delayed MDP (state, action and reward delays): the agent's
command travels to the actuator through a link that takes ``d_t`` steps, ``d_t`` drawn from a
:mod:`delayed_rl.delays` distribution. :class:`ActionDelay` wraps one env;
:class:`VectorActionDelay` is its ``gymnasium.vector`` twin. Both use :class:`ActionLine`, the
rule itself.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from delayed_rl.delays import Delay, as_delay
from delayed_rl.wrappers._delay_draws import DelaySampler, check_max_delay
from delayed_rl.wrappers._in_transit import InTransit
from delayed_rl.wrappers._samples import as_action, copy_sample
from delayed_rl.wrappers._spec import JsonSpecMixin, record_arguments

__all__ = ["ActionDelay", "ActionLine", "neutral_action", "checked_action"]


def neutral_action(space: gym.Space) -> Any:
    """The action executed before any sent action has arrived, when none is given.

    ``Discrete``: its first action (``start``, usually 0); ``Box``: zeros, clipped into the box;
    ``MultiDiscrete``: each entry's first value (``start``); ``MultiBinary``: zeros; ``Dict``
    and ``Tuple``: the neutral action of each of their spaces (a dict in the space's key order,
    a tuple), recursively.

    Raises:
        ValueError: any other space, or a ``Dict`` or ``Tuple`` holding one (give
            ``initial_action``).
    """
    if isinstance(space, spaces.Discrete):
        return space.dtype.type(space.start)
    if isinstance(space, spaces.Box):
        return np.clip(np.zeros(space.shape, space.dtype), space.low, space.high)
    if isinstance(space, spaces.MultiDiscrete):
        return np.array(space.start, dtype=space.dtype)
    if isinstance(space, spaces.MultiBinary):
        return np.zeros(space.shape, dtype=space.dtype)
    if isinstance(space, spaces.Dict):
        return {key: neutral_action(sub) for key, sub in space.spaces.items()}
    if isinstance(space, spaces.Tuple):
        return tuple(neutral_action(sub) for sub in space.spaces)
    raise ValueError(
        f"initial_action must be given for an action space of type {type(space).__name__} "
        f"({space}): there is no neutral action to default to"
    )


def checked_action(space: gym.Space, action: Any, name: str) -> Any:
    """A copy of ``action`` (:func:`copy_sample`), checked to be in ``space``.

    The copy is what the line keeps: the caller may reuse or modify its own object.

    Raises:
        ValueError: ``action`` is not in ``space``.
    """
    # the common case, quickly: an int in a Discrete's range (what Discrete.contains tests;
    # an int is immutable, so there is nothing to copy)
    if (
        type(action) is int
        and type(space) is spaces.Discrete
        and space.start <= action < space.start + space.n
    ):
        return action
    action = copy_sample(action)
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
    is in flight, not the delay's bound. The line keeps the very objects it is given and
    returns them: :class:`ActionDelay` and :class:`VectorActionDelay` give it copies and hand
    out copies of what it returns, so that nobody else holds its objects.

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
        self._in_transit = InTransit()
        self._step = 0
        self.executed: Any = self.initial_action
        self.executed_step = -1  # the step that sent it (-1: the initial action)

    @property
    def in_transit(self) -> int:
        """How many sent actions have not arrived yet."""
        return len(self._in_transit)

    def remaining(self) -> list[tuple[int, Any]]:
        """The actions sent that have not arrived yet, as ``(sent step, action)`` by sent step.

        They stay in transit (the line's own objects: copy them before handing them out).
        """
        return self._in_transit.remaining()

    def send(self, action: Any, delay: int) -> Any:
        """Send this step's ``action`` with ``delay`` steps of transit; return the one executed.

        :attr:`executed_step` is then the step that sent it (``-1``: the initial action).
        """
        step = self._step
        self._step = step + 1
        if delay == 0 and not self._in_transit:  # the common undelayed case, no heap
            self.executed, self.executed_step = action, step
            return action
        self._in_transit.send(step, action, delay)
        arrived = self._in_transit.arrived(step)
        if arrived and arrived[-1][0] > self.executed_step:  # the latest sent of them
            self.executed_step, self.executed = arrived[-1]
        return self.executed


class ActionDelay(JsonSpecMixin, gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Executes, at step ``t``, the action sent ``d_t`` steps earlier, ``d_t`` drawn from ``delay``.

    The action sent at step ``t`` arrives at step ``t + d_t`` (:class:`ActionLine` states the
    rule); the env executes, at each step, the latest-sent action that has arrived (one
    overtaken in transit by a later-sent one is never executed), and ``initial_action`` before
    the episode's first action arrives. ``Constant(k)`` is the classic constant-delay MDP.
    Every action sent is checked against the action space (any space, nested ``Dict`` and
    ``Tuple`` included), and actions are copied where they enter and where they leave.
    ``reset(seed=...)`` seeds the delays, from a stream of their own. ``docs/semantics.md`` has
    the rules in full: the copies, the initial action's forms, what a reset discards.

    ``info`` adds ``executed_action`` (the action the env executed), ``executed_action_step``
    (the episode step that sent it, ``-1`` for ``initial_action``) and ``drawn_action_delay``
    (``d_t``, the transit time drawn for this step's action).

    Args:
        env: the env whose actions to delay.
        delay: a :class:`~delayed_rl.delays.Delay`, its ``to_dict()`` description, or a number
            read as a Poisson mean.
        initial_action: executed until the episode's first action arrives, anything the
            space's ``contains`` accepts; ``None``: the space's neutral action
            (:func:`neutral_action`: 0 for ``Discrete``, zeros for ``Box``).
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
        record_arguments(self, delay=delay, initial_action=initial_action, max_delay=max_delay)
        gym.Wrapper.__init__(self, env)
        self.delay = as_delay(delay)
        self.max_delay = check_max_delay(max_delay)
        if initial_action is None:
            initial_action = neutral_action(env.action_space)
        self.initial_action = as_action(env.action_space, initial_action, "initial_action")
        self._sampler = DelaySampler(self.delay, self.max_delay, "action")
        self.line = ActionLine(copy_sample(self.initial_action))

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Reset the env and the line (actions in transit are discarded); ``seed`` reseeds it."""
        obs, info = self.env.reset(seed=seed, options=options)
        if seed is not None:
            self._sampler.seed(seed)
        self.line.reset()
        return obs, info

    def step(self, action):
        """Send ``action``; step the env with the action executed now (see the class docstring)."""
        action = checked_action(self.action_space, action, "action")
        delay = self._sampler()
        executed = self.line.send(action, delay)
        obs, reward, terminated, truncated, info = self.env.step(copy_sample(executed))
        info["executed_action"] = copy_sample(executed)
        info["executed_action_step"] = self.line.executed_step
        info["drawn_action_delay"] = delay
        return obs, reward, terminated, truncated, info
