"""Interleaved timings: the measuring and the min–median–max figures the speed benchmarks share.

A *repeat* is ``rounds`` rounds; a round times every run once, back to back, with the garbage
collector off (as ``timeit`` does). A repeat's cost of a run is its fastest round (the one least
disturbed by other processes); a ratio of two runs within a repeat is the median over its
rounds of each round's ratio, whose two timings were taken back to back and so were slowed
alike by a slow spell of the machine. Figures are min–median–max over the repeats.
"""

from __future__ import annotations

import gc
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import numpy as np

Repeat = dict[str, list[float]]
"""One repeat's timings: each run's seconds per step in each round."""


@contextmanager
def collector_off() -> Iterator[None]:
    """Turn the garbage collector off for the block (back on after it, if it was on)."""
    collecting = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if collecting:
            gc.enable()


def seconds_per_step(run: Callable[[], object], steps: int) -> float:
    """Seconds per step of ``run()``, which takes ``steps`` steps (garbage collector off)."""
    with collector_off():
        start = time.perf_counter()
        run()
        return (time.perf_counter() - start) / steps


def seconds_per_call(function: Callable[[], object], calls: int) -> float:
    """Mean seconds per call of ``function`` over ``calls`` calls (garbage collector as it is)."""
    start = time.perf_counter()
    for _ in range(calls):
        function()
    return (time.perf_counter() - start) / calls


def interleave(timed: dict[str, Callable[[], float]], repeats: int, rounds: int) -> list[Repeat]:
    """Time every run of ``timed`` once per round, ``rounds`` rounds per repeat.

    Args:
        timed: ``name: time()``, where ``time()`` returns the seconds per step of one timing
            (warmed up beforehand by the caller).
        repeats: how many repeats.
        rounds: rounds per repeat.

    Returns:
        One :data:`Repeat` per repeat.
    """
    result = []
    for _ in range(repeats):
        timings: Repeat = {name: [] for name in timed}
        for _ in range(rounds):
            for name, time_one in timed.items():
                timings[name].append(time_one())
        result.append(timings)
    return result


def fastest(repeat: Repeat) -> dict[str, float]:
    """Each run's fastest round of a repeat (the least disturbed by other processes)."""
    return {name: min(times) for name, times in repeat.items()}


def median_ratio(repeat: Repeat, name: str, floor: str) -> float:
    """``name``'s cost over ``floor``'s within a repeat: the median over its rounds."""
    return float(np.median([t / f for t, f in zip(repeat[name], repeat[floor], strict=True)]))


def spread(values: list[float]) -> tuple[float, float, float]:
    """``(min, median, max)`` of ``values``."""
    low, median, high = np.percentile(values, [0, 50, 100])
    return float(low), float(median), float(high)


def shown(values: tuple[float, float, float], digits: int = 2) -> str:
    """``min–median–max`` with ``digits`` decimals."""
    return "–".join(f"{value:.{digits}f}" for value in values)


def verdict(worst: float, target: float) -> str:
    """``ok`` when ``worst`` meets its target (at most ``target``), else ``MISSED``."""
    return "ok" if worst <= target else "MISSED"


def target_summary(
    what: str,
    ratios: list[float],
    target: float,
    per_repeat: list[Repeat],
    floor: str,
    floor_text: str,
    floor_digits: int = 2,
) -> str:
    """One line: a ratio of each repeat against its target, beside the floor's cost.

    Args:
        what: what the ratios are, with the sign that introduces them (``"a / b ="``).
        ratios: one ratio per repeat (shown min–median–max; the largest must meet ``target``).
        target: the most a repeat's ratio may be.
        per_repeat: the repeats, whose fastest rounds give the floor's cost.
        floor: the name of the floor's timings.
        floor_text: how the line names the floor.
        floor_digits: the decimals of the floor's µs/step.
    """
    floor_cost = spread([fastest(r)[floor] * 1e6 for r in per_repeat])
    return (
        f"{what} {shown(spread(ratios))} (min–median–max of {len(ratios)} repeats; target ≤ "
        f"{target} in every repeat: {verdict(max(ratios), target)}); floor, {floor_text}: "
        f"{shown(floor_cost, floor_digits)} µs/step"
    )


def one_repeat(timed: dict[str, Callable[[], float]], rounds: int) -> Repeat:
    """A single repeat of ``rounds`` rounds (:func:`interleave`), for figures over rounds."""
    return interleave(timed, 1, rounds)[0]
