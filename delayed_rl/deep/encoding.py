"""How a reward model stores the values of a Gymnasium space, and describes the space as JSON.

:class:`SpaceEncoding` states the spaces it takes and how it stores each.
"""

from __future__ import annotations

from collections import OrderedDict
from typing import Any

import numpy as np
from gymnasium import spaces

__all__ = ["MAX_FEATURES", "SpaceEncoding"]

MAX_FEATURES = 2**20
"""The most features one space may encode to (a one-hot of ``Discrete(n)`` has ``n``)."""

SUPPORTED = "Box, Discrete, MultiDiscrete, MultiBinary, or a Dict of those"
"""The spaces a reward model takes, for messages."""


def is_image(space: spaces.Space) -> bool:
    """Whether ``space`` is an image as SB3 tells one: a 3-d ``uint8`` ``Box`` on 0..255."""
    return (
        isinstance(space, spaces.Box)
        and space.dtype == np.uint8
        and len(space.shape) == 3
        and bool(np.all(space.low == 0))
        and bool(np.all(space.high == 255))
    )


def _leaf_layout(name: str, space: Any) -> tuple[tuple[int, ...], np.dtype, int]:
    """A leaf space's stored shape, stored dtype and number of features (one-hots counted)."""
    if isinstance(space, spaces.Box):
        shape = tuple(int(n) for n in space.shape)
        dtype = np.dtype(np.uint8) if is_image(space) else np.dtype(np.float32)
        return shape, dtype, int(np.prod(shape, dtype=np.int64))
    if isinstance(space, spaces.Discrete):
        return (1,), np.dtype(np.int64), int(space.n)
    if isinstance(space, spaces.MultiDiscrete):
        shape = tuple(int(n) for n in space.nvec.shape)
        return shape, np.dtype(np.int64), int(np.sum(space.nvec, dtype=np.int64))
    if isinstance(space, spaces.MultiBinary):
        shape = tuple(int(n) for n in np.atleast_1d(space.n))
        return shape, np.dtype(np.int8), int(np.prod(shape, dtype=np.int64))
    kind = "a nested Dict" if isinstance(space, spaces.Dict) else type(space).__name__
    raise TypeError(
        f"{name} must be a gymnasium {SUPPORTED} (the spaces SB3's policies take), got "
        f"{space!r} ({kind})"
    )


