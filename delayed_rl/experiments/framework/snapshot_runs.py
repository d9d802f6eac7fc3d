"""Grid-world training in pieces, with snapshots of the greedy policy, and the walks that judge it.

The greedy policy of a learner under delays can keep flipping between the optimal loop and
another route, so ``mmq-gridworld``, ``anonymous-delay`` and ``future-work`` look at it during
learning: :func:`train_with_snapshots` trains a run in :data:`SNAPSHOTS` pieces (as one call
does) and after each walks the greedy policy from the start cell (:func:`walk_average`,
:func:`is_optimal`). :func:`measure` makes a run's result of that; :func:`current_readout` and
:func:`averaged_readout` pick MMQ's current or averaged table's readout.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from delayed_rl._validation import check_bool, check_int
from delayed_rl.agents.common.q_table import greedy_actions
from delayed_rl.experiments.framework.delay_estimates import delay_estimate
from delayed_rl.experiments.framework.experiment import Curve, running_average
from delayed_rl.experiments.framework.training import grid_env

LOOP_FRACTION = 0.95
"""A greedy average this close to the optimum means the optimal loop: on 9×9, over 1000 steps the
17-step loop scores 58 rewards (0.580, 0.986 of 10/17), the next shortest, 19 steps, 0.895 of it."""
SNAPSHOTS = 50
"""Greedy snapshots a run takes: one every ``max(1, steps // SNAPSHOTS)`` steps."""
WALK_STEPS = 1000
"""Steps of a greedy walk (:func:`walk_average`), from the start cell of the undelayed grid."""
AVERAGED = "averaged"
"""The entry of :func:`measure`'s result holding the averaged table's readouts (MMQ's
``greedy_window``), under the names the current table's have."""
WARM_UP = 2000
"""Steps of the untimed warm-up run before each timed one (:func:`warm_up`): past DeconvQ's
first solve, so every kernel of the run is loaded."""


def optimal_average(size: int) -> float:
    """The optimal loop's reward per step on the ``size`` grid: ``10 / (2(size − 1) + 1)``."""
    return 10.0 / (2 * (size - 1) + 1)


@functools.lru_cache(maxsize=8)
def _dynamics(size: int) -> tuple[list[list[int]], list[list[float]], int]:
    """The undelayed grid's ``next_state`` and ``reward_table`` (as lists) and its start cell."""
    env = grid_env(size, 0).unwrapped
    return env.next_state.tolist(), env.reward_table.tolist(), int(env.start_state)


def walk_average(policy: Sequence[int] | np.ndarray, size: int, steps: int = WALK_STEPS) -> float:
    """Average reward of the deterministic ``policy`` walked ``steps`` steps from the start cell.

    The undelayed grid's dynamics are deterministic, so this is what
    :func:`~delayed_rl.experiments.framework.training.greedy_average_reward` measures, for any policy.

    Args:
        policy: the action of every cell (0-based, row-major).
        size: the grid's side.
        steps: how many steps to walk.
    """
    check_int("steps", steps, 1)
    return _walk_average(tuple(np.asarray(policy, dtype=np.int64).tolist()), size, steps)


@functools.lru_cache(maxsize=4096)
def _walk_average(actions: tuple[int, ...], size: int, steps: int) -> float:
    """:func:`walk_average` of one policy (cached: a settled run snapshots the same policy)."""
    next_state, reward, state = _dynamics(size)
    total = 0.0
    for _ in range(steps):
        action = actions[state]
        total += reward[state][action]
        state = next_state[state][action]
    return total / steps


def is_optimal(policy: Sequence[int] | np.ndarray, size: int) -> bool:
    """Whether ``policy``'s :data:`WALK_STEPS`-step walk scores ``LOOP_FRACTION`` of the optimal loop."""
    return walk_average(policy, size) >= LOOP_FRACTION * optimal_average(size)


def greedy_policy(agent: Any, averaged: bool = False) -> np.ndarray:
    """The agent's deterministic greedy action in every state.

    MMQ's is read off its current Q-table (the thesis's readout), or with ``averaged`` off the
    averaged table of its ``greedy_window`` (``greedy_table``); any other agent's is
    ``predict(..., deterministic=True)``.

    Raises:
        TypeError: ``averaged`` is not a bool.
    """
    averaged = check_bool("averaged", averaged)
    if hasattr(agent, "greedy_table"):
        return greedy_actions(np.asarray(agent.greedy_table if averaged else agent.q_table))
    states = np.arange(agent.observation_space.n)
    return np.asarray(agent.predict(states, deterministic=True)[0])


def train_with_snapshots(
    agent: Any, steps: int, size: int, keep_obs: bool = False
) -> dict[str, Any]:
    """Train ``agent`` for ``steps`` in pieces, recording whether its greedy policy is optimal.

    ``learn(..., reset_num_timesteps=False)`` continues the run (clock, episode, pending rewards,
    random streams, the acting-model counts), so the pieces train exactly as one
    ``learn(steps)`` call.

    Args:
        agent: the agent to train (on its env).
        steps: how many steps in all.
        size: the grid's side, for the greedy walks.
        keep_obs: also return ``obs``, the observation of every step.

    Returns:
        ``rewards`` (the undelayed reward of every step), ``learn_seconds`` (the wall time of
        the ``learn`` calls), ``snapshot_steps``, ``snapshot_optimal`` (bool) and
        ``snapshot_greedy`` (the walk's average) per snapshot, ``path`` (``learn``'s last), and
        ``obs`` with ``keep_obs``. An agent with a ``greedy_window`` has its averaged table's
        snapshots too, ``snapshot_optimal`` and ``snapshot_greedy`` in the entry
        :data:`AVERAGED`.
    """
    steps = check_int("steps", steps, 1)
    interval = max(1, steps // SNAPSHOTS)
    tables = [False]  # whether the readout is of the averaged table
    if getattr(agent, "greedy_window", None) is not None:
        tables.append(True)
    rewards, observations, marks = [], [], []
    optimal: dict[bool, list[bool]] = {averaged: [] for averaged in tables}
    greedy: dict[bool, list[float]] = {averaged: [] for averaged in tables}
    seconds, done = 0.0, 0
    while done < steps:
        piece = min(interval, steps - done)
        started = time.perf_counter()
        agent.learn(piece, log_interval=None, record=True, reset_num_timesteps=done == 0)
        seconds += time.perf_counter() - started
        done += piece
        rewards.append(agent.training_log["undelayed_reward"])
        if keep_obs:
            observations.append(agent.training_log["obs"])
        marks.append(done)
        for averaged in tables:
            average = walk_average(greedy_policy(agent, averaged), size)
            greedy[averaged].append(average)
            optimal[averaged].append(average >= LOOP_FRACTION * optimal_average(size))
    out: dict[str, Any] = {
        "rewards": np.concatenate(rewards),
        "learn_seconds": seconds,
        "snapshot_steps": np.asarray(marks, dtype=np.int64),
        "path": agent.last_learn_path,
    }
    for averaged in tables:
        snapshots = {
            "snapshot_optimal": np.asarray(optimal[averaged], dtype=bool),
            "snapshot_greedy": np.asarray(greedy[averaged]),
        }
        out.update({AVERAGED: snapshots} if averaged else snapshots)
    if keep_obs:
        out["obs"] = np.concatenate(observations)
    return out


def second_half_share(
    snapshot_steps: np.ndarray, snapshot_optimal: np.ndarray, steps: int
) -> float:
    """The share of the snapshots after half of ``steps`` whose greedy policy is optimal.

    With no snapshot after half the steps (fewer than two snapshots), the last one's.
    """
    late = np.asarray(snapshot_steps) > steps / 2
    if not late.any():
        late[-1] = True
    return float(np.asarray(snapshot_optimal)[late].mean())


def measure(agent: Any, steps: int, size: int) -> dict[str, Any]:
    """Train ``agent`` for ``steps`` steps on the grid of side ``size`` and measure the run.

    Returns:
        ``steps`` and ``curve`` (the running average reward), ``average`` (the training mean
        reward), ``greedy`` (the final greedy :data:`WALK_STEPS`-step average) and ``optimal``, the snapshot
        arrays of :func:`train_with_snapshots`, ``second_half_optimal`` (the share of snapshots
        after half the steps that are optimal), ``ns_per_step``, ``path``, and the
        :func:`delay_estimate`. With a ``greedy_window``, the averaged table's readouts too:
        ``greedy``, ``optimal``, ``second_half_optimal`` and the snapshot arrays, in the entry
        :data:`AVERAGED` (:func:`averaged_readout` puts them in place of the others).
    """
    run = train_with_snapshots(agent, steps, size)
    rewards = run.pop("rewards")
    points, curve = running_average(rewards)
    out = {
        "steps": points,
        "curve": curve,
        "average": float(rewards.mean()),
        "ns_per_step": 1e9 * run.pop("learn_seconds") / steps,
        **run,
        **delay_estimate(agent),
    }
    out.update(_readouts(run, run["snapshot_steps"], steps))
    if AVERAGED in run:
        out[AVERAGED] = {**run[AVERAGED], **_readouts(run[AVERAGED], run["snapshot_steps"], steps)}
    return out


def _readouts(snapshots: dict[str, Any], marks: np.ndarray, steps: int) -> dict[str, Any]:
    """A table's final ``greedy`` and ``optimal`` and its ``second_half_optimal`` share."""
    return {
        "greedy": float(snapshots["snapshot_greedy"][-1]),
        "optimal": bool(snapshots["snapshot_optimal"][-1]),
        "second_half_optimal": second_half_share(marks, snapshots["snapshot_optimal"], steps),
    }


def snapshot_curves(condition: str, seed: int, result: dict[str, Any]) -> list[Curve]:
    """A run's two curves for ``curves.csv``: its average reward, and its snapshots' optimality.

    ``result`` is :func:`measure`'s (``steps``, ``curve``, ``snapshot_steps``,
    ``snapshot_optimal``); the second curve's metric is ``greedy_optimal`` (1.0 where the
    snapshot's greedy policy walks the optimal loop).
    """
    return [
        Curve(condition, seed, result["steps"], result["curve"]),
        Curve(
            condition,
            seed,
            result["snapshot_steps"],
            np.asarray(result["snapshot_optimal"]).astype(np.float64),
            "greedy_optimal",
        ),
    ]


def current_readout(result: dict[str, Any]) -> dict[str, Any]:
    """A :func:`measure` result with the readouts of the current table only (as MMQ acts)."""
    return {key: value for key, value in result.items() if key != AVERAGED}


def averaged_readout(result: dict[str, Any]) -> dict[str, Any]:
    """A :func:`measure` result whose greedy readouts are the averaged table's (greedy window).

    Raises:
        ValueError: the run kept no averaged table.
    """
    if AVERAGED not in result:
        raise ValueError("the run kept no averaged table (an MMQ run without greedy_window)")
    return {**current_readout(result), **result[AVERAGED]}


_WARMED: set[str] = set()
"""The kinds of agent already warmed up in this process (see :func:`warm_up`)."""


def warm_up(make: Callable[[], Any], steps: int, kind: str) -> None:
    """Train a throw-away agent ``make()`` for ``min(steps, WARM_UP)`` steps, untimed, once.

    The first ``learn`` of a compiled agent in a process loads its kernels (seconds); the
    warm-up pays that, so ns/step measures training alone. It is done once per ``kind`` of
    agent (its kernels) in a process: a worker's later runs of that kind find them loaded.
    """
    if kind not in _WARMED:
        make().learn(min(steps, WARM_UP), log_interval=None)
        _WARMED.add(kind)
