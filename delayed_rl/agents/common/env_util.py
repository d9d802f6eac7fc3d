"""Env helpers of the tabular agents: making and checking envs, and the one-env VecEnv view.

- :func:`make_env`: an env instance as it is, an id string through ``gym.make``;
- :func:`check_discrete`: the ``Discrete`` space check, with a hint for other spaces;
- :func:`vec_env_view` and :class:`SingleEnvVecView`: what ``agent.get_env()`` returns;
- :class:`SpaceIndex`: observations and actions of a ``Discrete`` space as 0-based indices.
"""

from __future__ import annotations

import numbers
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

__all__ = [
    "SingleEnvVecView",
    "SpaceIndex",
    "check_discrete",
    "check_spaces_match",
    "make_env",
    "vec_env_view",
]

_HINTS = {
    "observation_space": (
        "map observations to integers first, e.g. "
        "gymnasium.wrappers.DiscretizeObservation(env, bins=10) for a Box space, "
        "delayed_rl.wrappers.DiscreteObservation(env) for a Tuple of Discrete spaces (as "
        "Blackjack's) or a MultiDiscrete, or your own gymnasium.ObservationWrapper whose "
        "observation_space is Discrete(n)"
    ),
    "action_space": (
        "use a discrete action set, e.g. gymnasium.wrappers.DiscretizeAction(env, bins=5) for "
        "a Box space, or your own gymnasium.ActionWrapper whose action_space is Discrete(n)"
    ),
}


def check_discrete(space: Any, name: str) -> spaces.Discrete:
    """Return ``space`` after checking that it is ``Discrete``.

    Args:
        space: the space.
        name: ``"observation_space"`` or ``"action_space"`` (the message's hint depends on it).

    Raises:
        TypeError: ``space`` is not ``Discrete``; the message says how to make it so.
    """
    if isinstance(space, spaces.Discrete):
        return space
    raise TypeError(f"tabular agents need a Discrete {name}, got {space!r}: {_HINTS[name]}")


def check_spaces_match(
    env: gym.Env, observation_space: spaces.Discrete, action_space: spaces.Discrete
) -> gym.Env:
    """Return ``env`` after checking that its spaces are the agent's.

    Raises:
        TypeError: a space of ``env`` is not ``Discrete``.
        ValueError: a space differs from the agent's (the message shows both).
    """
    for name, ours in (("observation_space", observation_space), ("action_space", action_space)):
        theirs = check_discrete(getattr(env, name), name)
        if theirs != ours:
            raise ValueError(f"the env's {name} is {theirs!r} but the agent was built for {ours!r}")
    return env


def make_env(env: Any) -> gym.Env:
    """``env`` itself if it is a ``gymnasium.Env``, ``gym.make(env)`` if it is an id string.

    Raises:
        TypeError: ``env`` is neither (a stable-baselines3 ``VecEnv`` gets its own hint).
    """
    if isinstance(env, str):
        return gym.make(env)
    if isinstance(env, gym.Env):
        return env
    if hasattr(env, "num_envs") and hasattr(env, "step_async"):
        raise TypeError(
            "tabular agents step one gymnasium.Env, got a stable-baselines3 VecEnv "
            f"({type(env).__name__}); pass the env itself (for a DummyVecEnv: venv.envs[0])"
        )
    raise TypeError(f"env must be a gymnasium.Env or a registered env id string, got {env!r}")


