"""Sweeps of your own: agents × envs × delay distributions × seeds, defined in one file.

``delayed-rl sweep FILE`` (or :func:`load_sweep` and :func:`run_sweep`) answers "which agent
copes with which delay on my envs?": it trains every agent on every env under every delay for
every seed, runs each trained agent's greedy policy, and writes into the output folder
``results.csv`` (one row per run), ``summary.csv`` and ``summary.md`` (mean and 95 % confidence
interval over the seeds) and one figure per env, ``eval_reward_<env>.png``.

**The sweep file.** YAML (``.yaml`` or ``.yml``; reading it needs the ``sweep`` extra, PyYAML)
or JSON (``.json``), holding one mapping with the keys below. Every key and value is checked
before anything runs: a value of the wrong type is a ``TypeError``, a wrong value (an unknown
name, a number out of range, an unknown key anywhere) a ``ValueError``, and the message names
the field (``agents[1].kwargs.gamma``), the value and what is allowed.

``agents`` (required)
    A non-empty list. Each entry is an agent's name, or a mapping with the keys

    - ``name`` (required): one of the library's agents — ``q`` (:class:`~delayed_rl.agents.QLearning`),
      ``fixed`` (:class:`~delayed_rl.agents.FixedDelayQLearning`, which needs
      ``delay_estimate``), ``mmq`` (:class:`~delayed_rl.agents.MultipleModelQLearning`),
      ``deconv`` (:class:`~delayed_rl.agents.DeconvolutionQLearning`), ``oracle``
      (:class:`~delayed_rl.agents.OracleQLearning`) and ``expected-credit``
      (:class:`~delayed_rl.agents.ExpectedCreditQLearning`, which needs ``delay``) — or a
      stable-baselines3 algorithm, ``sb3:A2C``, ``sb3:DDPG``, ``sb3:DQN``, ``sb3:PPO``,
      ``sb3:SAC`` or ``sb3:TD3`` (the ``sb3`` extra);
    - ``kwargs``: the agent's constructor arguments (default none). For the library's agents,
      any argument of the class but ``env`` and ``seed`` (the sweep sets those), e.g.
      ``{learning_rate: 0.1, q_init: 5, max_delay_estimate: 10}``; for SB3, the algorithm's
      (``policy`` defaults to ``MlpPolicy``), e.g. ``{n_steps: 256, learning_rate: 0.001}``;
    - ``label``: its name in the results (default: ``name``); two entries of the same name
      need labels of their own;
    - ``steps``: training steps of its runs (default: the env's ``steps``, else the sweep's);
    - ``envs``: the labels of the envs it runs on (default: all), e.g. to keep tabular agents
      off ``CartPole-v1``.

    *The run's delay as an argument.* A ``kwargs`` value that is one of these strings is
    replaced, in each run, by the run's reward delay (the delay entry's ``reward``;
    ``Constant(0)`` when the entry delays no reward):

    - ``$delay``: the distribution itself, a :class:`~delayed_rl.delays.Delay` (for
      ``expected-credit``'s ``delay``, or ``deconv``'s to know the delay instead of learning it);
    - ``$delay_mean``: its mean, a float;
    - ``$delay_steps``: its mean rounded to an integer (for ``fixed``'s ``delay_estimate``).

    The ``oracle`` needs to know which transition emitted each reward: its envs get a
    :class:`~delayed_rl.wrappers.RewardDelay` with ``record_arrivals=True`` by themselves.

``envs`` (required)
    A non-empty list. Each entry is a Gymnasium id (``delayed_rl/GridWorld-5x5-v0``,
    ``Taxi-v4``, ``CartPole-v1``, or ``module:Id`` to import your own), or a mapping with the
    keys

    - ``id`` (required): the id;
    - ``kwargs``: ``gym.make``'s keyword arguments (default none), e.g. ``{size: 7}``; the
      delays come from ``delays``, so ``reward_delay``, ``observation_delay`` and
      ``action_delay`` are not allowed here;
    - ``label``: its name in the results (default: ``id``);
    - ``steps``: training steps on it (default: the sweep's; an agent's ``steps`` wins);
    - ``eval_episodes`` or ``eval_steps``: how to evaluate on it (default: the sweep's).

``delays`` (required)
    A non-empty list. Each entry is

    - a number λ ≥ 0: rewards delayed by Poisson(λ) steps (``0``: undelayed);
    - a distribution's description, as :meth:`Delay.to_dict() <delayed_rl.delays.Delay.to_dict>`
      writes it and :func:`~delayed_rl.delays.as_delay` reads it: ``{type: Geometric, p: 0.25}``,
      ``{type: Constant, k: 2}``, ``{type: Uniform, low: 0, high: 6}``,
      ``{type: Empirical, pmf: [0.5, 0.3, 0.2]}``, ``{type: Poisson, lam: 3}``: on the rewards;
    - or a mapping with any of the keys ``reward``, ``observation`` and ``action`` (at least
      one), each a number or a description as above — what is delayed, stacked as
      :func:`~delayed_rl.wrappers.wrap_delays` stacks them — and ``label``.

    Its label (default: the distribution, ``Poisson(lam=3)``, prefixed by what it delays when
    that is not only the reward, e.g. ``observation Poisson(lam=2)``) names it in the results.

``seeds`` (default 3)
    A count ``n`` (seeds ``0 .. n − 1``) or a list of distinct integers ≥ 0. Seed ``s`` seeds
    the agent (``seed=s``: its random choices and its training env's first reset, delays
    included); the evaluation env is reset with seed ``s`` + :data:`EVAL_SEED_OFFSET`.

``steps`` (default 100 000)
    Training steps per run (``learn(steps)``; SB3's on-policy algorithms round up to whole
    rollouts).

``eval_episodes`` or ``eval_steps`` (default ``eval_episodes: 10``)
    The greedy evaluation after training (``predict(obs, deterministic=True)``, no learning,
    on a fresh env under the same delays): that many whole episodes, or that many steps.
    Continuing envs, whose episodes never end (the grid worlds), need ``eval_steps``; an
    episode longer than :data:`MAX_EVAL_EPISODE_STEPS` fails its run.

``name`` (default: the file's name without its suffix)
    The title of ``summary.md``.

An example (``examples/sweep.yaml`` is a commented one that runs in about a minute):

.. code-block:: yaml

    name: delayed rewards on two small worlds
    agents:
      - q
      - {name: mmq, kwargs: {max_delay_estimate: 10}}
      - {name: expected-credit, kwargs: {delay: $delay, max_delay: 30}}
      - {name: fixed, label: fixed at the mean, kwargs: {delay_estimate: $delay_steps}}
    envs:
      - {id: delayed_rl/GridWorld-5x5-v0, eval_steps: 1000}
      - {id: Taxi-v4, steps: 200000}
    delays:
      - 3
      - {type: Geometric, p: 0.25}
      - {observation: 1, label: observations one step late}
    seeds: 3
    steps: 30000
    eval_episodes: 20

YAML anchors share settings between entries (``kwargs: &tabular {q_init: 5}``, then
``kwargs: {<<: *tabular, max_delay_estimate: 10}``).

**Results.** ``results.csv`` has one row per run, with the columns :data:`RESULT_COLUMNS` —
``agent``, ``env``, ``delay`` (the labels), ``seed``, ``steps``, ``train_reward`` (the mean
undelayed reward per step during training: the agent's ``rollout/undelayed_reward_per_step``,
or for SB3 every step its env took), ``eval_reward`` (the greedy evaluation's mean undelayed
return per episode, or its mean undelayed reward per step with ``eval_steps``) and ``wall_s``
(the run's seconds) — then ``eval_unit`` (``episode`` or ``step``: which of the two
``eval_reward`` is) and ``run_id`` (a hash of the run's whole configuration: agent and its
arguments, env and its arguments, delays, seed, steps, evaluation). ``summary.csv`` has, per
(agent, env, delay), the seeds and the mean and 95 % CI half-width (Student t,
:func:`~delayed_rl.experiments.runner.mean_ci95`) of both rewards; ``summary.md`` shows the
evaluation and training rewards as an agent × delay table per env, the best agent per delay in
bold, beside the env's figure (the ``plot`` extra, matplotlib: mean and 95 % CI bars of the
evaluation reward by delay, one colour per agent).

**Resuming.** Each run's row is appended to ``results.csv`` as it finishes. Rerunning a sweep
with the same output folder skips the runs already there — matched by agent, env, delay, seed
and ``run_id``, so a run whose configuration changed (more steps, another argument) runs again
— and appends the rest; an interrupted sweep keeps what finished. Rows of runs no longer in
the file are kept in ``results.csv`` (after the sweep's own, which are in the file's order:
agent, env, delay, seed), but left out of the summary.

**Determinism and backends.** Every run builds its env and agent from its own configuration
and seed, so the numbers (all but ``wall_s``) are the same whatever runs them: in this process
(``workers=1``), on joblib's process pool (``workers=N``), or on a Ray or Dask cluster
(``backend="ray"``/``"dask"``, local or at ``address``; see
:func:`~delayed_rl.experiments.runner.iter_tasks`). SB3 runs use one torch thread, so their
floating-point sums do not depend on the machine's thread count either.
"""

