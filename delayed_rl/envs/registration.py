"""Entry points that let ``gym.make(id, reward_delay=..., ...)`` return a delayed env.

Every ``delayed_rl/...`` id is registered with a :class:`DelayableEntryPoint`, which builds the
env and wraps it for the delays given (:func:`~delayed_rl.wrappers.wrap_delays`): the action
delay innermost, then the observation delay, the delay-aware view and the reward delay
outermost. The delays are ordinary keyword arguments, so ``env.spec`` records them and
``gym.make(env.spec)`` rebuilds the same stack. The order, the spec's JSON and why the envs end
their own episodes: the docs' environments page (``docs/envs.md``).
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
    distribution in the env spec's kwargs that way (see ``docs/envs.md``)."""

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

    def __call__(self, **kwargs: Any) -> gym.Env:
        """Build the env from ``kwargs`` and wrap it with :func:`~delayed_rl.wrappers.wrap_delays`.

        Args:
            **kwargs: :func:`~delayed_rl.wrappers.wrap_delays`' keywords go to it, and take its
                defaults when absent: ``reward_delay``, ``observation_delay`` and
                ``action_delay`` (each ``None``, the default: no wrapper; a number λ, for
                Poisson(λ); a :class:`~delayed_rl.delays.Delay` or its ``to_dict()``
                description), ``observation_arrival``, ``delay_aware`` and ``action_history``.
                The rest are the env class's own arguments (over the preset's).

        Raises:
            TypeError, ValueError: :func:`~delayed_rl.wrappers.wrap_delays` refuses a delay
                keyword, or the env class one of its own arguments. The message names it.
        """
        from delayed_rl.wrappers.stack import WRAP_DELAYS_KEYWORDS, wrap_delays

        delays = {name: kwargs.pop(name) for name in WRAP_DELAYS_KEYWORDS if name in kwargs}
        if self.preset is not None:
            kwargs = {**_load(self.preset), **kwargs}
        return wrap_delays(self.env_cls(**kwargs), **delays)

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
