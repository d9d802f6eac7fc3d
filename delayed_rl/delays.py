"""Delay distributions: how many steps late each reward (or observation) arrives.

Every distribution is a :class:`Delay` (``sample``, ``pmf``, ``mean``, ``support_max``,
``to_dict``), and :func:`as_delay` turns a number (a Poisson mean) or a ``to_dict()``
description back into one. The thesis assumes Poisson delays; its future work asks for other
statistics, so the wrappers and agents accept any :class:`Delay`.

Example:
    >>> import numpy as np
    >>> from delayed_rl.delays import Poisson
    >>> Poisson(5).sample(np.random.default_rng(0), 4).tolist()
    [5, 2, 1, 2]
"""

from __future__ import annotations

import functools
import inspect
import math
import numbers
from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from delayed_rl import _portable_math as portable_math
from delayed_rl._validation import check_int, check_real

__all__ = [
    "MAX_DELAY",
    "AliasTable",
    "Constant",
    "Delay",
    "Empirical",
    "Geometric",
    "Poisson",
    "Uniform",
    "as_delay",
    "delay_spec",
]

MAX_DELAY = int(np.iinfo(np.int64).max)
"""The largest delay (steps) any distribution may produce: ``2**63 − 1``, the ``int64`` limit.

Delays are drawn as ``int64`` and added to step clocks; a larger one would wrap round to a
negative delay. A parameter whose delays cannot fit is refused at construction."""

_TAIL = 1e-20  # the probability of a delay beyond MAX_DELAY that an unbounded distribution may have
_FITS = f" (delays must fit int64: at most {MAX_DELAY})"


def _as_pmf(pmf: Any) -> np.ndarray:
    """``pmf`` as a 1-D float array of finite weights ``>= 0`` (not yet normalised).

    Raises:
        TypeError: ``pmf`` does not hold numbers (strings, ``None``, bools...).
        ValueError: ``pmf`` is empty, not 1-D, or has a negative or non-finite entry.
    """
    try:
        probs = np.asarray(pmf)
    except ValueError:  # a ragged nesting of sequences
        raise ValueError(f"pmf must be a non-empty 1-D sequence of numbers, got {pmf!r}") from None
    if probs.dtype.kind not in "iuf":
        raise TypeError(
            f"pmf must be a non-empty 1-D sequence of numbers, got {pmf!r} ({type(pmf).__name__})"
        )
    probs = probs.astype(float)
    if probs.ndim != 1 or probs.size == 0:
        raise ValueError(f"pmf must be a non-empty 1-D sequence of numbers, got {pmf!r}")
    if not np.all(np.isfinite(probs)) or np.any(probs < 0):
        raise ValueError(f"pmf must hold finite numbers >= 0, got {pmf!r}")
    return probs


class Delay(ABC):
    """A distribution over non-negative integer delays (in steps).

    A subclass gives ``sample(rng, size)``, a batch of delays as an ``int64`` array (batched, so
    a wrapper draws many at once instead of calling the generator every step); ``pmf(k)``, the
    probability of delay ``k`` (vectorised over ``k``); ``mean``, the expected delay;
    ``support_max``, the largest delay it can produce (``None`` when unbounded, as for Poisson);
    and ``to_dict()``, a JSON-able description, ``{"type": "Constant", "k": 2}``, which
    :func:`as_delay` reads back (so a delay survives an env spec's JSON round trip). Every delay
    fits ``int64``: parameters that would produce delays beyond :data:`MAX_DELAY`
    (``Constant(2**63)``, ``Poisson(1e19)``...) are refused at construction.
    """

    @abstractmethod
    def sample(self, rng: np.random.Generator, size: int | None = None) -> np.ndarray | int:
        """Draw delays: an ``int64`` array of ``size`` delays, or one ``int`` if ``size`` is None."""

    @abstractmethod
    def pmf(self, k: int | np.ndarray) -> float | np.ndarray:
        """Probability that the delay equals ``k`` (0 outside the support)."""

    @property
    @abstractmethod
    def mean(self) -> float:
        """The expected delay."""

    @property
    def support_max(self) -> int | None:
        """The largest possible delay, or ``None`` if the support is unbounded."""
        return None

    def to_dict(self) -> dict[str, Any]:
        """A JSON-able description, ``{"type": <class name>, <parameter>: <value>, ...}``.

        :func:`as_delay` turns it back into an equal distribution, so wrappers record delays in
        env specs in this form.

        Raises:
            NotImplementedError: for a subclass of your own (only the library's distributions
                are read back by :func:`as_delay`); a wrapper then records the object itself.
        """
        if _DELAY_TYPES.get(type(self).__name__) is not type(self):
            raise NotImplementedError(
                f"{type(self).__name__} is not one of the library's distributions "
                f"{tuple(_DELAY_TYPES)}: it has no JSON description"
            )
        names = inspect.signature(type(self)).parameters
        return {"type": type(self).__name__, **{name: getattr(self, name) for name in names}}

    def _finish(self, draws: np.ndarray, size: int | None) -> np.ndarray | int:
        draws = np.asarray(draws, dtype=np.int64)
        return int(draws) if size is None else draws

    def __eq__(self, other: object) -> bool:
        return type(self) is type(other) and repr(self) == repr(other)

    def __hash__(self) -> int:
        return hash(repr(self))


