"""Entry points that let ``gym.make(id, reward_delay=...)`` return a reward-delayed env.

Every ``delayed_rl/...`` id is registered with a :class:`DelayableEntryPoint` instead of the bare
env class. It builds the env from the remaining keyword arguments and, when ``reward_delay`` is
given, wraps it in :class:`~delayed_rl.wrappers.PoissonRewardDelay` (a number, read as the Poisson
mean λ) or :class:`~delayed_rl.wrappers.RewardDelay` (a :mod:`delayed_rl.delays` distribution).
Because ``reward_delay`` is an ordinary keyword argument, it is recorded in ``env.spec.kwargs`` and
``gym.make(env.spec)`` rebuilds the same stack.

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
    """

    def __init__(self, env_path: str):
        self.env_path = env_path

    @property
    def env_cls(self) -> type[gym.Env]:
        """The env class this entry point builds."""
        return _load(self.env_path)

    @property
    def metadata(self) -> dict[str, Any]:
        """The env class's metadata, so ``gym.make`` can check ``render_mode``."""
        return self.env_cls.metadata

    def __call__(self, reward_delay: Any = None, **kwargs: Any) -> gym.Env:
        """Build the env from ``kwargs``, wrapped for ``reward_delay`` when it is not None.

        Args:
            reward_delay: ``None`` (no wrapper), a number λ (``PoissonRewardDelay``) or a
                :class:`~delayed_rl.delays.Delay` (``RewardDelay``).
            **kwargs: the env class's own arguments.

        Raises:
            TypeError: ``reward_delay`` is neither a number nor a ``Delay`` (or the env refuses
                the type of one of its arguments).
            ValueError: ``reward_delay`` is not a valid Poisson mean (or the env refuses the
                value of one of its arguments).
        """
        env = self.env_cls(**kwargs)
        if reward_delay is None:
            return env
        from delayed_rl.wrappers import wrap_reward_delay

        return wrap_reward_delay(env, reward_delay)

    def __repr__(self) -> str:
        return f"DelayableEntryPoint({self.env_path!r})"


GridWorld = DelayableEntryPoint("delayed_rl.envs.gridworld:GridWorldEnv")
Roulette = DelayableEntryPoint("delayed_rl.envs.roulette:RouletteEnv")
EPuckLineFollow = DelayableEntryPoint("delayed_rl.envs.linefollow.env:EPuckLineFollowEnv")