from __future__ import annotations

import contextlib
import csv
import difflib
import hashlib
import inspect
import json
import math
import numbers
import os
import re
import sys
import textwrap
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym

import delayed_rl  # noqa: F401  (registers the env ids)
from delayed_rl._validation import check_choice, check_int, check_real
from delayed_rl.delays import Delay, as_delay
from delayed_rl.experiments.runner import iter_tasks, mean_ci95

__all__ = [
    "AGENTS",
    "RESULT_COLUMNS",
    "SB3_ALGORITHMS",
    "RunError",
    "Sweep",
    "SweepOutcome",
    "check_sweep",
    "evaluate",
    "load_sweep",
    "make_env",
    "make_model",
    "parse_sweep",
    "read_sweep_file",
    "resolve_placeholders",
    "run_sweep",
    "run_sweep_task",
]

#: The library's agents by the names a sweep file, and ``delayed-rl train --agent``, use.
AGENTS = {
    "q": "QLearning",
    "fixed": "FixedDelayQLearning",
    "mmq": "MultipleModelQLearning",
    "deconv": "DeconvolutionQLearning",
    "oracle": "OracleQLearning",
    "expected-credit": "ExpectedCreditQLearning",
}
#: The agents whose env must record which transition emitted each reward.
ARRIVAL_AGENTS = ("oracle",)
#: The stable-baselines3 algorithms a sweep runs, as ``sb3:NAME``.
SB3_ALGORITHMS = ("A2C", "DDPG", "DQN", "PPO", "SAC", "TD3")
SB3_PREFIX = "sb3:"
#: What a delay entry may delay, in the order :func:`~delayed_rl.wrappers.wrap_delays` stacks.
DELAY_KINDS = ("action", "observation", "reward")
#: The ``kwargs`` values replaced by the run's reward delay (see the module docstring).
PLACEHOLDERS = ("$delay", "$delay_mean", "$delay_steps")
#: The columns of ``results.csv`` that every sweep writes, in this order.
RESULT_COLUMNS = ("agent", "env", "delay", "seed", "steps", "train_reward", "eval_reward", "wall_s")
#: The columns after them: which ``eval_reward`` it is, and the run's configuration hash.
EXTRA_COLUMNS = ("eval_unit", "run_id")
SUMMARY_COLUMNS = (
    "agent",
    "env",
    "delay",
    "seeds",
    "train_reward_mean",
    "train_reward_ci95",
    "eval_reward_mean",
    "eval_reward_ci95",
    "eval_unit",
)
DEFAULT_SEEDS = 3
DEFAULT_STEPS = 100_000
DEFAULT_EVAL_EPISODES = 10
#: Added to a run's seed to seed its evaluation env (training and evaluation differ).
EVAL_SEED_OFFSET = 1_000_000
#: The longest evaluation episode: one that runs longer fails its run (a continuing env).
MAX_EVAL_EPISODE_STEPS = 100_000

_TOP_KEYS = ("name", "agents", "envs", "delays", "seeds", "steps", "eval_episodes", "eval_steps")
_AGENT_KEYS = ("name", "label", "kwargs", "steps", "envs")
_ENV_KEYS = ("id", "label", "kwargs", "steps", "eval_episodes", "eval_steps")
_DELAY_KEYS = (*DELAY_KINDS, "label")
_ENV_DELAY_KWARGS = ("action_delay", "observation_delay", "reward_delay")
_NO_DELAY = {"type": "Constant", "k": 0}


# ---------------------------------------------------------------------------------- the plan
@dataclass(frozen=True)
class Evaluation:
    """How a trained agent is evaluated: ``count`` greedy episodes, or ``count`` steps."""

    unit: str  # "episode" or "step"
    count: int


@dataclass(frozen=True)
class SweepAgent:
    """One entry of ``agents``: a library agent's name or ``sb3:ALGO``, and its arguments."""

    name: str
    label: str
    kwargs: dict[str, Any]
    steps: int | None = None
    envs: tuple[str, ...] | None = None