class AliasTable:
    """Draws from a distribution on ``0, 1, …, len(pmf) − 1`` in O(1) per draw.

    Vose's construction of Walker's alias table: each of the ``n`` columns holds a probability
    ``keep[i]`` of its own value and an ``alias[i]`` for the rest, so a draw picks a column with
    the integer part of ``n·u`` (``u`` uniform) and decides with its fractional part. Exact up to
    the rounding of the probabilities (relative 1e-16).

    Args:
        pmf: non-negative probabilities; they are normalised to sum to one.

    Raises:
        TypeError: if ``pmf`` does not hold numbers.
        ValueError: if ``pmf`` is empty or not 1-D, has a negative or non-finite entry, or sums
            to zero.
    """

    def __init__(self, pmf: Sequence[float] | np.ndarray):
        pmf = _as_pmf(pmf)
        total = pmf.sum()
        if total <= 0:
            raise ValueError(f"pmf must have positive mass, got {pmf}")
        n = pmf.size
        scaled = pmf * (n / total)
        self.keep = np.ones(n)
        self.alias = np.arange(n)
        small = [i for i in range(n) if scaled[i] < 1.0]
        large = [i for i in range(n) if scaled[i] >= 1.0]
        while small and large:
            low, high = small.pop(), large[-1]
            self.keep[low] = scaled[low]
            self.alias[low] = high
            scaled[high] -= 1.0 - scaled[low]
            if scaled[high] < 1.0:
                small.append(large.pop())
        # what is left holds probability one up to rounding: it keeps its own value

    def sample(self, rng: np.random.Generator, size: int | tuple[int, ...] | None) -> np.ndarray:
        """Independent draws, an ``int64`` array of shape ``size`` (0-d if ``size`` is None)."""
        u = np.asarray(rng.random(size)) * self.keep.size
        column = u.astype(np.int64)
        return np.where(u - column < self.keep[column], column, self.alias[column])


