"""Space samples (actions, observations) passed between callers, wrappers and envs, as copies.

A wrapper that keeps a sample (an action in transit, an observation in a history) must not share
it with anyone who may modify it: the caller reusing its action array, an env editing its action
in place, a user writing into an ``info`` entry. :func:`copy_sample` is the one copy the delay
wrappers make. Gymnasium has no such helper (``gymnasium.vector.utils`` batches and unbatches
samples, ``gymnasium.spaces.utils`` flattens them; ``copy.deepcopy`` would do, at several times
the cost of the recursion below).
"""

from __future__ import annotations

import warnings
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector.utils import concatenate, create_empty_array

__all__ = ["as_action", "batch_of_copies", "copy_sample"]


def copy_sample(sample: Any) -> Any:
    """A copy of ``sample`` that shares nothing mutable with it.

    Numpy arrays are copied; dicts (Gymnasium's ``Dict`` samples), tuples (``Tuple``,
    ``OneOf`` and ``Sequence`` samples; a named tuple, such as ``Graph``'s ``GraphInstance``,
    keeps its type) and lists are rebuilt around copies of their entries, recursively. Everything else (Python and numpy
    scalars, strings) is immutable and returned as it is.

    Example:
        >>> action = {"a": np.zeros(2), "b": (1, np.ones(1))}
        >>> copied = copy_sample(action)
        >>> copied["b"][1][0] = 5.0
        >>> action["b"][1].tolist()
        [1.0]
    """
    if isinstance(sample, np.ndarray):
        return sample.copy()
    if isinstance(sample, dict):
        return type(sample)((key, copy_sample(value)) for key, value in sample.items())
    if isinstance(sample, tuple):
        copied = (copy_sample(value) for value in sample)
        if hasattr(sample, "_fields"):  # a named tuple: Graph's GraphInstance
            return type(sample)(*copied)
        return tuple(copied)
    if isinstance(sample, list):
        return [copy_sample(value) for value in sample]
    return sample


def batch_of_copies(space: gym.Space, samples: list[Any]) -> Any:
    """One ``gymnasium.vector`` batch of ``samples`` of ``space`` (one per sub-env), sharing nothing.

    The batch is new (``gymnasium.vector.utils.create_empty_array`` filled by ``concatenate``),
    built from copies of the samples (:func:`copy_sample`), so it shares nothing with them even
    for a space whose batch holds the samples themselves (``Text``, ``Graph``, ``Sequence``).
    """
    copies = [copy_sample(sample) for sample in samples]
    return concatenate(space, copies, create_empty_array(space, len(copies)))


def as_action(space: gym.Space, value: Any, name: str) -> Any:
    """``value`` checked to be in ``space`` and returned as a fresh sample of the space's form.

    What ``space.contains`` accepts is accepted; the result is then the form the space's own
    samples take, so that a value read back from JSON (lists, from an env spec) gives the same
    sample as the arrays it was written from: ``Box``, ``MultiDiscrete`` and ``MultiBinary``
    values become arrays of the space's dtype (a cast ``contains`` allows: exact for the integer
    spaces, the box's precision for ``Box``), ``Tuple`` values tuples, ``Dict`` values dicts in
    the space's key order, recursively; a ``Discrete`` value and other spaces' values are kept
    as they are (copied if they hold arrays).

    Args:
        space: the space ``value`` must be in.
        value: the value.
        name: the argument's name, for the message.

    Raises:
        ValueError: ``value`` is not in ``space``.
    """
    if not _contains(space, value):
        raise ValueError(f"{name} must be an action of {space}, got {value!r}")
    return _canonical(space, value)


def _contains(space: gym.Space, value: Any) -> bool:
    """``space.contains(value)``, without ``Box``'s warning for a list (a spec's JSON form)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "Casting input x to numpy array."
        return bool(space.contains(value))


def _canonical(space: gym.Space, value: Any) -> Any:
    """``value`` (in ``space``) in the form of the space's samples, sharing nothing with it."""
    if isinstance(space, spaces.Box | spaces.MultiDiscrete | spaces.MultiBinary):
        return np.array(value, dtype=space.dtype)  # a new array, whatever value was
    if isinstance(space, spaces.Dict):
        return {key: _canonical(sub, value[key]) for key, sub in space.spaces.items()}
    if isinstance(space, spaces.Tuple):
        return tuple(_canonical(sub, part) for sub, part in zip(space.spaces, value, strict=True))
    return copy_sample(value)