@dataclass(frozen=True)
class SweepEnv:
    """One entry of ``envs``: a Gymnasium id, ``gym.make``'s arguments and its overrides."""

    id: str
    label: str
    kwargs: dict[str, Any]
    steps: int | None = None
    evaluation: Evaluation | None = None


@dataclass(frozen=True)
class SweepDelay:
    """One entry of ``delays``: the ``to_dict()`` description of each delay, by what it delays."""

    label: str
    delays: dict[str, dict[str, Any]]


@dataclass(frozen=True)
class Sweep:
    """A checked sweep file (see the module docstring); :meth:`runs` lists its runs."""

    name: str
    agents: tuple[SweepAgent, ...]
    envs: tuple[SweepEnv, ...]
    delays: tuple[SweepDelay, ...]
    seeds: tuple[int, ...] = tuple(range(DEFAULT_SEEDS))
    steps: int = DEFAULT_STEPS
    evaluation: Evaluation = Evaluation("episode", DEFAULT_EVAL_EPISODES)
    source: str = "sweep"

    def runs(self) -> list[dict[str, Any]]:
        """One task per (agent, env, delay, seed), in that nesting: what :func:`run_sweep_task` runs.

        Returns:
            Dicts with the run's labels (``agent``, ``env``, ``delay``), ``seed``, ``run_id``
            and ``config``: everything the run reads, JSON-able (its hash is ``run_id``).
        """
        tasks = []
        for agent in self.agents:
            for env in self.envs:
                if agent.envs is not None and env.label not in agent.envs:
                    continue
                for delay in self.delays:
                    tasks += [self._task(agent, env, delay, seed) for seed in self.seeds]
        return tasks

    def _task(
        self, agent: SweepAgent, env: SweepEnv, delay: SweepDelay, seed: int
    ) -> dict[str, Any]:
        steps = next(s for s in (agent.steps, env.steps, self.steps) if s is not None)
        evaluation = env.evaluation or self.evaluation
        config = {
            "agent": {"name": agent.name, "kwargs": agent.kwargs},
            "env": {"id": env.id, "kwargs": env.kwargs},
            "delays": delay.delays,
            "seed": seed,
            "steps": steps,
            "eval": {"unit": evaluation.unit, "count": evaluation.count},
        }
        text = json.dumps(config, sort_keys=True, separators=(",", ":"))
        run_id = hashlib.sha256(text.encode()).hexdigest()[:16]
        labels = {"agent": agent.label, "env": env.label, "delay": delay.label, "seed": seed}
        return {**labels, "run_id": run_id, "config": config}