class Poisson(Delay):
    """Poisson(λ) delays, the thesis's model: ``P(d = k) = λ^k e^{-λ} / k!``.

    Delays are drawn by table look-up (an :class:`AliasTable` of the pmf, built on first use and
    ending where the remaining tail weighs less than 1e-20, far below a uniform draw's 2⁻⁵³
    resolution): several times cheaper than numpy's transformed rejection, which was the largest
    part of the delay wrappers' and the compiled path's cost (measured: ``benchmarks/SPEED.md``).
    Beyond λ ≈ 30 000 the table would pass 65 536 entries and numpy's ``poisson`` draws instead.

    Args:
        lam: the mean (and variance) λ ≥ 0, any finite real up to :attr:`MAX_LAM`; λ = 0 means
            no delay.

    Raises:
        TypeError: ``lam`` is not a real number (a bool or a string included).
        ValueError: ``lam`` is negative, NaN, infinite or above :attr:`MAX_LAM`.

    Example:
        >>> import numpy as np
        >>> delay = Poisson(3.0)
        >>> delay.mean, delay.support_max, round(float(delay.pmf(3)), 4)
        (3.0, None, 0.224)
        >>> delay.sample(np.random.default_rng(0), size=4).shape
        (4,)
    """

    TAIL = 1e-20
    """The mass of the far tail left out of the table."""

    MAX_TABLE = 1 << 16
    """The largest table built."""

    MAX_LAM = MAX_DELAY - 10.0 * math.sqrt(MAX_DELAY)
    """The largest λ (about 9.2e18): numpy's own limit, ten standard deviations below ``MAX_DELAY``."""

    def __init__(self, lam: float):
        self.lam = check_real("lam", lam, 0.0, self.MAX_LAM, note=_FITS)

    def sample(self, rng, size=None):
        """Draw delays by alias-table look-up (numpy's ``poisson`` when there is no table).

        Args:
            rng: the generator to draw from.
            size: how many delays (an int or a shape), or ``None`` for one ``int``.
        """
        table = self.table
        if table is None:
            return self._finish(rng.poisson(self.lam, size), size)
        return self._finish(table.sample(rng, size), size)

    @functools.cached_property
    def table(self) -> AliasTable | None:
        """The alias table of the pmf up to a negligible tail, or ``None`` if it is too long."""
        end = math.ceil(2 * self.lam) + 1  # past 2λ each term is less than half the one before
        while end <= self.MAX_TABLE and self.pmf(end) * 2 >= self.TAIL:
            end *= 2
        return AliasTable(self.pmf(np.arange(end))) if end <= self.MAX_TABLE else None

    def pmf(self, k):
        """``λ^k e^{-λ} / k!`` (computed in log space), 0 for negative ``k``; vectorised.

        The logarithms and exponentials are ``delayed_rl._portable_math``'s, so the values
        (and every alias table and credit weight made from them) have the same bits on every CPU.
        """
        k = np.asarray(k)
        if self.lam == 0.0:
            out = (k == 0).astype(float)
        else:
            safe_k = np.where(k >= 0, k, 0).astype(float)
            log_p = (
                safe_k * portable_math.log(self.lam)
                - self.lam
                - portable_math.log_factorial(safe_k)
            )
            out = np.where(k >= 0, portable_math.exp_array(log_p), 0.0)
        return float(out) if out.ndim == 0 else out

    @property
    def mean(self) -> float:
        """λ."""
        return self.lam

    def __repr__(self) -> str:
        return f"Poisson(lam={self.lam!r})"


class Constant(Delay):
    """Every delay is exactly ``k`` steps (the constant-delay MDP of the literature).

    Args:
        k: the delay, an integer in ``[0, MAX_DELAY]``.

    Raises:
        TypeError: ``k`` is not an integer (``2.0`` included).
        ValueError: ``k`` is negative or above :data:`MAX_DELAY`.

    Example:
        >>> import numpy as np
        >>> Constant(2).sample(np.random.default_rng(0), size=3).tolist()
        [2, 2, 2]
    """

    def __init__(self, k: int):
        self.k = check_int("k", k, 0, MAX_DELAY, note=_FITS)

    def sample(self, rng, size=None):
        """``size`` copies of ``k`` (``rng`` is not used, so its stream does not advance)."""
        return self._finish(np.full(() if size is None else size, self.k), size)

    def pmf(self, k):
        """1 at ``k == self.k``, 0 elsewhere; vectorised."""
        out = (np.asarray(k) == self.k).astype(float)
        return float(out) if out.ndim == 0 else out

    @property
    def mean(self) -> float:
        """``k``."""
        return float(self.k)

    @property
    def support_max(self) -> int:
        """``k``."""
        return self.k

    def __repr__(self) -> str:
        return f"Constant(k={self.k!r})"


class Geometric(Delay):
    """Geometric delays on {0, 1, 2, ...}: ``P(d = k) = p (1 − p)^k`` (failures before a success).

    Args:
        p: the per-step arrival probability, ``MIN_P <= p <= 1``; the mean is ``(1 − p) / p``.

    Raises:
        TypeError: ``p`` is not a real number.
        ValueError: ``p`` is outside ``[MIN_P, 1]`` or NaN.

    Example:
        >>> delay = Geometric(0.25)
        >>> delay.mean, delay.support_max, float(delay.pmf(2))  # 0.25 · 0.75²
        (3.0, None, 0.140625)
    """

    MIN_P = -portable_math.log(_TAIL) / MAX_DELAY
    """The smallest ``p`` (about 5e-18): below it a delay passes ``MAX_DELAY`` with probability
    above 1e-20 (numpy would clip it there, distorting the distribution)."""

    def __init__(self, p: float):
        self.p = check_real(
            "p", p, self.MIN_P, 1.0, note=" (delays must fit int64, except with probability 1e-20)"
        )

    def sample(self, rng, size=None):
        """Draw with numpy's ``geometric`` (trials up to a success) minus one."""
        return self._finish(rng.geometric(self.p, size) - 1, size)

    def pmf(self, k):
        """``p (1 − p)^k`` for ``k >= 0``, else 0; vectorised (the power by repeated squaring)."""
        k = np.asarray(k)
        power = portable_math.integer_power(1.0 - self.p, np.where(k >= 0, k, 0))
        out = np.where(k >= 0, self.p * power, 0.0)
        return float(out) if out.ndim == 0 else out

    @property
    def mean(self) -> float:
        """``(1 − p) / p``."""
        return (1.0 - self.p) / self.p

    @property
    def support_max(self) -> int | None:
        """0 when ``p == 1`` (every delay is 0), else ``None`` (unbounded)."""
        return 0 if self.p == 1.0 else None

    def __repr__(self) -> str:
        return f"Geometric(p={self.p!r})"


