"""The ``gymnasium.vector`` twin of :class:`~delayed_rl.wrappers.DelayAwareObservation`."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space, concatenate, create_empty_array, iterate

from delayed_rl._validation import check_int
from delayed_rl.wrappers._samples import as_action, copy_sample
from delayed_rl.wrappers._spec import json_safe
from delayed_rl.wrappers.delay_aware import (
    MAX_ACTION_HISTORY,
    ViewState,
    _the_wrapper,
    _view_settings,
)
from delayed_rl.wrappers.vector._sub_envs import autoreset_mode, reset_mask, unbatch_actions
from delayed_rl.wrappers.vector.action_delay import VectorActionDelay
from delayed_rl.wrappers.vector.observation_delay import VectorObservationDelay


class VectorDelayAwareObservation(gym.vector.VectorWrapper, gym.utils.RecordConstructorArgs):
    """Observe, for each sub-env of a vector stack, the view of :class:`~delayed_rl.wrappers.DelayAwareObservation`.

    ``env`` is a vector stack holding a :class:`~delayed_rl.wrappers.VectorObservationDelay`, a
    :class:`~delayed_rl.wrappers.VectorActionDelay`, both or neither (found by walking ``.env``
    down the ``gym.vector.VectorWrapper`` layers; at most one of each). Each sub-env has its own
    :class:`~delayed_rl.wrappers.delay_aware.ViewState`, fed what the stack reports for it (its row of the observations,
    ``info["observation_age"]`` and ``info["arrived_observations"]``) and its action given to
    this wrapper's ``step``, so sub-env ``i`` observes exactly the view of a
    :class:`~delayed_rl.wrappers.DelayAwareObservation` over the same sub-env under an ``ObservationDelay`` and an
    ``ActionDelay`` of the same arguments, reset with the seed the stack gives sub-env ``i``.
    ``K`` (``action_history``) and ``D`` (``max_age``) are read from the delays' bounds as
    :class:`~delayed_rl.wrappers.DelayAwareObservation` reads them, and the rows before an episode's first action hold
    the ``VectorActionDelay``'s ``initial_action`` (without one, the neutral action).

    ``single_observation_space`` is :class:`~delayed_rl.wrappers.DelayAwareObservation`'s ``Dict``;
    ``observation_space`` is its batch (``gymnasium.vector.utils.batch_space``: a ``Dict`` of
    batches), and the views are batched with ``gymnasium.vector.utils.concatenate`` into new
    arrays. A sub-env's view restarts with its episode, as the stack's delays do:

    - ``NEXT_STEP`` (the default autoreset mode): at the reset step that follows an episode's end
      (the action given for it is neither checked nor recorded: the sub-env ignores it), with the
      new episode's ``o_0``;
    - ``SAME_STEP``: the ending step is recorded in the ending episode's view, which
      ``info["final_obs"]`` holds for that sub-env (built from the observation the stack reports
      there, the delayed one under a ``VectorObservationDelay``); that step's
      ``received_observations`` and ``age_clipped`` are in ``info["final_info"]``, and the view
      returned is the new episode's, at ``o_0``;
    - ``DISABLED``: when ``reset(options={"reset_mask": ...})`` resets the sub-env; the others
      keep their views.

    ``info`` holds, with Gymnasium's ``_key`` masks (set for the sub-envs stepped or reset),
    ``received_observations`` (an object array: each sub-env's tuple of the ``(i, o_i)`` received
    at this step, as :class:`~delayed_rl.wrappers.DelayAwareObservation` reports it) and ``age_clipped`` (a ``bool``
    array). Everything handed out is a copy, as :class:`~delayed_rl.wrappers.DelayAwareObservation`'s. Each sub-env's
    action is checked against the single action space before the stack is stepped. The wrapper
    draws nothing: ``reset(seed=...)`` seeds the stack.

    Wrap outside the delays: wrappers between them and the view must not change observations or
    drop ``info`` entries. The view reads only vector delay wrappers: a stack whose sub-envs hold
    an ``ObservationDelay`` or an ``ActionDelay`` of their own (seen by their ``info`` entries,
    ``observation_age`` at ``reset()`` and ``executed_action`` at ``step()``) is refused; wrap
    each of those sub-envs with :class:`~delayed_rl.wrappers.DelayAwareObservation` instead.

    Args:
        env: the vector stack to observe.
        action_history: as :class:`~delayed_rl.wrappers.DelayAwareObservation`'s.

    Raises:
        TypeError, ValueError: as :class:`~delayed_rl.wrappers.DelayAwareObservation` (the stack holding two
            ``VectorObservationDelay`` or ``VectorActionDelay`` wrappers), and ``ValueError`` for
            an env whose ``metadata["autoreset_mode"]`` is not a
            ``gymnasium.vector.AutoresetMode``.

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
        gym.utils.RecordConstructorArgs.__init__(self, action_history=json_safe(action_history))
        gym.vector.VectorWrapper.__init__(self, env)
        action_history = check_int(
            "action_history", action_history, 1, MAX_ACTION_HISTORY, optional=True
        )
        owner = type(self).__name__
        self._observation_delay = _the_wrapper(env, VectorObservationDelay, owner)
        self._action_delay = _the_wrapper(env, VectorActionDelay, owner)
        self.action_history, self.max_age, self.initial_action, self.single_observation_space = (
            _view_settings(
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
        """Empty ``received_observations`` and ``age_clipped`` arrays, one entry per sub-env."""
        return {
            "received_observations": np.full(self.num_envs, None, dtype=object),
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