# ---------------------------------------------------------------------------------- reading
def read_sweep_file(path: str | Path) -> Any:
    """The content of a sweep file: YAML for ``.yaml``/``.yml``, JSON for ``.json``.

    Raises:
        OSError: the file cannot be read (e.g. there is none).
        ValueError: its suffix is none of those, or its text is not valid YAML or JSON.
        RuntimeError: it is YAML and PyYAML (the ``sweep`` extra) is not installed.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".yaml", ".yml", ".json"):
        raise ValueError(f"a sweep file must end in .yaml, .yml or .json, got {str(path)!r}")
    text = path.read_text(encoding="utf-8")
    if suffix == ".json":
        try:
            return json.loads(text)
        except json.JSONDecodeError as error:
            raise ValueError(f"{path} is not valid JSON: {error}") from None
    try:
        import yaml
    except ImportError:
        raise RuntimeError(
            f"reading the YAML sweep file {path} needs PyYAML: pip install 'delayed-rl[sweep]' "
            "(or write the sweep as .json)"
        ) from None
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as error:
        raise ValueError(f"{path} is not valid YAML: {' '.join(str(error).split())}") from None


def load_sweep(path: str | Path, check: bool = True) -> Sweep:
    """Read, parse and (with ``check``) try out a sweep file: :func:`parse_sweep`, :func:`check_sweep`.

    Args:
        path: the ``.yaml``, ``.yml`` or ``.json`` file.
        check: build every (agent, env, delay) once before returning, so that an argument the
            agent refuses, or an env it cannot use, fails now rather than in the middle.

    Raises:
        OSError, RuntimeError: see :func:`read_sweep_file` (and, with ``check``, a missing
            extra such as stable-baselines3).
        TypeError, ValueError: the file is wrong; the message starts with its path.
    """
    data = read_sweep_file(path)
    try:
        sweep = parse_sweep(data, name=Path(path).stem, source=str(path))
        if check:
            check_sweep(sweep)
    except TypeError as error:
        raise TypeError(f"{path}: {error}") from None
    except ValueError as error:
        raise ValueError(f"{path}: {error}") from None
    return sweep


def parse_sweep(data: Any, name: str = "sweep", source: str = "sweep") -> Sweep:
    """Check a sweep file's content (a mapping, see the module docstring) and return its plan.

    Args:
        data: what :func:`read_sweep_file` returned (or the same structure built in Python).
        name: the sweep's name when the content gives none.
        source: where it came from, for ``summary.md``.

    Raises:
        TypeError: a field has the wrong type.
        ValueError: a field has a wrong value, or there is an unknown key.
    """
    data = _mapping("the sweep file", data)
    _check_keys("the sweep file", data, _TOP_KEYS, required=("agents", "envs", "delays"))
    agents = _entries("agents", data["agents"], _parse_agent)
    envs = _entries("envs", data["envs"], _parse_env)
    delays = _entries("delays", data["delays"], _parse_delay)
    env_labels = tuple(env.label for env in envs)
    for i, agent in enumerate(agents):
        for j, label in enumerate(agent.envs or ()):
            check_choice(f"agents[{i}].envs[{j}] (an env label)", label, env_labels)
    return Sweep(
        name=_text("name", data.get("name", name)),
        agents=agents,
        envs=envs,
        delays=delays,
        seeds=_parse_seeds(data.get("seeds", DEFAULT_SEEDS)),
        steps=check_int("steps", data.get("steps", DEFAULT_STEPS), 1),
        evaluation=_parse_evaluation("", data) or Evaluation("episode", DEFAULT_EVAL_EPISODES),
        source=source,
    )


def _mapping(where: str, value: Any, what: str = "a mapping") -> Mapping[str, Any]:
    if not isinstance(value, Mapping):
        raise TypeError(f"{where} must be {what}, got {value!r} ({type(value).__name__})")
    return value


def _check_keys(
    where: str, mapping: Mapping[str, Any], allowed: Sequence[str], required: Sequence[str] = ()
) -> None:
    """Refuse a key of ``mapping`` that is not ``allowed``, and a ``required`` one missing."""
    for key in mapping:
        if key not in allowed:
            close = difflib.get_close_matches(str(key), allowed, n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise ValueError(
                f"{where} has the unknown key {key!r}; allowed: {', '.join(allowed)}{hint}"
            )
    for key in required:
        if key not in mapping:
            raise ValueError(f"{where} must have the key {key!r}, got the keys {list(mapping)}")


def _text(where: str, value: Any) -> str:
    if not isinstance(value, str):
        raise TypeError(f"{where} must be a string, got {value!r} ({type(value).__name__})")
    if not value.strip():
        raise ValueError(f"{where} must be a non-empty string, got {value!r}")
    return value


def _entries(where: str, value: Any, parse: Callable[[str, Any], Any]) -> tuple[Any, ...]:
    """Each entry of the list ``value`` parsed by ``parse``; their labels must differ."""
    if not isinstance(value, list):
        raise TypeError(f"{where} must be a list, got {value!r} ({type(value).__name__})")
    if not value:
        raise ValueError(f"{where} must be a non-empty list, got []")
    entries = tuple(parse(f"{where}[{i}]", entry) for i, entry in enumerate(value))
    first: dict[str, int] = {}
    for i, entry in enumerate(entries):
        if entry.label in first:
            raise ValueError(
                f"{where}[{i}] has the label {entry.label!r} of {where}[{first[entry.label]}]: "
                "give one of them a 'label' of its own"
            )
        first[entry.label] = i
    return entries


def _plain(where: str, value: Any) -> Any:
    """``value`` after checking that it is JSON-like: None, bool, number, string, list, mapping."""
    if value is None or isinstance(value, (bool, str)):
        return value
    if isinstance(value, numbers.Integral):
        return int(value)
    if isinstance(value, numbers.Real):
        return check_real(where, value)
    if isinstance(value, list):
        return [_plain(f"{where}[{i}]", item) for i, item in enumerate(value)]
    if isinstance(value, Mapping):
        return {_text(f"{where} key", k): _plain(f"{where}.{k}", v) for k, v in value.items()}
    raise TypeError(
        f"{where} must be a number, string, bool, null, list or mapping, got {value!r} "
        f"({type(value).__name__})"
    )


def _kwargs(where: str, value: Any, refused: Sequence[str], why: str) -> dict[str, Any]:
    """A ``kwargs`` mapping, JSON-like, without the ``refused`` names (``why`` says why)."""
    kwargs = dict(_plain(where, _mapping(where, value)))
    for name in refused:
        if name in kwargs:
            raise ValueError(f"{where} must not set {name!r}: {why}")
    return kwargs


def _agent_class(name: str) -> type:
    from delayed_rl import agents

    return getattr(agents, AGENTS[name])


def _agent_name(where: str, value: Any) -> str:
    name = _text(where, value)
    allowed = (*AGENTS, *(SB3_PREFIX + algorithm for algorithm in SB3_ALGORITHMS))
    if name not in allowed:
        close = difflib.get_close_matches(name, allowed, n=1)
        hint = f"; did you mean {close[0]!r}?" if close else ""
        raise ValueError(f"{where} must be one of {allowed}, got {name!r}{hint}")
    return name


def _check_agent_kwargs(where: str, name: str, kwargs: Mapping[str, Any]) -> None:
    """Refuse a library agent's unknown argument, and a placeholder that is not one."""
    for key, value in kwargs.items():
        if isinstance(value, str) and value.startswith("$") and value not in PLACEHOLDERS:
            raise ValueError(
                f"{where}.{key} must be one of the placeholders {PLACEHOLDERS} or a value that "
                f"does not start with '$', got {value!r}"
            )
    if name.startswith(SB3_PREFIX):
        return  # the algorithm's own check, when check_sweep builds it, names the argument
    cls = _agent_class(name)
    allowed = [p for p in inspect.signature(cls).parameters if p not in ("env", "seed")]
    for key in kwargs:
        if key not in allowed:
            raise ValueError(
                f"{where} has {key!r}, which is not an argument of {cls.__name__}; allowed: "
                f"{', '.join(allowed)}"
            )


def _parse_agent(where: str, entry: Any) -> SweepAgent:
    if isinstance(entry, str):
        entry = {"name": entry}
    entry = _mapping(where, entry, "an agent's name or a mapping with 'name'")
    _check_keys(where, entry, _AGENT_KEYS, required=("name",))
    name = _agent_name(f"{where}.name", entry["name"])
    why = "the sweep makes the env and seeds every run from 'seeds'"
    kwargs = _kwargs(f"{where}.kwargs", entry.get("kwargs", {}), ("env", "seed"), why)
    _check_agent_kwargs(f"{where}.kwargs", name, kwargs)
    envs = entry.get("envs")
    if envs is not None:
        if not isinstance(envs, list):
            raise TypeError(
                f"{where}.envs must be a list of env labels, got {envs!r} ({type(envs).__name__})"
            )
        if not envs:
            raise ValueError(f"{where}.envs must be a non-empty list of env labels, got []")
        envs = tuple(_text(f"{where}.envs[{i}]", label) for i, label in enumerate(envs))
    return SweepAgent(
        name=name,
        label=_text(f"{where}.label", entry.get("label", name)),
        kwargs=kwargs,
        steps=check_int(f"{where}.steps", entry.get("steps"), 1, optional=True),
        envs=envs,
    )


def _check_env_id(where: str, env_id: Any) -> str:
    env_id = _text(where, env_id)
    if env_id in gym.registry or ":" in env_id:
        return env_id
    close = difflib.get_close_matches(env_id, list(gym.registry), n=3)
    hint = f"; did you mean {', '.join(close)}?" if close else "; see delayed-rl list"
    raise ValueError(f"{where} must be a registered Gymnasium id, got {env_id!r}{hint}")


def _parse_env(where: str, entry: Any) -> SweepEnv:
    if isinstance(entry, str):
        entry = {"id": entry}
    entry = _mapping(where, entry, "a Gymnasium id or a mapping with 'id'")
    _check_keys(where, entry, _ENV_KEYS, required=("id",))
    env_id = _check_env_id(f"{where}.id", entry["id"])
    why = "set the delays in 'delays'"
    kwargs = _kwargs(f"{where}.kwargs", entry.get("kwargs", {}), _ENV_DELAY_KWARGS, why)
    return SweepEnv(
        id=env_id,
        label=_text(f"{where}.label", entry.get("label", env_id)),
        kwargs=kwargs,
        steps=check_int(f"{where}.steps", entry.get("steps"), 1, optional=True),
        evaluation=_parse_evaluation(f"{where}.", entry),
    )