class Uniform(Delay):
    """Delays uniform on the integers ``low, low + 1, ..., high`` (both ends included).

    Args:
        low: the smallest delay, an integer ≥ 0.
        high: the largest delay, an integer in ``[low, MAX_DELAY]``.

    Raises:
        TypeError: ``low`` or ``high`` is not an integer.
        ValueError: ``low`` is negative or above :data:`MAX_DELAY`, or ``high`` is below ``low``
            or above :data:`MAX_DELAY`.

    Example:
        >>> delay = Uniform(1, 3)
        >>> delay.mean, delay.support_max, float(delay.pmf(0)), round(float(delay.pmf(2)), 4)
        (2.0, 3, 0.0, 0.3333)
    """

    def __init__(self, low: int, high: int):
        self.low = check_int("low", low, 0, MAX_DELAY, note=_FITS)
        self.high = check_int("high", high, self.low, MAX_DELAY, note=_FITS)

    def sample(self, rng, size=None):
        """Draw with ``rng.integers(low, high + 1)``."""
        return self._finish(rng.integers(self.low, self.high + 1, size), size)

    def pmf(self, k):
        """``1 / (high − low + 1)`` on ``low..high``, 0 elsewhere; vectorised."""
        k = np.asarray(k)
        out = np.where((k >= self.low) & (k <= self.high), 1.0 / (self.high - self.low + 1), 0.0)
        return float(out) if out.ndim == 0 else out

    @property
    def mean(self) -> float:
        """``(low + high) / 2``."""
        return (self.low + self.high) / 2.0

    @property
    def support_max(self) -> int:
        """``high``."""
        return self.high

    def __repr__(self) -> str:
        return f"Uniform(low={self.low!r}, high={self.high!r})"


class Empirical(Delay):
    """Delays with an explicit probability table: ``P(d = k) = pmf[k]``.

    Args:
        pmf: non-negative finite weights for delays 0, 1, ..., len(pmf) − 1, summing to 1
            (within 1e-9; they are then renormalised exactly). Use it for measured latency
            histograms.

    Raises:
        TypeError: ``pmf`` does not hold numbers.
        ValueError: ``pmf`` is empty or not 1-D, has a negative or non-finite entry, or does not
            sum to 1.

    Example:
        >>> import numpy as np
        >>> delay = Empirical([0.5, 0.0, 0.5])  # half undelayed, half two steps late
        >>> delay.mean, delay.support_max
        (1.0, 2)
        >>> set(delay.sample(np.random.default_rng(0), size=100).tolist())
        {0, 2}
    """

    def __init__(self, pmf: Sequence[float] | np.ndarray):
        probs = _as_pmf(pmf)
        total = probs.sum()
        if abs(total - 1.0) > 1e-9:
            raise ValueError(f"pmf must sum to 1, got a sum of {total!r}")
        self._weights = probs.tolist()  # as given: to_dict() rebuilds the very same probs
        self.probs = probs / total
        self._cdf = np.cumsum(self.probs)
        self._cdf[-1] = 1.0

    def sample(self, rng, size=None):
        """Draw by inverting the cumulative table with one uniform per delay."""
        draws = np.searchsorted(self._cdf, rng.random(size), side="right")
        return self._finish(draws, size)

    def pmf(self, k):
        """``probs[k]`` inside the table, 0 outside; vectorised."""
        k = np.asarray(k)
        inside = (k >= 0) & (k < self.probs.size)
        out = np.where(inside, self.probs[np.where(inside, k, 0)], 0.0)
        return float(out) if out.ndim == 0 else out

    @property
    def mean(self) -> float:
        """``Σ k · probs[k]``."""
        return float(np.sum(np.arange(self.probs.size) * self.probs))

    @property
    def support_max(self) -> int:
        """The largest ``k`` with ``probs[k] > 0``."""
        return int(np.flatnonzero(self.probs)[-1])

    def to_dict(self) -> dict[str, Any]:
        """``{"type": "Empirical", "pmf": [...]}``, the weights as given."""
        return {"type": "Empirical", "pmf": list(self._weights)}

    def __repr__(self) -> str:
        return f"Empirical(pmf={self.probs.tolist()!r})"


