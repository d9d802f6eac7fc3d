"""The delay-aware observation: what the agent can know at step ``t``, and nothing more.

Under observation and action delays the newest observation is not the state, and the actions
still on their way will change it. The classic remedy (the augmented state of the constant-delay
MDP; rlrd's RTRL and DCAC, Bouteiller et al., ICLR 2021) observes the newest observation received,
its age and the actions sent since it was made. :class:`DelayAwareObservation` builds that view
over a stack of the library's delay wrappers, and :class:`VectorDelayAwareObservation`, its
``gymnasium.vector`` twin, over a stack of their vector twins; both follow :class:`ViewState`,
the rule itself. :class:`DiscreteDelayAwareObservation` numbers the view with one ``Discrete``
index, for the tabular agents.
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import VectorEnv

from delayed_rl._validation import check_int
from delayed_rl.wrappers._samples import as_action, copy_sample
from delayed_rl.wrappers._spec import JsonSpecMixin, record_arguments
from delayed_rl.wrappers.action_delay import ActionDelay, neutral_action
from delayed_rl.wrappers.discrete_observation import DiscreteObservation
from delayed_rl.wrappers.observation_delay import ObservationDelay

__all__ = [
    "MAX_ACTION_HISTORY",
    "MAX_DISCRETE_STATES",
    "DelayAwareObservation",
    "DiscreteDelayAwareObservation",
    "ViewState",
    "view_settings",
]

MAX_ACTION_HISTORY = 2**16
"""The most actions :class:`DelayAwareObservation` keeps (its ``K``): a bound beyond it is refused
rather than allocated (a delay of ``Uniform(0, 10**9)`` would ask for 10⁹ actions a step)."""

MAX_DISCRETE_STATES = 2**24
"""The most states :class:`DiscreteDelayAwareObservation` numbers (16 777 216): a Q-table of that
many states and a few actions already takes hundreds of megabytes."""

VIEW_KEYS = ("actions", "age", "observation")
"""The keys of the view's ``Dict`` (Gymnasium orders a ``Dict``'s keys alphabetically)."""


def _the_wrapper(env: gym.Env | VectorEnv, cls: type, owner: str) -> Any:
    """The one ``cls`` among ``env``'s wrappers (walking ``.env`` down), or ``None``.

    ``env`` is an env (its ``gym.Wrapper`` layers are walked) or a vector env (its
    ``gym.vector.VectorWrapper`` layers); ``owner`` names the view, for the message.

    Raises:
        ValueError: the stack holds more than one.
    """
    layer = gym.vector.VectorWrapper if isinstance(env, VectorEnv) else gym.Wrapper
    found = []
    while isinstance(env, layer):
        if isinstance(env, cls):
            found.append(env)
        env = env.env
    if len(found) > 1:
        raise ValueError(
            f"env must hold at most one {cls.__name__} for {owner} to read its delays, "
            f"got {len(found)}: {found!r}"
        )
    return found[0] if found else None


def _bound(wrapper: Any) -> int | None:
    """The longest delay ``wrapper`` applies: 0 without one, ``None`` if unbounded.

    ``wrapper`` is an observation or action delay, of one env or a vector env. The bound is the
    smaller of its ``max_delay`` and its distribution's ``support_max``, whichever are set.
    """
    if wrapper is None:
        return 0
    bounds = [b for b in (wrapper.max_delay, wrapper.delay.support_max) if b is not None]
    return min(bounds) if bounds else None


def _history_space(space: gym.Space, k: int, owner: str) -> spaces.Space:
    """The space of ``k`` actions of ``space``, stacked along a new first axis.

    Raises:
        TypeError: ``space`` is not ``Discrete``, ``Box``, ``MultiDiscrete`` or ``MultiBinary``.
    """
    if isinstance(space, spaces.Discrete):
        return spaces.MultiDiscrete(np.full(k, space.n), start=np.full(k, space.start))
    if isinstance(space, spaces.Box):
        low, high = (np.repeat(bound[np.newaxis], k, axis=0) for bound in (space.low, space.high))
        return spaces.Box(low, high, dtype=space.dtype)
    if isinstance(space, spaces.MultiDiscrete):
        nvec, start = (np.repeat(a[np.newaxis], k, axis=0) for a in (space.nvec, space.start))
        return spaces.MultiDiscrete(nvec, start=start, dtype=space.dtype)
    if isinstance(space, spaces.MultiBinary):
        return spaces.MultiBinary([k, *space.shape])
    raise TypeError(
        f"{owner} needs an env whose action_space is Discrete, Box, MultiDiscrete "
        f"or MultiBinary (to stack the actions sent), got {space!r}"
    )


def _bounded_history(
    observation_delay: Any,
    action_delay: Any,
    observation_bound: int | None,
    action_bound: int | None,
    owner: str,
) -> int:
    """``K`` from the delays' bounds: their sum, at least 1 (``owner`` names the view).

    Raises:
        ValueError: a delay is unbounded, or the sum is above :data:`MAX_ACTION_HISTORY`.
    """
    for wrapper, bound in ((observation_delay, observation_bound), (action_delay, action_bound)):
        if bound is None:
            raise ValueError(
                f"{owner} needs action_history (an integer >= 1) for the "
                f"{type(wrapper).__name__} of unbounded delay {wrapper.delay!r} (no "
                "max_delay): the number of actions to observe cannot be read from it"
            )
    total = max(observation_bound + action_bound, 1)
    if total > MAX_ACTION_HISTORY:
        raise ValueError(
            f"{owner} would observe {total} actions (the observation delay's "
            f"bound {observation_bound} plus the action delay's {action_bound}), more than "
            f"MAX_ACTION_HISTORY = {MAX_ACTION_HISTORY}: give action_history, or max_delay "
            "to the delay wrappers"
        )
    return total


def view_settings(
    observation_space: gym.Space,
    action_space: gym.Space,
    observation_delay: Any,
    action_delay: Any,
    action_history: int | None,
    owner: str,
) -> tuple[int, int, Any, spaces.Dict]:
    """``K``, ``D``, the initial action and the view's ``Dict`` space, for one env of a stack.

    ``observation_space`` and ``action_space`` are one env's (a vector env's single spaces);
    ``observation_delay`` and ``action_delay`` the stack's delay wrappers (``None``: none);
    ``action_history`` the checked argument; ``owner`` names the view, for the messages.
    :class:`DelayAwareObservation` says how each is chosen; its vector twin reads them here too.

    Raises:
        TypeError, ValueError: as :class:`DelayAwareObservation`.
    """
    observation_bound = _bound(observation_delay)
    action_bound = _bound(action_delay)
    if action_history is None:
        action_history = _bounded_history(
            observation_delay, action_delay, observation_bound, action_bound, owner
        )
    max_age = action_history if observation_bound is None else observation_bound
    initial = neutral_action(action_space) if action_delay is None else action_delay.initial_action
    actions_space = _history_space(action_space, action_history, owner)  # checks the space
    view_space = spaces.Dict(
        {
            "observation": observation_space,
            "age": spaces.Discrete(max_age + 1),
            "actions": actions_space,
        }
    )
    return action_history, max_age, as_action(action_space, initial, "initial_action"), view_space


class ViewState:
    """One env's delay-aware view, step by step: the rule of :class:`DelayAwareObservation`.

    It keeps the last ``K`` actions sent (newest first), the newest observation received with the
    index ``i`` of the step that made it, and the episode's step count, and builds the view from
    what the stack reports: each step's observation with its age, and the observations received.
    :class:`DelayAwareObservation` holds one; :class:`VectorDelayAwareObservation` one per sub-env.

    What it is given is copied where it keeps it (the newest observation, the actions written into
    its rows), and what it hands out is new: :meth:`view` copies, and the ``info`` entries that
    :meth:`reset` and :meth:`step` return are built from copies.

    Args:
        actions_space: the space of the ``actions`` rows (the view's ``"actions"`` space).
        initial_action: what the rows hold before the episode's first action is sent.
        max_age: ``D``, the ages' bound: an older age is shown as ``D``, and reported clipped.
    """

    def __init__(self, actions_space: spaces.Space, initial_action: Any, max_age: int):
        self.initial_action = initial_action
        self.max_age = max_age
        self.actions = np.empty(actions_space.shape, dtype=actions_space.dtype)
        self.actions[...] = initial_action
        self.newest: Any = None
        self.newest_index = 0
        self.steps = 0
        self.age = 0

    def reset(self, first: Any, arrived: Any = None) -> dict[str, Any]:
        """Start an episode at ``first`` (``o_0``, age 0), the rows all the initial action.

        Args:
            first: the episode's first observation.
            arrived: the stack's ``info["arrived_observations"]``; ``None`` without an
                observation delay.

        Returns:
            The ``info`` entries ``arrived_observations`` and ``age_clipped``.
        """
        self.steps = 0
        self.newest, self.newest_index = copy_sample(first), 0
        self.actions[...] = self.initial_action
        self.age = 0
        return self._report(first, arrived)

    def step(self, sent: Any, obs: Any, shown_age: int, arrived: Any = None) -> dict[str, Any]:
        """Record the action ``sent`` and the stack's observation ``obs`` of age ``shown_age``.

        ``obs`` was made at ``i = t + 1 − shown_age`` (``t`` this step, counted from 0), and it
        becomes the newest observation only if ``i`` is larger than the newest's.

        Args:
            sent: the action sent at this step, in the action space's form.
            obs: the observation the stack returned.
            shown_age: its ``info["observation_age"]`` (0 without an observation delay).
            arrived: the stack's ``info["arrived_observations"]``; ``None`` without an
                observation delay.

        Returns:
            The ``info`` entries ``arrived_observations`` and ``age_clipped``.
        """
        self.steps += 1
        self.actions[1:] = self.actions[:-1]
        self.actions[0] = sent
        made = self.steps - shown_age
        if made > self.newest_index:
            self.newest, self.newest_index = copy_sample(obs), made
        self.age = self.steps - self.newest_index
        return self._report(obs, arrived)

    def view(self) -> dict[str, Any]:
        """The view's ``Dict`` sample: copies of the rows and of the newest observation."""
        return {
            "actions": self.actions.copy(),
            "age": np.int64(min(self.age, self.max_age)),
            "observation": copy_sample(self.newest),
        }

    def _report(self, obs: Any, arrived: Any) -> dict[str, Any]:
        """This step's ``arrived_observations`` (copies) and ``age_clipped``."""
        received = ((self.steps, copy_sample(obs)),) if arrived is None else copy_sample(arrived)
        return {"arrived_observations": received, "age_clipped": self.age > self.max_age}


class DelayAwareObservation(JsonSpecMixin, gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Observe what the agent can know: the newest observation received, its age, the actions sent.

    ``env`` is a stack holding an :class:`~delayed_rl.wrappers.ObservationDelay`, an
    :class:`~delayed_rl.wrappers.ActionDelay`, both or neither (at most one of each; wrap outside
    them and inside a reward delay, as :func:`~delayed_rl.wrappers.wrap_delays` does). The view
    is built only from what the stack reports to the agent, never from the undelayed state. It
    is a ``Dict``: ``"observation"``, the newest observation received so far (by the step it
    was made at); ``"age"``, the steps since it was made, in ``Discrete(D + 1)``, ``D`` the
    observation delay's bound; ``"actions"``, the last ``K`` actions sent, newest first. ``K``,
    at least 1, is the observation delay's bound plus the action delay's: the actions that can
    have changed the state since the observation was made. An unbounded delay needs
    ``action_history``. Everything handed out is a copy; the wrapper draws nothing:
    ``reset(seed=...)`` seeds the stack. The rules in full, the vector twins and the policies
    that read the view: the late-observations page of the docs.

    ``info`` holds ``arrived_observations``, the ``(i, o_i)`` pairs received at this step (the
    observation delay's own entry, or the step's observation when the stack delays none), and
    ``age_clipped``, whether the age was clipped to ``D`` (an unbounded observation delay).

    Args:
        env: the stack to observe.
        action_history: ``K``, the number of actions observed, when given (an integer in
            ``1..MAX_ACTION_HISTORY``), and ``D``, the ages' bound, for an unbounded observation
            delay; ``None``: from the delays' bounds (see above).

    Raises:
        TypeError: ``action_history`` is not an integer, or the action space is not
            ``Discrete``, ``Box``, ``MultiDiscrete`` or ``MultiBinary``.
        ValueError: ``action_history`` is outside ``1..MAX_ACTION_HISTORY``; it is ``None`` and a
            delay is unbounded, or the bounds add up to more than :data:`MAX_ACTION_HISTORY`;
            the stack holds two ``ObservationDelay`` (or ``ActionDelay``) wrappers.

    Example:
        >>> import gymnasium as gym
        >>> from delayed_rl.delays import Constant, Uniform
        >>> from delayed_rl.wrappers import wrap_delays
        >>> stack = wrap_delays(
        ...     gym.make("CartPole-v1"),
        ...     observation_delay=Constant(2),
        ...     observation_arrival="network",
        ...     action_delay=Uniform(0, 1),
        ... )
        >>> env = DelayAwareObservation(stack)
        >>> env.observation_space["age"], env.observation_space["actions"]
        (Discrete(3), MultiDiscrete([2 2 2]))
        >>> view, info = env.reset(seed=0)
        >>> view, reward, terminated, truncated, info = env.step(1)
        >>> int(view["age"]), view["actions"].tolist(), info["arrived_observations"]
        (1, [1, 0, 0], ())
    """

    def __init__(self, env: gym.Env, action_history: int | None = None):
        record_arguments(self, action_history=action_history)
        gym.Wrapper.__init__(self, env)
        action_history = check_int(
            "action_history", action_history, 1, MAX_ACTION_HISTORY, optional=True
        )
        owner = type(self).__name__
        self._observation_delay = _the_wrapper(env, ObservationDelay, owner)
        self._action_delay = _the_wrapper(env, ActionDelay, owner)
        self.action_history, self.max_age, self.initial_action, self.observation_space = (
            view_settings(
                env.observation_space,
                env.action_space,
                self._observation_delay,
                self._action_delay,
                action_history,
                owner,
            )
        )
        self._state = ViewState(
            self.observation_space["actions"], self.initial_action, self.max_age
        )

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Reset the stack (``seed`` seeds it) and the view: ``o_0``, age 0, the initial actions."""
        obs, info = self.env.reset(seed=seed, options=options)
        info.update(self._state.reset(obs, self._delayed(info)[1]))
        return self._state.view(), info

    def step(self, action):
        """Send ``action`` through the stack; observe the view (see the class docstring).

        Raises:
            ValueError: ``action`` is not in the action space.
        """
        sent = as_action(self.action_space, action, "action")
        obs, reward, terminated, truncated, info = self.env.step(action)
        info.update(self._state.step(sent, obs, *self._delayed(info)))
        return self._state.view(), reward, terminated, truncated, info

    def _delayed(self, info: dict[str, Any]) -> tuple[int, Any]:
        """The observation's age and the observations arrived, from the stack's ``info``.

        ``(0, None)`` without an ``ObservationDelay``.
        """
        if self._observation_delay is None:
            return 0, None
        return info["observation_age"], info["arrived_observations"]


class DiscreteDelayAwareObservation(JsonSpecMixin, DiscreteObservation):
    """Observe a :class:`DelayAwareObservation`'s view as one ``Discrete`` index, for tabular agents.

    ``env``'s observation is the view's ``Dict`` (a :class:`DelayAwareObservation`, possibly
    below other wrappers that leave observations alone: a reward delay, a time limit) over a
    ``Discrete(n)`` observation space and a ``Discrete(m)`` action space (or ``MultiDiscrete`` or
    ``MultiBinary``, read entry by entry). Every combination of the view's parts gets an index,
    numbered as :class:`~delayed_rl.wrappers.DiscreteObservation` numbers the parts
    ``(observation, age, action_1, ..., action_K)``, in that order (the observation most
    significant, the oldest action least). That takes

        ``n · (D + 1) · m^K``

    states (``D`` the age bound, ``K`` the actions observed; ``m^K`` is the product of the
    actions' sizes for a ``MultiDiscrete``, ``2^(K · entries)`` for a ``MultiBinary``), which
    must be at most :data:`MAX_DISCRETE_STATES` = 2**24. :meth:`decode` maps an index back to the
    view's ``Dict``. Rewards, ends and ``info`` pass through unchanged (it adds no ``info`` key;
    the view's own keys are :class:`DelayAwareObservation`'s).

    Args:
        env: an env whose observation is a :class:`DelayAwareObservation`'s view.

    Raises:
        TypeError: ``env``'s observation space is not such a view, of a ``Discrete`` observation
            and ``MultiDiscrete`` or ``MultiBinary`` actions.
        ValueError: the view has more than :data:`MAX_DISCRETE_STATES` combinations (the message
            gives the count).

    Example:
        >>> import gymnasium as gym
        >>> from delayed_rl.delays import Constant
        >>> from delayed_rl.wrappers import wrap_delays
        >>> stack = wrap_delays(
        ...     gym.make("FrozenLake-v1"), observation_delay=Constant(1), delay_aware=True
        ... )
        >>> env = DiscreteDelayAwareObservation(stack)
        >>> env.observation_space  # 16 observations, ages 0..1, 4 actions for each of K = 1
        Discrete(128)
        >>> index, _ = env.reset(seed=0)
        >>> env.decode(env.step(2)[0])["actions"].tolist()
        [2]
    """

    def __init__(self, env: gym.Env):
        gym.utils.RecordConstructorArgs.__init__(self)
        gym.ObservationWrapper.__init__(self, env)
        view = env.observation_space
        if (
            not isinstance(view, spaces.Dict)
            or tuple(view.spaces) != VIEW_KEYS
            or not isinstance(view["observation"], spaces.Discrete)
            or not isinstance(view["actions"], spaces.MultiDiscrete | spaces.MultiBinary)
        ):
            raise TypeError(
                "DiscreteDelayAwareObservation needs an env whose observation_space is a "
                "DelayAwareObservation's Dict of a Discrete observation and MultiDiscrete or "
                f"MultiBinary actions, got {view!r}"
            )
        self._actions_space = actions = view["actions"]
        if isinstance(actions, spaces.MultiDiscrete):
            action_sizes, action_starts = (
                actions.nvec.ravel().tolist(),
                actions.start.ravel().tolist(),
            )
        else:  # MultiBinary: 0 or 1 in every entry
            action_sizes, action_starts = (
                [2] * math.prod(actions.shape),
                [0] * math.prod(actions.shape),
            )
        self.sizes = [int(view["observation"].n), int(view["age"].n), *action_sizes]
        self.starts = [int(view["observation"].start), int(view["age"].start), *action_starts]
        states = math.prod(self.sizes)
        if states > MAX_DISCRETE_STATES:
            raise ValueError(
                f"DiscreteDelayAwareObservation would number {states} states (n · (D + 1) · m^K "
                f"for {view!r}), more than MAX_DISCRETE_STATES = {MAX_DISCRETE_STATES}: observe "
                "fewer actions (action_history) or bound the delays more tightly"
            )
        self.strides = [math.prod(self.sizes[i + 1 :]) for i in range(len(self.sizes))]
        self.observation_space = spaces.Discrete(states)

    def observation(self, observation: dict[str, Any]) -> int:
        """The index of the view ``observation`` (see the class docstring)."""
        parts = [observation["observation"], observation["age"], *np.ravel(observation["actions"])]
        return super().observation(parts)

    def decode(self, index: Any) -> dict[str, Any]:
        """The view numbered ``index`` (the inverse of :meth:`observation`).

        Raises:
            TypeError: ``index`` is not an integer.
            ValueError: it is outside ``0 .. observation_space.n − 1``.
        """
        observation, age, *actions = super().decode(index)
        space = self._actions_space
        return {
            "actions": np.array(actions, dtype=space.dtype).reshape(space.shape),
            "age": np.int64(age),
            "observation": np.int64(observation),
        }