def _parse_evaluation(prefix: str, entry: Mapping[str, Any]) -> Evaluation | None:
    """``eval_episodes`` or ``eval_steps`` of ``entry`` (``None``: neither is given)."""
    episodes, steps = entry.get("eval_episodes"), entry.get("eval_steps")
    if episodes is not None and steps is not None:
        raise ValueError(
            f"{prefix}eval_episodes and {prefix}eval_steps are both given ({episodes!r}, "
            f"{steps!r}): give one of them"
        )
    if episodes is not None:
        return Evaluation("episode", check_int(f"{prefix}eval_episodes", episodes, 1))
    if steps is not None:
        return Evaluation("step", check_int(f"{prefix}eval_steps", steps, 1))
    return None


def _distribution(where: str, value: Any) -> dict[str, Any]:
    """A delay as its ``to_dict()`` description: a number is a Poisson mean."""
    if isinstance(value, numbers.Real) and not isinstance(value, bool):
        check_real(where, value, 0.0, note=" (a Poisson mean)")
    elif not isinstance(value, Mapping):
        raise TypeError(
            f"{where} must be a number (a Poisson mean) or a distribution's description such as "
            f"{{type: Geometric, p: 0.25}}, got {value!r} ({type(value).__name__})"
        )
    try:
        return as_delay(dict(value) if isinstance(value, Mapping) else value, where).to_dict()
    except (TypeError, ValueError) as error:  # a parameter's check names only the parameter
        if str(error).startswith(where):
            raise
        raise type(error)(f"{where}: {error}") from None


def _distribution_label(description: Mapping[str, Any]) -> str:
    """``Poisson(lam=3)``, ``Geometric(p=0.25)``: a description as text."""
    params = ", ".join(
        f"{key}={value:g}" if isinstance(value, float) else f"{key}={value}"
        for key, value in description.items()
        if key != "type"
    )
    return f"{description['type']}({params})"


def _parse_delay(where: str, entry: Any) -> SweepDelay:
    if not isinstance(entry, Mapping) or "type" in entry:
        description = _distribution(where, entry)
        return SweepDelay(_distribution_label(description), {"reward": description})
    _check_keys(where, entry, _DELAY_KEYS)
    delays = {
        kind: _distribution(f"{where}.{kind}", entry[kind]) for kind in DELAY_KINDS if kind in entry
    }
    if not delays:
        raise ValueError(f"{where} must delay at least one of {DELAY_KINDS}, got {dict(entry)!r}")
    if list(delays) == ["reward"]:
        label = _distribution_label(delays["reward"])
    else:
        label = " + ".join(f"{kind} {_distribution_label(d)}" for kind, d in delays.items())
    return SweepDelay(_text(f"{where}.label", entry.get("label", label)), delays)


def _parse_seeds(value: Any) -> tuple[int, ...]:
    if not isinstance(value, list):
        count = check_int("seeds", value, 1, note=" (a count), or a list of seeds")
        return tuple(range(count))
    if not value:
        raise ValueError("seeds must be a count >= 1 or a non-empty list of seeds, got []")
    seeds = tuple(check_int(f"seeds[{i}]", seed, 0) for i, seed in enumerate(value))
    for i, seed in enumerate(seeds):
        if seed in seeds[:i]:
            raise ValueError(f"seeds[{i}] repeats the seed {seed}: seeds must differ")
    return seeds


def check_sweep(sweep: Sweep) -> None:
    """Build every (agent, env, delay) of ``sweep`` once, with its first seed, and close it.

    An argument value an agent refuses, or an env it cannot use (a tabular agent on a ``Box``
    observation space), fails here, before any run, naming the agent, env and delay.

    Raises:
        TypeError, ValueError: one of them cannot be built; the message says which and why.
        RuntimeError: an extra the sweep needs is not installed (stable-baselines3).
    """
    seen = set()
    for task in sweep.runs():
        combination = (task["agent"], task["env"], task["delay"])
        if combination in seen:
            continue
        seen.add(combination)
        where = f"agent {task['agent']!r} on env {task['env']!r} under delay {task['delay']!r}"
        env = None
        try:
            env = make_env(task["config"])
            make_model(task["config"], env)
        except TypeError as error:
            raise TypeError(f"{where}: {_one_line(error)}") from None
        except (ValueError, AssertionError, ImportError, gym.error.Error) as error:
            raise ValueError(f"{where}: {_one_line(error)}") from None
        finally:
            if env is not None:
                env.close()


def _one_line(error: BaseException) -> str:
    return " ".join(str(error).split()) or type(error).__name__


# ---------------------------------------------------------------------------------- one run
class RunError(RuntimeError):
    """A run of a sweep failed: the message names the run and the original error."""


def reward_delay(config: Mapping[str, Any]) -> Delay:
    """The run's reward delay: its ``reward`` delay, or ``Constant(0)`` when it has none."""
    return as_delay(config["delays"].get("reward", _NO_DELAY))


def resolve_placeholders(kwargs: Mapping[str, Any], delay: Delay) -> dict[str, Any]:
    """``kwargs`` with each :data:`PLACEHOLDERS` value replaced by ``delay`` (see the docstring)."""
    values = {"$delay": delay, "$delay_mean": delay.mean, "$delay_steps": round(delay.mean)}
    return {
        key: values[value] if isinstance(value, str) and value in values else value
        for key, value in kwargs.items()
    }


def make_env(config: Mapping[str, Any]) -> gym.Env:
    """The run's env: ``gym.make(id, **kwargs)`` behind the run's delays.

    Action and observation delays are stacked by :func:`~delayed_rl.wrappers.wrap_delays`; the
    reward delay, outermost, is a :class:`~delayed_rl.wrappers.RewardDelay` that records
    arrivals for the agents of :data:`ARRIVAL_AGENTS` (which get ``Constant(0)`` when the run
    delays no reward).
    """
    from delayed_rl.wrappers import RewardDelay, wrap_delays

    delays = config["delays"]
    env = gym.make(config["env"]["id"], **config["env"]["kwargs"])
    env = wrap_delays(
        env, action_delay=delays.get("action"), observation_delay=delays.get("observation")
    )
    arrivals = config["agent"]["name"] in ARRIVAL_AGENTS
    if "reward" not in delays and not arrivals:
        return env
    return RewardDelay(env, reward_delay(config), record_arrivals=arrivals)


def _sb3_class(name: str) -> type:
    try:
        import stable_baselines3
    except ImportError:
        raise RuntimeError(
            f"agent {name!r} needs stable-baselines3: pip install 'delayed-rl[sb3]'"
        ) from None
    return getattr(stable_baselines3, name.removeprefix(SB3_PREFIX))