_DELAY_TYPES: dict[str, type[Delay]] = {
    cls.__name__: cls for cls in (Poisson, Constant, Geometric, Uniform, Empirical)
}


def _from_dict(description: Mapping[str, Any], name: str) -> Delay:
    """The distribution a :meth:`Delay.to_dict` description stands for."""
    kind = description.get("type")
    allowed = f"a dict with a 'type' in {tuple(_DELAY_TYPES)} and its parameters"
    if kind is None:
        raise ValueError(f"{name} must be {allowed}, got {dict(description)!r} (no 'type')")
    if not isinstance(kind, str):
        raise TypeError(f"{name} must be {allowed}, got 'type' {kind!r} ({type(kind).__name__})")
    if kind not in _DELAY_TYPES:
        raise ValueError(f"{name} must be {allowed}, got 'type' {kind!r}")
    cls = _DELAY_TYPES[kind]
    params = {key: value for key, value in description.items() if key != "type"}
    expected = list(inspect.signature(cls).parameters)
    if sorted(params) != sorted(expected):
        raise ValueError(
            f"{name}: a {kind} description takes the parameters {expected}, got {sorted(params)}"
        )
    return cls(**params)


def as_delay(delay: Delay | float | Mapping[str, Any], name: str = "delay") -> Delay:
    """Turn ``delay`` into a :class:`Delay`: a number is read as a Poisson mean λ.

    Args:
        delay: a :class:`Delay` (returned as it is), a real number λ (``Poisson(λ)``) or a
            description made by :meth:`Delay.to_dict` (``{"type": "Constant", "k": 2}``).
        name: the argument's name in the caller, for the error message.

    Raises:
        TypeError: if ``delay`` is neither a :class:`Delay`, a real number (a bool is not) nor a
            dict, or a description's parameter has the wrong type.
        ValueError: if ``delay`` is a number that is not a valid λ (negative, NaN, infinite,
            above :attr:`Poisson.MAX_LAM`), or a dict that describes no distribution (no or an
            unknown ``"type"``, missing or extra parameters, a parameter's bad value).

    Every message starts with ``name``: a number's (``"reward_delay must be a number in [0,
    9.22337e+18] (a Poisson mean), got -1"``), not Poisson's own ``lam``, and a description's
    (``"reward_delay: k must be an integer >= 0, got 2.5"``).
    """
    if isinstance(delay, Delay):
        return delay
    if isinstance(delay, numbers.Real) and not isinstance(delay, (bool, np.bool_)):
        return Poisson(check_real(name, delay, 0.0, Poisson.MAX_LAM, note=" (a Poisson mean)"))
    if isinstance(delay, Mapping):
        try:
            return _from_dict(delay, name)
        except (TypeError, ValueError) as error:  # a parameter's check names the parameter only
            if str(error).startswith(name):
                raise
            raise type(error)(f"{name}: {error}") from None
    raise TypeError(
        f"{name} must be a delayed_rl.delays.Delay (Poisson, Constant, Geometric, Uniform, "
        f"Empirical), a number read as a Poisson mean or a Delay.to_dict() description, got "
        f"{delay!r} ({type(delay).__name__})"
    )


def delay_spec(delay: Any) -> Any:
    """The JSON-able form of a delay argument, as wrappers record it for env specs.

    A :class:`Delay` becomes its :meth:`~Delay.to_dict` description (kept as it is if it cannot
    describe itself), a number a plain ``int`` or ``float``, a description the ``to_dict()`` of
    the delay it describes (its numpy numbers and arrays as Python numbers and lists); anything
    else is returned unchanged (the wrapper's own check refuses it). :func:`as_delay` reads every
    form back.
    """
    if isinstance(delay, Mapping):
        try:
            delay = as_delay(delay)
        except (TypeError, ValueError):
            return delay
    if isinstance(delay, Delay):
        try:
            return delay.to_dict()
        except NotImplementedError:
            return delay
    if isinstance(delay, numbers.Integral) and not isinstance(delay, (bool, np.bool_)):
        return int(delay)
    if isinstance(delay, numbers.Real) and not isinstance(delay, (bool, np.bool_)):
        return float(delay)
    return delay