class SpaceEncoding:
    """How the values of one space are checked and stored.

    A :class:`SpaceEncoding` is made from one space that SB3's algorithms take:

    - ``Box``: stored in its own shape, ``float32`` (an image, a ``uint8`` ``Box`` with bounds 0 and
      255 as SB3's ``is_image_space`` tells, keeps ``uint8``: a quarter of the memory);
    - ``Discrete(n, start)``: one ``int64`` a value, shape ``(1,)`` (as SB3 stores it);
    - ``MultiDiscrete(nvec, start)``: ``int64``, the shape of ``nvec``;
    - ``MultiBinary(n)``: ``int8``, its shape;
    - ``Dict`` of those (not nested, as SB3's ``MultiInputPolicy``): a store per key.

    Any other space (``Tuple``, ``Graph``, ``Text``, ``Sequence``, a nested ``Dict``) is refused
    with a ``TypeError`` that names the argument, the space and what is supported. What the network
    reads from a stored value is :mod:`delayed_rl.deep.network`'s job. The encoding describes its
    space as JSON (:meth:`SpaceEncoding.to_dict`), so that a reward model file records its spaces
    without pickling them.

    Args:
        name: the argument the space came from (``"observation_space"``...), for messages.
        space: the space.

    Attributes:
        space: the space.
        parts: for a ``Dict``, the encoding of each key's space (in the space's key order);
            ``None`` for any other space.
        shape: a leaf's stored shape (``(1,)`` for ``Discrete``); ``None`` for a ``Dict``.
        dtype: a leaf's stored dtype; ``None`` for a ``Dict``.
        n_features: a leaf's feature count (one-hots counted), or the sum over a ``Dict``'s keys.

    Raises:
        TypeError: a space of another kind; a ``Dict`` with a key that is not a string.
        ValueError: a space with no features, or more than :data:`MAX_FEATURES`.
    """

    def __init__(self, name: str, space: Any):
        self.name = name
        self.space = space
        self.parts: dict[str, SpaceEncoding] | None = None
        if isinstance(space, spaces.Dict):
            if not space.spaces:
                raise ValueError(f"{name} must have at least one key, got {space!r}")
            for key in space.spaces:
                if not isinstance(key, str):  # as SB3's extractors; a file holds string keys
                    raise TypeError(
                        f"{name} must have string keys (as SB3's Dict observations), got the key "
                        f"{key!r} ({type(key).__name__}) in {space!r}"
                    )
            self.parts = {
                key: SpaceEncoding(f"{name}[{key!r}]", part) for key, part in space.spaces.items()
            }
            for key, part in self.parts.items():
                if part.parts is not None:
                    raise TypeError(
                        f"{name} must be a gymnasium {SUPPORTED}, got a nested Dict at key {key!r}"
                    )
            self.shape, self.dtype = None, None
            n_features = sum(part.n_features for part in self.parts.values())
        else:
            self.shape, self.dtype, n_features = _leaf_layout(name, space)
        if not 1 <= n_features <= MAX_FEATURES:
            raise ValueError(
                f"{name} must encode to 1..{MAX_FEATURES} features (MAX_FEATURES), got "
                f"{space!r}, which has {n_features}"
            )
        self.n_features = n_features

    @property
    def image(self) -> bool:
        """Whether the (leaf) space is an image (:func:`is_image`)."""
        return self.parts is None and is_image(self.space)

    @property
    def value_bytes(self) -> int:
        """The bytes one stored value takes."""
        if self.parts is not None:
            return sum(part.value_bytes for part in self.parts.values())
        return int(np.prod(self.shape, dtype=np.int64)) * self.dtype.itemsize

    # ------------------------------------------------------------------ checking
    def batch(self, values: Any, count: int) -> Any:
        """``count`` values of the space as stored arrays (a dict of them for a ``Dict``), checked.

        Raises:
            TypeError: values that are not numbers; a ``Dict`` space's values not a mapping.
            ValueError: values that are not ``count`` of the space's shape, a non-finite
                number, or an integer outside the space.
        """
        if self.parts is not None:
            if not isinstance(values, dict):
                raise TypeError(
                    f"{self.name} values must be a dict with keys {list(self.parts)}, got "
                    f"{type(values).__name__}"
                )
            if set(values) != set(self.parts):
                raise ValueError(
                    f"{self.name} values must have the keys {sorted(self.parts)}, got "
                    f"{sorted(map(str, values))}"
                )
            return {key: part.batch(values[key], count) for key, part in self.parts.items()}
        array = np.asarray(values)
        if array.dtype.kind not in "biuf":
            raise TypeError(f"{self.name} values must be numbers, got {array.dtype} values")
        if array.size != count * int(np.prod(self.shape, dtype=np.int64)):
            raise ValueError(
                f"{self.name} values must be {count} of shape {self.shape}, got an array of "
                f"shape {array.shape}"
            )
        array = array.reshape((count, *self.shape))
        if self.dtype.kind == "f":
            array = array.astype(np.float32)
            if not np.all(np.isfinite(array)):
                raise ValueError(f"{self.name} values must be finite, got {array.ravel()[:8]}")
            return array
        if array.dtype.kind == "f" and not np.all(array == np.round(array)):
            raise ValueError(f"{self.name} values must be integers, got {array.ravel()[:8]}")
        low, high = self.integer_bounds()
        if np.any(array < low) or np.any(array > high):
            raise ValueError(
                f"{self.name} values must be in {self._bounds_text()}, got {array.ravel()[:8]}"
            )
        return array.astype(self.dtype)

    def integer_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """A leaf integer space's lowest and highest values, broadcastable to a batch."""
        space = self.space
        if isinstance(space, spaces.Discrete):
            return np.asarray(space.start), np.asarray(space.start + space.n - 1)
        if isinstance(space, spaces.MultiDiscrete):
            return np.asarray(space.start), np.asarray(space.start + space.nvec - 1)
        if isinstance(space, spaces.MultiBinary):
            return np.asarray(0), np.asarray(1)
        return np.asarray(space.low), np.asarray(space.high)  # an image Box

    def _bounds_text(self) -> str:
        low, high = self.integer_bounds()
        if np.all(low == low.flat[0]) and np.all(high == high.flat[0]):  # an image's: 0..255
            return f"{int(low.flat[0])}..{int(high.flat[0])}"
        return f"{low.tolist()}..{high.tolist()} (per entry)"

    # ------------------------------------------------------------------ storing
    def empty(self, *leading: int) -> Any:
        """A zeroed store: shape ``(*leading, *shape)`` (a dict of them for a ``Dict``)."""
        if self.parts is not None:
            return {key: part.empty(*leading) for key, part in self.parts.items()}
        return np.zeros((*leading, *self.shape), dtype=self.dtype)

    def take(self, store: Any, index: Any) -> Any:
        """``store[index]`` (of every key's array, for a ``Dict``)."""
        if self.parts is not None:
            return {key: store[key][index] for key in self.parts}
        return store[index]

    def put(self, store: Any, index: Any, values: Any) -> None:
        """``store[index] = values`` (key by key, for a ``Dict``)."""
        if self.parts is not None:
            for key in self.parts:
                store[key][index] = values[key]
        else:
            store[index] = values

    def flat(self, stored: Any) -> Any:
        """Stored values with every leading axis merged into one: ``(n, *shape)`` a leaf."""
        if self.parts is not None:
            return {key: part.flat(stored[key]) for key, part in self.parts.items()}
        return stored.reshape(-1, *self.shape)

    def arrays(self, store: Any, prefix: str) -> dict[str, np.ndarray]:
        """The store's arrays by file name: ``prefix``, or ``prefix.<i>`` for a Dict's i-th key."""
        if self.parts is None:
            return {prefix: store}
        return {f"{prefix}.{i}": store[key] for i, key in enumerate(self.parts)}

    def from_arrays(self, arrays: dict[str, np.ndarray], prefix: str) -> Any:
        """The store :meth:`arrays` wrote (``KeyError`` where a name is missing)."""
        if self.parts is None:
            return arrays[prefix]
        return {key: arrays[f"{prefix}.{i}"] for i, key in enumerate(self.parts)}

    # ------------------------------------------------------------------ JSON
    def to_dict(self) -> dict[str, Any]:
        """The space as JSON: its ``type`` and what makes it (bounds, sizes, starts, keys)."""
        space = self.space
        if self.parts is not None:
            return {
                "type": "Dict",
                "keys": list(self.parts),
                "spaces": [part.to_dict() for part in self.parts.values()],
            }
        if isinstance(space, spaces.Discrete):
            return {"type": "Discrete", "n": int(space.n), "start": int(space.start)}
        if isinstance(space, spaces.MultiDiscrete):
            return {
                "type": "MultiDiscrete",
                "nvec": space.nvec.tolist(),
                "start": space.start.tolist(),
            }
        if isinstance(space, spaces.MultiBinary):
            return {"type": "MultiBinary", "n": np.atleast_1d(space.n).tolist()}
        return {
            "type": "Box",
            "low": space.low.tolist(),
            "high": space.high.tolist(),
            "dtype": str(space.dtype),
        }

    @classmethod
    def from_dict(cls, name: str, data: Any) -> SpaceEncoding:
        """The encoding of the space :meth:`to_dict` described (from a file: checked).

        Raises:
            ValueError: ``data`` does not describe a space a reward model takes.
        """
        try:
            space = _space_from_dict(data)
        except (KeyError, TypeError, ValueError, OverflowError, AssertionError) as error:
            raise ValueError(f"{name} must describe a {SUPPORTED} space: {error}") from None
        try:
            return cls(name, space)
        except TypeError as error:
            raise ValueError(str(error)) from None