def make_model(config: Mapping[str, Any], env: gym.Env) -> Any:
    """The run's agent on ``env``, seeded with the run's seed, its placeholders resolved."""
    name = config["agent"]["name"]
    kwargs = resolve_placeholders(config["agent"]["kwargs"], reward_delay(config))
    if name.startswith(SB3_PREFIX):
        kwargs = {"policy": "MlpPolicy", **kwargs}
        return _sb3_class(name)(env=env, seed=config["seed"], **kwargs)
    return _agent_class(name)(env, seed=config["seed"], **kwargs)


class UndelayedRewardTally(gym.Wrapper):
    """Counts the steps taken and sums their undelayed rewards (an SB3 run's training reward).

    The undelayed reward is ``info["undelayed_reward"]`` of the reward-delay wrapper, else the
    reward itself.
    """

    def __init__(self, env: gym.Env):
        super().__init__(env)
        self.steps = 0
        self.total = 0.0

    def step(self, action: Any) -> Any:
        """Step the env and count the step's undelayed reward."""
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.steps += 1
        self.total += float(info.get("undelayed_reward", reward))
        return obs, reward, terminated, truncated, info

    @property
    def mean(self) -> float:
        """The mean undelayed reward per step so far (NaN before any step)."""
        return self.total / self.steps if self.steps else math.nan


def train(config: Mapping[str, Any]) -> tuple[Any, float]:
    """Train the run's agent for its steps; return it and its mean undelayed reward per step."""
    if config["agent"]["name"].startswith(SB3_PREFIX):
        tally = UndelayedRewardTally(make_env(config))
        model = make_model(config, tally)
        model.learn(total_timesteps=config["steps"])
        return model, tally.mean
    model = make_model(config, make_env(config))
    model.learn(config["steps"], log_interval=None)
    return model, float(model.logger.dumps[-1]["rollout/undelayed_reward_per_step"])


def _greedy_step(model: Any, env: gym.Env, obs: Any) -> tuple[Any, float, bool]:
    """One greedy step: the next observation, the undelayed reward, whether the episode ended."""
    action, _ = model.predict(obs, deterministic=True)
    if isinstance(env.action_space, gym.spaces.Discrete):
        action = int(action)
    obs, reward, terminated, truncated, info = env.step(action)
    return obs, float(info.get("undelayed_reward", reward)), bool(terminated or truncated)


def evaluate(model: Any, env: gym.Env, evaluation: Evaluation, seed: int) -> float:
    """The greedy policy's mean undelayed return per episode, or reward per step, on ``env``.

    Args:
        model: anything with SB3's ``predict(obs, deterministic=True)``.
        env: a fresh env (it is reset here, with ``seed`` + :data:`EVAL_SEED_OFFSET`).
        evaluation: ``count`` episodes (``unit="episode"``) or steps (``"step"``).
        seed: the run's seed.

    Raises:
        ValueError: with episodes, one runs longer than :data:`MAX_EVAL_EPISODE_STEPS`.
    """
    obs, _ = env.reset(seed=seed + EVAL_SEED_OFFSET)
    if evaluation.unit == "step":
        total = 0.0
        for _ in range(evaluation.count):
            obs, reward, ended = _greedy_step(model, env, obs)
            total += reward
            if ended:
                obs, _ = env.reset()
        return total / evaluation.count
    returns = []
    for _ in range(evaluation.count):
        episode_return, ended, steps = 0.0, False, 0
        while not ended:
            if steps == MAX_EVAL_EPISODE_STEPS:
                raise ValueError(
                    f"no evaluation episode ended within {MAX_EVAL_EPISODE_STEPS} steps: it looks "
                    "like a continuing env; evaluate it with eval_steps"
                )
            obs, reward, ended = _greedy_step(model, env, obs)
            episode_return, steps = episode_return + reward, steps + 1
        returns.append(episode_return)
        obs, _ = env.reset()
    return sum(returns) / len(returns)


@contextlib.contextmanager
def _one_torch_thread(config: Mapping[str, Any]) -> Iterator[None]:
    """For an SB3 run: torch on one thread (sums that do not depend on the thread count)."""
    if not config["agent"]["name"].startswith(SB3_PREFIX):
        yield
        return
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(threads)


def run_sweep_task(task: Mapping[str, Any]) -> dict[str, Any]:
    """Train and evaluate one run of :meth:`Sweep.runs`; return its ``results.csv`` row.

    Raises:
        RunError: the run failed; the message names it and the original error.
    """
    config = task["config"]
    started = time.perf_counter()
    try:
        evaluation = Evaluation(**config["eval"])
        with _one_torch_thread(config):
            model, train_reward = train(config)
            model.env.close()  # the training env (SB3's VecEnv around it)
            with contextlib.closing(make_env(config)) as env:
                eval_reward = evaluate(model, env, evaluation, config["seed"])
    except Exception as error:
        run = f"({task['agent']}, {task['env']}, {task['delay']}, seed {task['seed']})"
        raise RunError(f"run {run} failed: {type(error).__name__}: {error}") from error
    return {
        "agent": task["agent"],
        "env": task["env"],
        "delay": task["delay"],
        "seed": task["seed"],
        "steps": config["steps"],
        "train_reward": train_reward,
        "eval_reward": eval_reward,
        "wall_s": round(time.perf_counter() - started, 3),
        "eval_unit": evaluation.unit,
        "run_id": task["run_id"],
    }


# ---------------------------------------------------------------------------------- results
RESULTS_FILE = "results.csv"
_COLUMNS = (*RESULT_COLUMNS, *EXTRA_COLUMNS)


def run_key(row: Mapping[str, Any]) -> tuple[str, ...]:
    """What identifies a run in ``results.csv``: its labels, seed and ``run_id``, as text."""
    return tuple(str(row[column]) for column in ("agent", "env", "delay", "seed", "run_id"))


def read_results(path: Path) -> list[dict[str, str]]:
    """The complete rows of ``path`` (none when there is no such file).

    A row missing a value (a write cut short) is left out, so its run runs again.

    Raises:
        ValueError: the file's columns are not a sweep's (:data:`RESULT_COLUMNS` and the extras).
    """
    if not path.exists():
        return []
    with open(path, newline="", encoding="utf-8") as handle:
        reader = csv.DictReader(handle)
        if reader.fieldnames is None:
            return []
        if tuple(reader.fieldnames) != _COLUMNS:
            raise ValueError(
                f"{path} has the columns {reader.fieldnames}, not a sweep's {list(_COLUMNS)}: "
                "give the sweep another output folder"
            )
        return [row for row in reader if all(row.get(c) not in (None, "") for c in _COLUMNS)]