class SpaceIndex:
    """Converts between the values of a ``Discrete(n, start)`` space and indices ``0..n−1``.

    Args:
        space: the space.
    """

    __slots__ = ("space", "n", "start")

    def __init__(self, space: spaces.Discrete):
        self.space = space
        self.n = int(space.n)
        self.start = int(space.start)

    def index(self, value: Any, name: str) -> int:
        """The index of one value of the space (an integer, or a 0-d integer array).

        A 0-d float array holding an integral value (``np.array(3.0)``) is accepted, as
        :meth:`indices` accepts integral floats; any other array (a batch, ``np.array(1.5)``,
        a bool array) is refused.

        Raises:
            TypeError: ``value`` is not one integer (a bool, a float, a string, an array of
                another shape than ``()``).
            ValueError: it is not in the space.
        """
        allowed = f"{name} must be an integer in {self.space}"
        if isinstance(value, np.ndarray):
            integral = value.dtype.kind in "iu" or (
                value.dtype.kind == "f"
                and value.ndim == 0
                and bool(np.isfinite(value))
                and float(value) == round(float(value))
            )
            if value.ndim != 0 or not integral:
                shown = value.tolist() if value.size <= 8 else f"{value.ravel()[:8].tolist()}..."
                raise TypeError(
                    f"{allowed} (one int, or a 0-d integer array), got array({shown}): an array "
                    f"of shape {value.shape} and dtype {value.dtype}"
                )
        elif isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral):
            raise TypeError(f"{allowed}, got {value!r}")
        index = int(value) - self.start
        if not 0 <= index < self.n:
            raise ValueError(f"{name} must be an integer in {self.space}, got {value!r}")
        return index

    def indices(self, values: Any, name: str) -> tuple[np.ndarray, bool]:
        """Indices of one value or a 1-D batch, and whether a single (unbatched) one was given.

        Integral floats (``3.0``) are accepted, as observations from some wrappers are floats.

        Raises:
            TypeError: the values are not integers.
            ValueError: a value is not in the space, or the batch is not 1-D.
        """
        array = np.asarray(values)
        integral_floats = (
            array.size
            and np.issubdtype(array.dtype, np.floating)
            and bool(np.all(array == np.round(array)))
        )
        if (array.dtype == np.bool_ or not np.issubdtype(array.dtype, np.integer)) and not (
            integral_floats
        ):
            raise TypeError(
                f"{name} must be an integer (or a 1-D batch of integers) in {self.space}, "
                f"got {values!r}"
            )
        if array.ndim > 1:
            raise ValueError(
                f"{name} must be one integer or a 1-D batch for {self.space}, "
                f"got shape {array.shape}"
            )
        index = array.astype(np.int64) - self.start
        if index.size and (index.min() < 0 or index.max() >= self.n):
            raise ValueError(f"{name} must lie in {self.space}, got {values!r}")
        return index, array.ndim == 0


class SingleEnvVecView:
    """A one-env, SB3-``VecEnv``-shaped view of a ``gymnasium.Env``.

    What ``agent.get_env()`` returns when stable-baselines3 is not loaded: batched
    ``reset``/``step`` with automatic reset, as in SB3. The agent itself steps the underlying
    env directly.

    Args:
        env: the env.
    """

    num_envs = 1

    def __init__(self, env: gym.Env):
        self.envs = [env]
        self.observation_space = env.observation_space
        self.action_space = env.action_space
        self.metadata = env.metadata
        self.render_mode = env.render_mode

    def reset(self) -> np.ndarray:
        """Reset the env; return its observation as a batch of one."""
        obs, _ = self.envs[0].reset()
        return np.array([obs])

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict]]:
        """Step with ``actions[0]``; reset when the episode ends (``info["terminal_observation"]``).

        Returns:
            SB3's ``(obs, rewards, dones, infos)``, each a batch of one.
        """
        obs, reward, terminated, truncated, info = self.envs[0].step(np.asarray(actions)[0])
        done = terminated or truncated
        if done:
            info["terminal_observation"] = obs
            info["TimeLimit.truncated"] = truncated and not terminated
            obs, _ = self.envs[0].reset()
        return np.array([obs]), np.array([reward], dtype=np.float32), np.array([done]), [info]

    def get_attr(self, name: str, indices: Any = None) -> list[Any]:
        """``[getattr(env, name)]``."""
        return [getattr(self.envs[0], name)]

    def env_is_wrapped(self, wrapper_class: type, indices: Any = None) -> list[bool]:
        """``[True]`` when a wrapper of ``wrapper_class`` is in the env's stack."""
        env = self.envs[0]
        while isinstance(env, gym.Wrapper):
            if isinstance(env, wrapper_class):
                return [True]
            env = env.env
        return [False]

    def close(self) -> None:
        """Close the env."""
        self.envs[0].close()


def vec_env_view(env: gym.Env) -> Any:
    """A one-env SB3 ``VecEnv`` over ``env``, as SB3's ``model.get_env()`` returns.

    A stable-baselines3 ``DummyVecEnv`` when stable-baselines3 is already imported (so SB3's
    callbacks see the type they expect; SB3 is never imported here), else a
    :class:`SingleEnvVecView`.
    """
    import sys

    if sys.modules.get("stable_baselines3") is None:
        return SingleEnvVecView(env)
    from stable_baselines3.common.vec_env import DummyVecEnv

    return DummyVecEnv([lambda: env])
