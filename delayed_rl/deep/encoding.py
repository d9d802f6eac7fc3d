"""Observations and actions as the float features a reward network reads.

A :class:`SpaceEncoding` is made from one Gymnasium space: a ``Box`` is flattened to its
``prod(shape)`` entries (cast to ``float32``), a ``Discrete(n, start)`` becomes a one-hot vector
of length ``n``. Other spaces are refused, with a ``TypeError`` that names the argument. The
encoding also describes its space as JSON (:meth:`SpaceEncoding.to_dict`), so that a reward model
file records its spaces without pickling them.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from gymnasium import spaces

__all__ = ["SpaceEncoding"]

MAX_FEATURES = 2**20
"""The most features one space may encode to (a one-hot of ``Discrete(n)`` has ``n``)."""


class SpaceEncoding:
    """How the values of one ``Box`` or ``Discrete`` space become float features.

    Args:
        name: the argument the space came from (``"observation_space"``...), for messages.
        space: the space.

    Attributes:
        space: the space.
        shape: the shape of one value as stored (``(1,)`` for ``Discrete``, as SB3 stores it).
        n_features: the length of one value's features.
    """

    def __init__(self, name: str, space: Any):
        if isinstance(space, spaces.Box):
            shape = tuple(int(n) for n in space.shape)
            n_features = int(np.prod(shape, dtype=np.int64))
        elif isinstance(space, spaces.Discrete):
            shape, n_features = (1,), int(space.n)
        else:
            raise TypeError(
                f"{name} must be a gymnasium Box or Discrete space, got {space!r} "
                f"({type(space).__name__})"
            )
        if not 1 <= n_features <= MAX_FEATURES:
            raise ValueError(
                f"{name} must encode to 1..{MAX_FEATURES} features (MAX_FEATURES), got "
                f"{space!r}, which has {n_features}"
            )
        self.name = name
        self.space = space
        self.shape = shape
        self.n_features = n_features

    @property
    def discrete(self) -> bool:
        """Whether the space is ``Discrete`` (encoded one-hot)."""
        return isinstance(self.space, spaces.Discrete)

    def batch(self, values: Any, count: int) -> np.ndarray:
        """``count`` values of the space as one array of shape ``(count, *shape)``, checked.

        Raises:
            ValueError: ``values`` does not hold ``count`` values of the space's shape, holds a
                non-finite number, or (``Discrete``) a value outside the space.
        """
        array = np.asarray(values)
        if array.dtype.kind not in "biuf":
            raise TypeError(f"{self.name} values must be numbers, got {array.dtype} values")
        if array.size != count * int(np.prod(self.shape)):
            raise ValueError(
                f"{self.name} values must be {count} of shape {self.shape}, got an array of "
                f"shape {array.shape}"
            )
        array = array.reshape((count, *self.shape))
        if self.discrete:
            start, n = int(self.space.start), int(self.space.n)
            if array.dtype.kind == "f" and not np.all(array == np.round(array)):
                raise ValueError(f"{self.name} values must be integers, got {array.ravel()[:8]}")
            if np.any(array < start) or np.any(array >= start + n):
                raise ValueError(
                    f"{self.name} values must be in {start}..{start + n - 1}, got "
                    f"{array.ravel()[:8]}"
                )
            return array.astype(np.int64)
        array = array.astype(np.float32)
        if not np.all(np.isfinite(array)):
            raise ValueError(f"{self.name} values must be finite, got {array.ravel()[:8]}")
        return array

    def features(self, values: torch.Tensor) -> torch.Tensor:
        """The features of a batch stored as :meth:`batch` makes it: shape ``(n, n_features)``."""
        if self.discrete:
            index = values.reshape(-1).long() - int(self.space.start)
            return torch.nn.functional.one_hot(index, self.n_features).float()
        return values.reshape(values.shape[0], -1).float()

    def empty(self, *leading: int) -> np.ndarray:
        """A zeroed store for values: shape ``(*leading, *shape)``, the dtype :meth:`batch` gives."""
        dtype = np.int64 if self.discrete else np.float32
        return np.zeros((*leading, *self.shape), dtype=dtype)

    def to_dict(self) -> dict[str, Any]:
        """The space as JSON: ``{"type": "Discrete", "n", "start"}`` or a ``Box``'s bounds."""
        if self.discrete:
            return {"type": "Discrete", "n": int(self.space.n), "start": int(self.space.start)}
        return {
            "type": "Box",
            "low": self.space.low.tolist(),
            "high": self.space.high.tolist(),
            "dtype": str(self.space.dtype),
        }

    @classmethod
    def from_dict(cls, name: str, data: Any) -> SpaceEncoding:
        """The encoding of the space :meth:`to_dict` described (from a file: checked).

        Raises:
            ValueError: ``data`` does not describe a ``Box`` or ``Discrete`` space.
        """
        try:
            if data["type"] == "Discrete":
                space = spaces.Discrete(int(data["n"]), start=int(data["start"]))
            elif data["type"] == "Box":
                dtype = np.dtype(data["dtype"])  # the bounds read in it: no precision warning
                low = np.asarray(data["low"], dtype=dtype)
                high = np.asarray(data["high"], dtype=dtype)
                space = spaces.Box(low, high, dtype=dtype)
            else:
                raise ValueError(f"unknown space type {data['type']!r}")
        except (KeyError, TypeError, ValueError, OverflowError) as error:
            raise ValueError(f"{name} must describe a Box or Discrete space: {error}") from None
        return cls(name, space)