def write_results(path: Path, rows: Sequence[Mapping[str, Any]]) -> None:
    """Write ``rows`` to ``path`` whole (through a temporary file, so it is never half written)."""
    partial = path.with_name(path.name + ".partial")
    with open(partial, "w", newline="", encoding="utf-8") as handle:
        writer = csv.DictWriter(handle, fieldnames=_COLUMNS)
        writer.writeheader()
        writer.writerows(rows)
    os.replace(partial, path)


def append_result(path: Path, row: Mapping[str, Any]) -> None:
    """Append one finished run's row to ``path`` (which has its header) and flush it."""
    with open(path, "a", newline="", encoding="utf-8") as handle:
        csv.DictWriter(handle, fieldnames=_COLUMNS).writerow(row)


def _in_sweep_order(
    rows: Sequence[Mapping[str, Any]], tasks: Sequence[Mapping[str, Any]]
) -> tuple[list[Mapping[str, Any]], list[Mapping[str, Any]]]:
    """The rows of ``tasks`` in their order, and the others (older runs) in theirs."""
    by_key: dict[tuple[str, ...], Mapping[str, Any]] = {}
    for row in rows:
        by_key.setdefault(run_key(row), row)
    keys = [run_key(task) for task in tasks]
    wanted = set(keys)
    ours = [by_key[key] for key in keys if key in by_key]
    others = [row for key, row in by_key.items() if key not in wanted]
    return ours, others


