"""Env specs whose delay arguments are JSON: ``gym.make(id, reward_delay=Constant(2))`` writable.

Every delay wrapper lists :class:`JsonSpecMixin` among its bases, so whichever is outermost
gives an ``env.spec`` that ``EnvSpec.to_json`` can write and ``gym.make`` can read back.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym

__all__ = ["DELAY_KWARGS", "JsonSpecMixin", "describe_delays"]

DELAY_KWARGS = ("action_delay", "observation_delay", "reward_delay")
"""The delay arguments of every ``delayed_rl/`` id, in the order their wrappers stack
(innermost first)."""


class JsonSpecMixin:
    """Gives a delay wrapper a ``spec`` whose delay arguments are JSON (:func:`describe_delays`).

    Listed before ``gym.Wrapper`` among a wrapper's bases, so its ``spec`` is the one used.
    """

    @property
    def spec(self) -> Any:
        """The env spec with this wrapper's ``WrapperSpec``, its delays described as JSON."""
        spec = gym.Wrapper.spec.fget(self)
        if spec is not None:
            describe_delays(spec)
        return spec


def describe_delays(spec: Any) -> None:
    """Record a registered env's delay arguments in ``spec.kwargs`` as JSON descriptions.

    ``gym.make(id, reward_delay=Constant(2))`` keeps the object in the env spec's kwargs, which
    ``EnvSpec.to_json`` cannot write; the library's entry points read the description back.
    Every delay wrapper's ``spec`` calls this, so the outermost one's spec is JSON-able.
    """
    from delayed_rl.delays import Delay, delay_spec

    kwargs = spec.kwargs if isinstance(spec.kwargs, dict) else {}
    objects = {key: kwargs[key] for key in DELAY_KWARGS if isinstance(kwargs.get(key), Delay)}
    if not objects:
        return
    entry = spec.entry_point
    try:  # a "module:attribute" string names the entry point (its module is loaded already)
        entry = gym.envs.registration.load_env_creator(entry) if isinstance(entry, str) else entry
    except (ImportError, AttributeError, ValueError):
        return
    if getattr(entry, "reads_delay_descriptions", False):  # a DelayableEntryPoint
        spec.kwargs = {**kwargs, **{key: delay_spec(value) for key, value in objects.items()}}
