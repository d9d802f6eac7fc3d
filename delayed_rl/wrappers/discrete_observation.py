"""``DiscreteObservation``: observations made of discrete parts as one ``Discrete`` index.

The tabular agents need a ``Discrete`` observation space; some envs observe several discrete
parts (Gymnasium's ``Blackjack-v1``: the player's sum, the dealer's card, a usable ace).
"""

from __future__ import annotations

import math
import numbers
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

__all__ = ["DiscreteObservation"]


def _parts(space: spaces.Space) -> tuple[list[int], list[int]]:
    """The sizes and starts of a ``Tuple`` of ``Discrete`` or a one-dimensional ``MultiDiscrete``.

    Raises:
        TypeError: ``space`` is neither.
    """
    parts = space.spaces if isinstance(space, spaces.Tuple) else ()
    if parts and all(isinstance(part, spaces.Discrete) for part in parts):
        return [int(p.n) for p in parts], [int(p.start) for p in parts]
    if isinstance(space, spaces.MultiDiscrete) and space.nvec.ndim == 1 and space.nvec.size:
        return [int(n) for n in space.nvec], [int(s) for s in space.start]
    raise TypeError(
        "DiscreteObservation needs an observation_space that is a non-empty Tuple of Discrete "
        f"spaces or a one-dimensional MultiDiscrete, got {space!r}"
    )


class DiscreteObservation(gym.ObservationWrapper, gym.utils.RecordConstructorArgs):
    """Observe one ``Discrete`` index per combination of the env's discrete parts.

    Such an env can then be learned by any of the library's agents (on the Python path: the
    compiled one needs the env's outcome tables, ``P``, which Blackjack does not have). The
    wrapped env's observation space is ``Discrete(Π n_i)``, numbered mixed radix with the first
    part most significant, as ``numpy.ravel_multi_index`` numbers a C-ordered array's cells: for
    parts ``x_i`` of ``Discrete(n_i, start=s_i)``, the index is ``Σ_i (x_i − s_i) · Π_{j > i}
    n_j``, in ``0 .. Π n_i − 1``; :meth:`decode` maps an index back to its parts. An observation
    outside the env's own space (a part missing, of the wrong type or out of its range) raises
    ``ValueError`` rather than mapping to another state's index. Rewards, ends and ``info``
    pass through unchanged (it adds no ``info`` key).

    Args:
        env: an env whose ``observation_space`` is a ``Tuple`` of ``Discrete`` spaces (e.g.
            ``Blackjack-v1``) or a one-dimensional ``MultiDiscrete``.

    Raises:
        TypeError: the observation space is neither.

    Example:
        >>> import gymnasium as gym
        >>> from delayed_rl.wrappers import DiscreteObservation, wrap_delays
        >>> env = DiscreteObservation(wrap_delays(gym.make("Blackjack-v1"), reward_delay=2))
        >>> env.observation_space
        Discrete(704)
        >>> env.decode(env.observation((14, 7, 0)))
        (14, 7, 0)
    """

    def __init__(self, env: gym.Env):
        gym.utils.RecordConstructorArgs.__init__(self)
        gym.ObservationWrapper.__init__(self, env)
        self.sizes, self.starts = _parts(env.observation_space)
        self.strides = [math.prod(self.sizes[i + 1 :]) for i in range(len(self.sizes))]
        self.observation_space = spaces.Discrete(math.prod(self.sizes))

    def observation(self, observation: Any) -> int:
        """The index of ``observation``'s combination of parts.

        Raises:
            ValueError: ``observation`` is not one integer per part, each in its part's range.
        """
        try:
            values = list(observation)
        except TypeError:
            values = None
        if values is None or len(values) != len(self.sizes):
            raise ValueError(
                f"observation must hold {len(self.sizes)} integers (one per part of "
                f"{self.env.observation_space!r}), got {observation!r}"
            )
        index = 0
        for value, size, start, stride in zip(
            values, self.sizes, self.starts, self.strides, strict=True
        ):
            offset = _offset(value, start, size)
            if offset is None:
                raise ValueError(
                    f"observation {observation!r} is outside {self.env.observation_space!r}: "
                    f"part {value!r} is not an integer in {start}..{start + size - 1}"
                )
            index += offset * stride
        return index

    def decode(self, index: Any) -> tuple[int, ...]:
        """The parts of the combination numbered ``index`` (the inverse of :meth:`observation`).

        Raises:
            TypeError: ``index`` is not an integer.
            ValueError: it is outside ``0 .. observation_space.n − 1``.
        """
        if isinstance(index, bool) or not isinstance(index, numbers.Integral):
            raise TypeError(f"index must be an integer, got {index!r} ({type(index).__name__})")
        n = int(self.observation_space.n)
        if not 0 <= index < n:
            raise ValueError(f"index must be in 0..{n - 1}, got {index!r}")
        index = int(index)
        parts = []
        for size, start, stride in zip(self.sizes, self.starts, self.strides, strict=True):
            parts.append(start + (index // stride) % size)
        return tuple(parts)


def _offset(value: Any, start: int, size: int) -> int | None:
    """``value − start`` for an integer ``value`` in ``start .. start + size − 1``, else ``None``."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral):
        return None
    offset = int(value) - start
    return offset if 0 <= offset < size else None
