"""Env specs whose delay arguments are JSON: ``gym.make(id, reward_delay=Constant(2))`` writable.

Every delay wrapper lists :class:`JsonSpecMixin` among its bases, so whichever is outermost
gives an ``env.spec`` that ``EnvSpec.to_json`` can write and ``gym.make`` can read back. The
wrappers record their own arguments through :func:`json_safe` (numpy numbers as Python numbers,
arrays as lists), and a registered env's delay arguments are recorded the same way.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np

__all__ = ["DELAY_KWARGS", "JsonSpecMixin", "describe_delays", "json_safe", "record_arguments"]

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


def json_safe(value: Any) -> Any:
    """``value`` in a form ``json.dumps`` writes and ``json.loads`` gives back equal.

    Numpy scalars become Python numbers (``np.float32(2.5)`` → ``2.5``, ``np.int64(3)`` → ``3``,
    ``np.bool_`` → ``bool``), arrays nested lists of them; dicts are rebuilt around their
    converted values, tuples and lists become lists (JSON has no tuples), recursively. Anything
    else is returned as it is (``EnvSpec.to_json`` then says what it cannot write).

    Example:
        >>> json_safe({"k": np.int64(2), "pose": (np.float32(0.5), np.zeros(2))})
        {'k': 2, 'pose': [0.5, [0.0, 0.0]]}
    """
    if isinstance(value, np.ndarray | np.generic):
        return value.tolist()
    if isinstance(value, Mapping):
        return {key: json_safe(entry) for key, entry in value.items()}
    if isinstance(value, tuple | list):
        return [json_safe(entry) for entry in value]
    return value


def record_arguments(wrapper: gym.utils.RecordConstructorArgs, **arguments: Any) -> None:
    """Record a delay wrapper's constructor ``arguments`` for its env spec, in JSON form.

    A ``delay`` argument is recorded as :func:`~delayed_rl.delays.delay_spec` describes it (a
    description, or a mapping of them per agent, stays as it is), and every argument through
    :func:`json_safe`, so ``EnvSpec.to_json`` writes the spec and
    ``gym.make`` reads it back. Call it first in ``__init__``: the first call records.
    """
    from delayed_rl.delays import delay_spec

    if "delay" in arguments:
        arguments["delay"] = delay_spec(arguments["delay"])
    recorded = {name: json_safe(value) for name, value in arguments.items()}
    gym.utils.RecordConstructorArgs.__init__(wrapper, **recorded)


def describe_delays(spec: Any) -> None:
    """Record a registered env's delay arguments in ``spec.kwargs`` in JSON form.

    ``gym.make(id, reward_delay=Constant(2))`` keeps the object in the env spec's kwargs, which
    ``EnvSpec.to_json`` cannot write; it is recorded as its ``to_dict()`` description, which the
    library's entry points read back. A number is recorded as a Python ``int`` or ``float``
    (``reward_delay=np.float32(2.0)`` as ``2.0``) and a description's numpy numbers likewise
    (:func:`json_safe`): the same delay, in a form JSON keeps; so is a numpy ``action_history``
    (the delay-aware view's). Every delay wrapper's ``spec`` calls this, so the outermost one's
    spec is JSON-able.
    """
    from delayed_rl.delays import Delay, delay_spec

    kwargs = spec.kwargs if isinstance(spec.kwargs, dict) else {}
    objects = {
        key: kwargs[key]
        for key in DELAY_KWARGS
        if isinstance(kwargs.get(key), Delay | np.generic | Mapping)
    }
    numbers = {
        key: json_safe(kwargs[key])
        for key in ("action_history",)
        if isinstance(kwargs.get(key), np.generic)
    }
    if not objects and not numbers:
        return
    entry = spec.entry_point
    try:  # a "module:attribute" string names the entry point (its module is loaded already)
        entry = gym.envs.registration.load_env_creator(entry) if isinstance(entry, str) else entry
    except (ImportError, AttributeError, ValueError):
        return
    if getattr(entry, "reads_delay_descriptions", False):  # a DelayableEntryPoint
        described = {key: json_safe(delay_spec(value)) for key, value in objects.items()}
        spec.kwargs = {**kwargs, **described, **numbers}
