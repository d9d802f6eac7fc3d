"""Entry points that let ``gym.make(id, reward_delay=..., ...)`` return a delayed env.

Every ``delayed_rl/...`` id is registered with a :class:`DelayableEntryPoint` instead of the bare
env class. It builds the env from the remaining keyword arguments and wraps it for the delays
given (:func:`~delayed_rl.wrappers.wrap_delays`), innermost first:

1. ``action_delay``: :class:`~delayed_rl.wrappers.ActionDelay` (the env executes actions sent
   earlier);
2. ``observation_delay``: :class:`~delayed_rl.wrappers.ObservationDelay` (the agent sees older
   observations), under the arrival rule ``observation_arrival`` (``"stale"``, the default, or
   ``"network"``);
3. ``delay_aware=True``: :class:`~delayed_rl.wrappers.DelayAwareObservation` (the agent observes
   the newest observation received, its age and the last ``action_history`` actions sent),
   outside the delays it reads;
4. ``reward_delay``: :class:`~delayed_rl.wrappers.PoissonRewardDelay` for a number (the Poisson
   mean λ) or :class:`~delayed_rl.wrappers.RewardDelay` for a distribution — outermost, so its
   ``info["undelayed_reward"]`` and episode-end handling see the whole step.

Each is a number (a Poisson mean), a :mod:`delayed_rl.delays` distribution or its ``to_dict()``
description. Because they are ordinary keyword arguments, they are recorded in
``env.spec.kwargs`` and ``gym.make(env.spec)`` rebuilds the same stack. A distribution is
recorded there (by the delay wrappers' ``spec``,
:func:`~delayed_rl.wrappers._spec.describe_delays`) as its JSON
description, ``{"type": "Constant", "k": 2}`` (:meth:`~delayed_rl.delays.Delay.to_dict`), which
the entry points accept back, so the spec also survives ``EnvSpec.to_json`` /
``EnvSpec.from_json``.

Gymnasium applies its own wrappers (``PassiveEnvChecker``, ``OrderEnforcing`` and, when
``max_episode_steps`` is passed to ``gym.make``, ``TimeLimit``) *outside* the delay wrapper. The
envs of this package therefore end their episodes themselves (``max_steps`` arguments, as Minigrid
does), so the delay wrapper sees every episode end and can flush pending rewards.
"""

from __future__ import annotations

import importlib
from typing import Any

import gymnasium as gym


def _load(path: str) -> Any:
    """The object named by ``"module:attribute"``, importing the module."""
    module_name, attr = path.split(":")
    return getattr(importlib.import_module(module_name), attr)


class DelayableEntryPoint:
    """A Gymnasium entry point: ``env_cls(**kwargs)``, delay-wrapped when ``reward_delay`` is set.

    Args:
        env_path: ``"module:ClassName"`` of the env class, imported on first use.
        preset: ``"module:NAME"`` of a mapping of default keyword arguments (a registered
            configuration of the class), imported on first use; the caller's arguments override
            it. ``None``: no preset.

    Raises:
        TypeError: ``env_path`` (or ``preset``) is not a string.
        ValueError: ``env_path`` (or ``preset``) is not of the form ``"module:Name"``.
    """

    reads_delay_descriptions = True
    """Each delay may be a ``Delay.to_dict()`` description: the delay wrappers record a
    distribution in the env spec's kwargs that way (see the module docstring)."""

    def __init__(self, env_path: str, preset: str | None = None):
        for name, path in (("env_path", env_path), ("preset", preset)):
            if path is None and name == "preset":
                continue
            if not isinstance(path, str):
                raise TypeError(
                    f"{name} must be a 'module:Name' string, got {path!r} ({type(path).__name__})"
                )
            module, _, attr = path.partition(":")
            if not module or not attr or ":" in attr:
                raise ValueError(f"{name} must be a 'module:Name' string, got {path!r}")
        self.env_path = env_path
        self.preset = preset

    @property
    def env_cls(self) -> type[gym.Env]:
        """The env class this entry point builds."""
        return _load(self.env_path)

    @property
    def metadata(self) -> dict[str, Any]:
        """The env class's metadata, so ``gym.make`` can check ``render_mode``."""
        return self.env_cls.metadata

    def __call__(
        self,
        reward_delay: Any = None,
        observation_delay: Any = None,
        action_delay: Any = None,
        observation_arrival: str = "stale",
        delay_aware: bool = False,
        action_history: int | None = None,
        **kwargs: Any,
    ) -> gym.Env:
        """Build the env from ``kwargs``, wrapped for each delay that is not None.

        Args:
            reward_delay: ``None`` (no wrapper), a number λ (``PoissonRewardDelay``), a
                :class:`~delayed_rl.delays.Delay` or its ``to_dict()`` description
                (``RewardDelay``).
            observation_delay: ``None``, or a delay as above (``ObservationDelay``).
            action_delay: ``None``, or a delay as above (``ActionDelay``).
            observation_arrival: the observation delay's arrival rule, ``"stale"`` or
                ``"network"`` (``ObservationDelay``'s ``arrival``).
            delay_aware: wrap a ``DelayAwareObservation`` around the delays.
            action_history: its ``action_history`` (only with ``delay_aware=True``).
            **kwargs: the env class's own arguments.

        Raises:
            TypeError, ValueError: a delay is neither a number, a ``Delay`` nor a dict, or is
                not a valid Poisson mean or describes no distribution; another argument is
                refused by :func:`~delayed_rl.wrappers.wrap_delays` (or the env refuses one of
                its arguments). The message names the argument.
        """
        if self.preset is not None:
            kwargs = {**_load(self.preset), **kwargs}
        env = self.env_cls(**kwargs)
        from delayed_rl.wrappers import wrap_delays

        return wrap_delays(
            env,
            action_delay=action_delay,
            observation_delay=observation_delay,
            reward_delay=reward_delay,
            observation_arrival=observation_arrival,
            delay_aware=delay_aware,
            action_history=action_history,
        )

    def __repr__(self) -> str:
        preset = "" if self.preset is None else f", preset={self.preset!r}"
        return f"DelayableEntryPoint({self.env_path!r}{preset})"


GridWorld = DelayableEntryPoint("delayed_rl.envs.gridworld:GridWorldEnv")
Roulette = DelayableEntryPoint("delayed_rl.envs.roulette:RouletteEnv")
EPuckLineFollow = DelayableEntryPoint("delayed_rl.envs.linefollow.env:EPuckLineFollowEnv")
EPuckLineFollowReal = DelayableEntryPoint(
    "delayed_rl.envs.linefollow.env:EPuckLineFollowEnv",
    preset="delayed_rl.envs.linefollow.env:REAL_ROBOT",
)