def _space_from_dict(data: Any) -> spaces.Space:
    kind = data["type"]
    if kind == "Discrete":
        return spaces.Discrete(int(data["n"]), start=int(data["start"]))
    if kind == "MultiDiscrete":
        return spaces.MultiDiscrete(
            np.asarray(data["nvec"], dtype=np.int64), start=np.asarray(data["start"], np.int64)
        )
    if kind == "MultiBinary":
        n = [int(size) for size in data["n"]]
        return spaces.MultiBinary(n[0] if len(n) == 1 else n)
    if kind == "Box":
        dtype = np.dtype(data["dtype"])  # the bounds read in it: no precision warning
        low = np.asarray(data["low"], dtype=dtype)
        high = np.asarray(data["high"], dtype=dtype)
        return spaces.Box(low, high, dtype=dtype)
    if kind == "Dict":
        keys, parts = data["keys"], data["spaces"]
        if not isinstance(keys, list) or not isinstance(parts, list) or len(keys) != len(parts):
            raise ValueError("a Dict needs lists 'keys' and 'spaces' of one length")
        if not all(isinstance(key, str) for key in keys) or len(set(keys)) != len(keys):
            raise ValueError(f"a Dict's keys must be distinct strings, got {keys!r}")
        return spaces.Dict(
            OrderedDict(
                (key, _space_from_dict(part)) for key, part in zip(keys, parts, strict=True)
            )
        )
    raise ValueError(f"unknown space type {kind!r}")
