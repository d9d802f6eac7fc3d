"""The ``gymnasium.vector`` twin of :class:`~delayed_rl.wrappers.DelayAwareObservation`."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space, concatenate, create_empty_array, iterate

from delayed_rl._validation import check_int
from delayed_rl.wrappers._samples import as_action, copy_sample
from delayed_rl.wrappers._spec import record_arguments
from delayed_rl.wrappers.delay_aware import (
    MAX_ACTION_HISTORY,
    ViewState,
    _the_wrapper,
    view_settings,
)
from delayed_rl.wrappers.vector._sub_envs import autoreset_mode, reset_mask, unbatch_actions
from delayed_rl.wrappers.vector.action_delay import VectorActionDelay
from delayed_rl.wrappers.vector.observation_delay import VectorObservationDelay


class VectorDelayAwareObservation(gym.vector.VectorWrapper, gym.utils.RecordConstructorArgs):
    """Observe, for each sub-env of a vector stack, the view of :class:`~delayed_rl.wrappers.DelayAwareObservation`.

    ``env`` is a vector stack holding a :class:`~delayed_rl.wrappers.VectorObservationDelay`, a
    :class:`~delayed_rl.wrappers.VectorActionDelay`, both or neither (at most one of each; wrap
    outside them). Each sub-env has its own view, built from what the stack reports for it and
    the actions it is given, so sub-env ``i`` observes exactly what a
    :class:`~delayed_rl.wrappers.DelayAwareObservation` over the same sub-env and delays, reset
    with the seed the stack gives it, would. ``observation_space`` is the batch of the single
    view's ``Dict`` (a ``Dict`` of batches). A sub-env's view restarts with its episode, under
    each autoreset mode. Everything handed out is a copy; the wrapper draws nothing:
    ``reset(seed=...)`` seeds the stack. The rules in full: the late-observations page of the
    docs.

    ``info`` holds, with Gymnasium's ``_key`` masks, ``arrived_observations`` (an object array
    of each sub-env's ``(i, o_i)`` received at this step) and ``age_clipped`` (a ``bool``
    array); under ``SAME_STEP``, the ending step's are in ``info["final_info"]``.

    Args:
        env: the vector stack to observe.
        action_history: as :class:`~delayed_rl.wrappers.DelayAwareObservation`'s.

    Raises:
        TypeError, ValueError: as :class:`~delayed_rl.wrappers.DelayAwareObservation` (the stack
            holding two ``VectorObservationDelay`` or ``VectorActionDelay`` wrappers), and
            ``ValueError`` for an env whose ``metadata["autoreset_mode"]`` is not a
            ``gymnasium.vector.AutoresetMode``, or at ``reset()`` or ``step()`` for a stack whose
            sub-envs hold an ``ObservationDelay`` or ``ActionDelay`` of their own (wrap each
            sub-env with :class:`~delayed_rl.wrappers.DelayAwareObservation` instead).

    Example:
        >>> import gymnasium as gym
        >>> from delayed_rl.delays import Constant, Uniform
        >>> from delayed_rl.wrappers import VectorActionDelay, VectorObservationDelay
        >>> envs = gym.make_vec("CartPole-v1", num_envs=2, vectorization_mode="sync")
        >>> envs = VectorObservationDelay(VectorActionDelay(envs, Uniform(0, 1)), Constant(2))
        >>> envs = VectorDelayAwareObservation(envs)
        >>> envs.single_observation_space["age"], envs.single_observation_space["actions"]
        (Discrete(3), MultiDiscrete([2 2 2]))
        >>> views, info = envs.reset(seed=0)
        >>> views, rewards, terminated, truncated, info = envs.step(np.array([1, 0]))
        >>> views["age"].tolist(), views["actions"].tolist()
        ([1, 1], [[1, 0, 0], [0, 0, 0]])
    """

    def __init__(self, env: VectorEnv, action_history: int | None = None):
        record_arguments(self, action_history=action_history)
        gym.vector.VectorWrapper.__init__(self, env)
        action_history = check_int(
            "action_history", action_history, 1, MAX_ACTION_HISTORY, optional=True
        )
        owner = type(self).__name__
        self._observation_delay = _the_wrapper(env, VectorObservationDelay, owner)
        self._action_delay = _the_wrapper(env, VectorActionDelay, owner)
        self.action_history, self.max_age, self.initial_action, self.single_observation_space = (
            view_settings(
                env.single_observation_space,
                env.single_action_space,
                self._observation_delay,
                self._action_delay,
                action_history,
                owner,
            )
        )
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.autoreset_mode = autoreset_mode(env)
        actions_space = self.single_observation_space["actions"]
        self.states = [
            ViewState(actions_space, copy_sample(self.initial_action), self.max_age)
            for _ in range(self.num_envs)
        ]
        self._resetting = np.zeros(self.num_envs, dtype=bool)

    def reset(self, *, seed: int | list[int] | None = None, options: dict[str, Any] | None = None):
        """Reset the stack (``seed`` seeds it) and the views: ``o_0``, age 0, the initial actions.

        All sub-envs' views are reset, or those in ``options["reset_mask"]``.
        """
        envs = reset_mask(options, self.num_envs)
        obs, info = self.env.reset(seed=seed, options=options)
        self._check_visible(info, "observation_age")
        rows = list(iterate(self.env.observation_space, obs))
        entries = self._entries()
        for i in np.flatnonzero(envs).tolist():
            self._put(entries, i, self.states[i].reset(rows[i], self._delayed(info, i)[1]))
        self._resetting[envs] = False
        self._report(info, entries, envs)
        return self._views(), info

    def step(self, actions):
        """Send each sub-env's action through the stack; observe the views (see the class docstring).

        Raises:
            TypeError: ``actions`` is not a batch of the action space's form.
            ValueError: it does not hold one action per sub-env, or a sub-env's action is not
                in the single action space (the message names ``actions[i]``).
        """
        space = self.single_action_space
        given = unbatch_actions(self, actions)
        sent = [
            None if self._resetting[i] else as_action(space, given[i], f"actions[{i}]")
            for i in range(self.num_envs)
        ]
        obs, rewards, terminated, truncated, info = self.env.step(actions)
        self._check_visible(info, "executed_action")
        rows = list(iterate(self.env.observation_space, obs))
        ended = np.asarray(terminated) | np.asarray(truncated)
        same_step = self.autoreset_mode == AutoresetMode.SAME_STEP
        entries, final_entries = self._entries(), self._entries()
        final_obs = info["final_obs"].copy() if same_step and ended.any() else None
        for i, state in enumerate(self.states):
            if self._resetting[i]:  # NEXT_STEP's reset step: the new episode's o_0
                self._put(entries, i, state.reset(rows[i], self._delayed(info, i)[1]))
            elif same_step and ended[i]:  # the last step, then the next episode's o_0
                last = info["final_obs"][i]
                self._put(
                    final_entries,
                    i,
                    state.step(sent[i], last, *self._delayed(info["final_info"], i)),
                )
                final_obs[i] = state.view()
                self._put(entries, i, state.reset(rows[i], self._delayed(info, i)[1]))
            else:
                self._put(entries, i, state.step(sent[i], rows[i], *self._delayed(info, i)))
        if self.autoreset_mode == AutoresetMode.NEXT_STEP:
            self._resetting = ended & ~self._resetting
        if final_obs is not None:
            info["final_obs"] = final_obs
            self._report(info.setdefault("final_info", {}), final_entries, ended)
            info["_final_info"] = np.asarray(info.get("_final_info", ended)) | ended
        self._report(info, entries, np.ones(self.num_envs, dtype=bool))
        return self._views(), rewards, terminated, truncated, info

    def _delayed(self, info: dict[str, Any], i: int) -> tuple[int, Any]:
        """Sub-env ``i``'s observation age and observations arrived, from the stack's ``info``.

        ``(0, None)`` without a ``VectorObservationDelay``.
        """
        if self._observation_delay is None:
            return 0, None
        return int(info["observation_age"][i]), info["arrived_observations"][i]

    def _check_visible(self, info: dict[str, Any], key: str) -> None:
        """Refuse a stack whose sub-envs delay by themselves (``info[key]`` and no vector twin).

        Raises:
            ValueError: ``info`` holds ``key`` (``"observation_age"`` or
                ``"executed_action"``) but the stack holds no vector wrapper that reports it.
        """
        kind = "ObservationDelay" if key == "observation_age" else "ActionDelay"
        wrapper = self._observation_delay if key == "observation_age" else self._action_delay
        if wrapper is None and key in info:
            raise ValueError(
                f"env reports info[{key!r}] but holds no Vector{kind}: its sub-envs hold an "
                f"{kind}, which {type(self).__name__} cannot read (it reads the vector "
                f"wrappers only); wrap the vector env with Vector{kind} instead, or each "
                "sub-env with DelayAwareObservation"
            )

    def _entries(self) -> dict[str, np.ndarray]:
        """Empty ``arrived_observations`` and ``age_clipped`` arrays, one entry per sub-env."""
        return {
            "arrived_observations": np.full(self.num_envs, None, dtype=object),
            "age_clipped": np.zeros(self.num_envs, dtype=bool),
        }

    @staticmethod
    def _put(entries: dict[str, np.ndarray], i: int, values: dict[str, Any]) -> None:
        """Write one sub-env's ``info`` entries (a :class:`~delayed_rl.wrappers.delay_aware.ViewState`'s) at index ``i``."""
        for key, value in values.items():
            entries[key][i] = value

    @staticmethod
    def _report(info: dict[str, Any], entries: dict[str, np.ndarray], mask: np.ndarray) -> None:
        """Store ``entries`` in ``info``, each with its Gymnasium ``_key`` mask."""
        for key, values in entries.items():
            info[key], info["_" + key] = values, mask.copy()

    def _views(self) -> dict[str, Any]:
        """The batch of the sub-envs' views (new arrays, from the views' copies)."""
        space = self.single_observation_space
        views = [state.view() for state in self.states]
        return concatenate(space, views, create_empty_array(space, self.num_envs))