# ---------------------------------------------------------------------------------- summary
def summarize(rows: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Per (agent, env, delay), in the rows' order: the seeds and both rewards' mean and 95 % CI."""
    groups: dict[tuple[str, str, str], list[Mapping[str, Any]]] = {}
    for row in rows:
        groups.setdefault((row["agent"], row["env"], row["delay"]), []).append(row)
    summary = []
    for (agent, env, delay), runs in groups.items():
        train_mean, train_ci = mean_ci95([float(run["train_reward"]) for run in runs])
        eval_mean, eval_ci = mean_ci95([float(run["eval_reward"]) for run in runs])
        summary.append(
            {
                "agent": agent,
                "env": env,
                "delay": delay,
                "seeds": len(runs),
                "train_reward_mean": train_mean,
                "train_reward_ci95": train_ci,
                "eval_reward_mean": eval_mean,
                "eval_reward_ci95": eval_ci,
                "eval_unit": runs[0]["eval_unit"],
            }
        )
    return summary


def write_summary_csv(path: Path, summary: Sequence[Mapping[str, Any]]) -> None:
    """``summary.csv``: the rows of :func:`summarize`."""
    with open(path, "w", newline="", encoding="utf-8") as handle:
        writer = csv.DictWriter(handle, fieldnames=SUMMARY_COLUMNS)
        writer.writeheader()
        writer.writerows(summary)


def figure_name(env_label: str, taken: Sequence[str] = ()) -> str:
    """The file name of an env's figure: ``eval_reward_<slug>.png``, unlike those ``taken``.

    >>> figure_name("delayed_rl/GridWorld-5x5-v0")
    'eval_reward_delayed-rl-gridworld-5x5-v0.png'
    """
    slug = re.sub(r"[^a-z0-9]+", "-", env_label.lower()).strip("-") or "env"
    name, n = f"eval_reward_{slug}.png", 1
    while name in taken:
        n += 1
        name = f"eval_reward_{slug}-{n}.png"
    return name


def _by_env(summary: Sequence[Mapping[str, Any]]) -> dict[str, list[Mapping[str, Any]]]:
    groups: dict[str, list[Mapping[str, Any]]] = {}
    for row in summary:
        groups.setdefault(row["env"], []).append(row)
    return groups


def _cell(mean: float, ci: float) -> str:
    return f"{mean:.3f} ± {ci:.3f}"


def _markdown(text: str) -> str:
    return str(text).replace("|", "\\|")


def _best(rows: Sequence[Mapping[str, Any]], delay: str, column: str) -> float:
    """The largest ``column`` among the rows of ``delay`` (NaN when none is a number)."""
    values = [row[column] for row in rows if row["delay"] == delay]
    return max((value for value in values if not math.isnan(value)), default=math.nan)


def agent_delay_table(rows: Sequence[Mapping[str, Any]], reward: str) -> list[str]:
    """One env's Markdown table: an agent per row, a delay per column, ``reward`` ± its CI.

    Args:
        rows: the env's rows of :func:`summarize`.
        reward: ``"eval_reward"`` or ``"train_reward"``; each delay's best mean is in bold.
    """
    agents = list(dict.fromkeys(row["agent"] for row in rows))
    delays = list(dict.fromkeys(row["delay"] for row in rows))
    cells = {(row["agent"], row["delay"]): row for row in rows}
    best = {delay: _best(rows, delay, f"{reward}_mean") for delay in delays}
    lines = [
        "| agent | " + " | ".join(_markdown(delay) for delay in delays) + " |",
        "|---" * (len(delays) + 1) + "|",
    ]
    for agent in agents:
        texts = []
        for delay in delays:
            row = cells.get((agent, delay))
            if row is None:
                texts.append("—")
                continue
            text = _cell(row[f"{reward}_mean"], row[f"{reward}_ci95"])
            texts.append(f"**{text}**" if row[f"{reward}_mean"] == best[delay] else text)
        lines.append(f"| {_markdown(agent)} | " + " | ".join(texts) + " |")
    return lines


def render_summary(
    sweep: Sweep, summary: Sequence[Mapping[str, Any]], figures: Mapping[str, str]
) -> str:
    """``summary.md``: per env, the evaluation and training rewards by agent and delay.

    Args:
        sweep: the sweep (its name, source, and size).
        summary: the rows of :func:`summarize`.
        figures: per env label, its figure's file name or a note that it was not drawn.
    """
    seeds = len(sweep.seeds)
    lines = [
        f"# {sweep.name}",
        "",
        f"From `{sweep.source}`: {len(sweep.agents)} agent(s) × {len(sweep.envs)} env(s) × "
        f"{len(sweep.delays)} delay(s) × {seeds} seed(s). Each cell is the mean ± the half-width "
        "of its 95 % confidence interval over the seeds (Student t); `results.csv` has every "
        "run, `summary.csv` these numbers.",
    ]
    for env, rows in _by_env(summary).items():
        unit = rows[0]["eval_unit"]
        lines += [
            "",
            f"## {env}",
            "",
            f"Greedy evaluation: undelayed reward per {unit} (the best agent per delay in bold):",
            "",
            *agent_delay_table(rows, "eval_reward"),
            "",
            "Training: mean undelayed reward per step:",
            "",
            *agent_delay_table(rows, "train_reward"),
        ]
        figure = figures.get(env)
        if figure is not None:
            drawn = figure.endswith(".png")
            lines += ["", f"![{env}: evaluation reward by delay]({figure})" if drawn else figure]
    return "\n".join(lines) + "\n"


def plot_env(path: Path, env: str, rows: Sequence[Mapping[str, Any]]) -> None:
    """One env's figure: per agent, the evaluation reward's mean and 95 % CI bar at each delay.

    Args:
        path: where to save the PNG.
        env: the env's label (the title).
        rows: the env's rows of :func:`summarize`.
    """
    from delayed_rl.experiments import plotting

    plt = plotting._pyplot()
    delays = list(dict.fromkeys(row["delay"] for row in rows))
    agents = list(dict.fromkeys(row["agent"] for row in rows))
    width = min(0.8 / len(agents), 0.2)
    fig, ax = plt.subplots(figsize=(max(8.5, 1.8 * len(delays) + 5.5), 4.4))
    for i, agent in enumerate(agents):
        mine = [row for row in rows if row["agent"] == agent]
        x = [delays.index(row["delay"]) + (i - (len(agents) - 1) / 2) * width for row in mine]
        means = [row["eval_reward_mean"] for row in mine]
        cis = [row["eval_reward_ci95"] for row in mine]
        label = plotting.band_label(agent, min(row["seeds"] for row in mine))
        ax.errorbar(x, means, yerr=cis, marker="o", linestyle="none", capsize=4, label=label)
    ax.set_xticks(range(len(delays)), [textwrap.fill(delay, 18) for delay in delays])
    ax.set_xlim(-0.6, len(delays) - 0.4)
    ax.margins(y=0.15)
    plotting.outside_legend(ax)
    unit = rows[0]["eval_unit"]
    title = f"{env}: greedy evaluation reward by delay"
    plotting._finish(fig, ax, path, title, "delay", f"undelayed reward per {unit}")


def draw_figures(out: Path, summary: Sequence[Mapping[str, Any]]) -> dict[str, str]:
    """Draw :func:`plot_env` for every env into ``out``.

    Returns:
        Per env label, the figure's file name, or a note when matplotlib (the ``plot`` extra)
        is not installed.
    """
    figures: dict[str, str] = {}
    for env, rows in _by_env(summary).items():
        name = figure_name(env, list(figures.values()))
        try:
            plot_env(out / name, env, rows)
        except ImportError:
            name = f"{name} not drawn: install the plot extra, matplotlib"
        figures[env] = name
    return figures


# ---------------------------------------------------------------------------------- running
@dataclass
class SweepOutcome:
    """What :func:`run_sweep` did.

    Attributes:
        out: the output folder.
        runs: the sweep's runs.
        ran: how many of them ran now.
        skipped: how many were already in ``results.csv``.
        wall_s: the seconds it took.
        summary: the rows of ``summary.csv``.
        figures: per env label, its figure's file name (or why it was not drawn).
    """

    out: Path
    runs: int
    ran: int
    skipped: int
    wall_s: float
    summary: list[dict[str, Any]] = field(default_factory=list)
    figures: dict[str, str] = field(default_factory=dict)


@contextlib.contextmanager
def progress_counter(total: int, enabled: bool) -> Iterator[Callable[[], None]]:
    """Yield ``tick()``, to call once per finished run: tqdm's bar on stderr, else a count line.

    Args:
        total: how many runs there are.
        enabled: show the progress at all.
    """
    if not enabled:
        yield lambda: None
        return
    try:
        from tqdm.auto import tqdm
    except ImportError:
        done = 0

        def tick() -> None:
            nonlocal done
            done += 1
            print(f"[sweep] {done}/{total} runs done", file=sys.stderr, flush=True)

        yield tick
        return
    with tqdm(total=total, desc="sweep", unit="run", file=sys.stderr) as bar:
        yield bar.update


def run_sweep(
    sweep: Sweep,
    out: str | Path,
    workers: int | None = None,
    backend: str = "loky",
    address: str | None = None,
    progress: bool = False,
) -> SweepOutcome:
    """Run the runs of ``sweep`` that ``out/results.csv`` lacks; write the results and summary.

    Args:
        sweep: what :func:`load_sweep` (or :func:`parse_sweep`) returned.
        out: the output folder (made if missing); ``results.csv`` there is resumed.
        workers: runs in parallel (``None``: 1 with ``loky``, which runs them in this process;
            every core of the cluster with ``ray`` and ``dask``).
        backend: ``"loky"`` (joblib's process pool), ``"ray"`` or ``"dask"``.
        address: an existing Ray or Dask cluster to run on (``None``: a local one); see
            :func:`~delayed_rl.experiments.runner.iter_tasks`.
        progress: show a progress bar on stderr (tqdm's, else a count line).

    Returns:
        What was run and written.

    Raises:
        TypeError, ValueError: a bad argument, or ``out/results.csv`` is not a sweep's.
        RunError: a run failed (the rows of the runs that finished are kept).
        RuntimeError: the backend's package (Ray, Dask) is not installed.
    """
    if workers is None and backend == "loky":
        workers = 1
    out = Path(out)
    results = out / RESULTS_FILE
    tasks = sweep.runs()
    existing = read_results(results)
    done = {run_key(row) for row in existing}
    pending = [task for task in tasks if run_key(task) not in done]
    finished = iter_tasks(run_sweep_task, pending, workers, backend, address)  # checks the rest
    out.mkdir(parents=True, exist_ok=True)
    write_results(results, existing)  # a clean file to append to, without a row cut short
    started = time.perf_counter()
    if pending:  # (no backend starts for nothing)
        with progress_counter(len(pending), progress) as tick:
            for _, row in finished:
                append_result(results, row)
                tick()
    ours, others = _in_sweep_order(read_results(results), tasks)
    write_results(results, [*ours, *others])
    summary = summarize(ours)
    write_summary_csv(out / "summary.csv", summary)
    figures = draw_figures(out, summary)
    (out / "summary.md").write_text(render_summary(sweep, summary, figures), encoding="utf-8")
    return SweepOutcome(
        out=out,
        runs=len(tasks),
        ran=len(pending),
        skipped=len(tasks) - len(pending),
        wall_s=round(time.perf_counter() - started, 2),
        summary=summary,
        figures=figures,
    )
