"""The sweep file's format: its names and defaults, reading the file, and checking every field.

:func:`~delayed_rl.sweep.reading.read_sweep_file` reads a YAML or JSON file;
:func:`parse_sweep` checks what it holds, field by field, and returns the plan, a :class:`Sweep`,
whose :meth:`Sweep.runs` lists the runs. Every size a file sets is bounded by a stated limit
(``learn()``'s ``MAX_TIMESTEPS``, :data:`MAX_EVAL_STEPS`, :data:`MAX_EVAL_EPISODES`, :data:`~delayed_rl.parallel.pools.MAX_SEED_COUNT`,
:data:`MAX_SWEEP_SEED_VALUE`, :data:`MAX_RUNS`), checked before anything is built or run.
:mod:`delayed_rl.sweep` documents the format.
"""

from __future__ import annotations

import difflib
import hashlib
import inspect
import json
import numbers
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import gymnasium as gym

import delayed_rl  # noqa: F401  (registers the env ids)
from delayed_rl._validation import Limit, check_choice, check_int, check_limit, check_real
from delayed_rl.agents.common.python_loop import MAX_TIMESTEPS
from delayed_rl.agents.registry import CLASS_NAMES, agent_class
from delayed_rl.delays import as_delay
from delayed_rl.parallel.pools import MAX_SEED_COUNT

#: The stable-baselines3 algorithms a sweep runs, as ``sb3:NAME``.
SB3_ALGORITHMS = ("A2C", "DDPG", "DQN", "PPO", "SAC", "TD3")
#: Those of them that learn from rollouts (a reward model relabels their rollout buffer).
SB3_ON_POLICY = ("A2C", "PPO")
SB3_PREFIX = "sb3:"
#: What a delay entry may delay, in the order :func:`~delayed_rl.wrappers.wrap_delays` stacks.
DELAY_KINDS = ("action", "observation", "reward")
#: The ``kwargs`` values replaced by the run's reward delay (see ``docs/sweeps.md``).
PLACEHOLDERS = ("$delay", "$delay_mean", "$delay_steps")
DEFAULT_SEEDS = 3
DEFAULT_STEPS = 100_000
DEFAULT_EVAL_EPISODES = 10

MAX_EVAL_STEPS = Limit(10**9, "MAX_EVAL_STEPS", __name__, "10**9")
"""The most evaluation steps of a run (``eval_steps``)."""
MAX_EVAL_EPISODES = Limit(10**6, "MAX_EVAL_EPISODES", __name__, "10**6")
"""The most evaluation episodes of a run (``eval_episodes``; each at most
:data:`~delayed_rl.sweep.runs.MAX_EVAL_EPISODE_STEPS` steps)."""
MAX_SWEEP_SEED_VALUE = Limit(2**32 - 1, "MAX_SWEEP_SEED_VALUE", __name__, "2**32 - 1")
"""The largest seed: what every agent accepts (stable-baselines3 seeds numpy's legacy generator,
which takes 32 bits)."""
MAX_LABEL_CHARS = Limit(1000, "MAX_LABEL_CHARS", __name__, "1000")
"""The longest name, label or env id in a sweep file (they are written in every row)."""
MAX_RUNS = Limit(100_000, "MAX_RUNS", __name__)
"""The most runs (agents × envs × delays × seeds) in one sweep."""

_TOP_KEYS = ("name", "agents", "envs", "delays", "seeds", "steps", "eval_episodes", "eval_steps")
_AGENT_KEYS = ("name", "label", "kwargs", "reward_model", "steps", "envs")
_ENV_KEYS = ("id", "label", "kwargs", "steps", "eval_episodes", "eval_steps")
_DELAY_KEYS = (*DELAY_KINDS, "label")
_ENV_DELAY_KWARGS = ("action_delay", "observation_delay", "reward_delay")


# ---------------------------------------------------------------------------------- the plan
@dataclass(frozen=True)
class Evaluation:
    """How a trained agent is evaluated: ``count`` greedy episodes, or ``count`` steps."""

    unit: str  # "episode" or "step"
    count: int


@dataclass(frozen=True)
class SweepAgent:
    """One entry of ``agents``: a library agent's name or ``sb3:ALGO``, and its arguments.

    Attributes:
        name: the agent registry's name, or ``sb3:ALGO`` for a stable-baselines3 algorithm.
        label: its name in the results rows.
        kwargs: the agent's constructor arguments, placeholders such as ``$delay_mean`` filled
            in per delay.
        steps: its training steps (``None``: the env's, else the sweep's).
        envs: the labels of the envs it runs on (``None``: every env).
        reward_model: an SB3 agent's reward model from :mod:`delayed_rl.deep`, or a replay
            buffer that computes its own rewards, as the mapping the sweep file gives
            (``None``: the delivered rewards, raw).
    """

    name: str
    label: str
    kwargs: dict[str, Any]
    steps: int | None = None
    envs: tuple[str, ...] | None = None
    reward_model: dict[str, Any] | None = None


@dataclass(frozen=True)
class SweepEnv:
    """One entry of ``envs``: a Gymnasium id, ``gym.make``'s arguments and its overrides.

    Attributes:
        id: the Gymnasium id, e.g. ``"delayed_rl/GridWorld-5x5-v0"``.
        label: its name in the results rows.
        kwargs: ``gym.make``'s arguments (the sweep's delays are added to them).
        steps: the training steps of its runs (``None``: the sweep's), unless an agent sets its
            own.
        evaluation: how its runs are evaluated (``None``: the sweep's).
    """

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
    """A checked sweep file (see ``docs/sweeps.md``); :meth:`runs` lists its runs."""

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
            "agent": {
                "name": agent.name,
                "kwargs": agent.kwargs,
                # only when given: the runs of a sweep without one keep their run_id
                **({} if agent.reward_model is None else {"reward_model": agent.reward_model}),
            },
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


# ---------------------------------------------------------------------------------- checking
def parse_sweep(data: Any, name: str = "sweep", source: str = "sweep") -> Sweep:
    """Check a sweep file's content (a mapping, see ``docs/sweeps.md``) and return its plan.

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
    seeds = _parse_seeds(data.get("seeds", DEFAULT_SEEDS))
    pairs = sum(len(agent.envs) if agent.envs else len(envs) for agent in agents)
    runs = pairs * len(delays) * len(seeds)
    if runs > MAX_RUNS:
        raise ValueError(
            f"the sweep has {runs:,} runs ({pairs} (agent, env) pairs × {len(delays)} delays × "
            f"{len(seeds)} seeds), more than {MAX_RUNS.text}: split it"
        )
    return Sweep(
        name=_text("name", data.get("name", name)),
        agents=agents,
        envs=envs,
        delays=delays,
        seeds=seeds,
        steps=_steps("steps", data.get("steps", DEFAULT_STEPS)),
        evaluation=_parse_evaluation("", data) or Evaluation("episode", DEFAULT_EVAL_EPISODES),
        source=source,
    )


def _steps(where: str, value: Any, optional: bool = False) -> int | None:
    """A run's training steps: an integer in ``[1, MAX_TIMESTEPS]`` (``learn()``'s bound)."""
    steps = check_int(where, value, 1, optional=optional)
    return check_limit(where, steps, MAX_TIMESTEPS)


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


def _named_entry(
    where: str, entry: Any, key: str, allowed: Sequence[str], named: str
) -> Mapping[str, Any]:
    """An entry given as its ``key`` alone (``named``, a string) or as a mapping with ``key``.

    Returns the mapping (``{key: entry}`` for a string), its keys checked against ``allowed``.
    """
    if isinstance(entry, str):
        entry = {key: entry}
    entry = _mapping(where, entry, f"{named} or a mapping with {key!r}")
    _check_keys(where, entry, allowed, required=(key,))
    return entry


def _text(where: str, value: Any) -> str:
    """A name, label or id: a non-empty string of at most :data:`MAX_LABEL_CHARS` characters.

    It must be encodable as UTF-8 (no lone surrogate, which a JSON escape can make): it is
    written to ``results.csv`` and ``summary.md``.
    """
    if not isinstance(value, str):
        raise TypeError(f"{where} must be a string, got {value!r} ({type(value).__name__})")
    if not value.strip():
        raise ValueError(f"{where} must be a non-empty string, got {value!r}")
    if len(value) > MAX_LABEL_CHARS:
        raise ValueError(
            f"{where}'s length must be at most {MAX_LABEL_CHARS.text}, got "
            f"{len(value):,}: {value[:40]!r}..."
        )
    try:
        value.encode("utf-8")
    except UnicodeEncodeError as error:
        raise ValueError(f"{where} must be text UTF-8 can write, got {value!r}: {error}") from None
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


def _agent_name(where: str, value: Any) -> str:
    name = _text(where, value)
    allowed = (*CLASS_NAMES, *(SB3_PREFIX + algorithm for algorithm in SB3_ALGORITHMS))
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
    cls = agent_class(name)
    allowed = [p for p in inspect.signature(cls).parameters if p not in ("env", "seed")]
    for key in kwargs:
        if key not in allowed:
            raise ValueError(
                f"{where} has {key!r}, which is not an argument of {cls.__name__}; allowed: "
                f"{', '.join(allowed)}"
            )


def _parse_agent(where: str, entry: Any) -> SweepAgent:
    entry = _named_entry(where, entry, "name", _AGENT_KEYS, "an agent's name")
    name = _agent_name(f"{where}.name", entry["name"])
    why = "the sweep makes the env and seeds every run from 'seeds'"
    kwargs = _kwargs(f"{where}.kwargs", entry.get("kwargs", {}), ("env", "seed"), why)
    _check_agent_kwargs(f"{where}.kwargs", name, kwargs)
    reward_model = _reward_model(f"{where}.reward_model", name, entry.get("reward_model"))
    envs = entry.get("envs")
    if envs is not None:
        if not isinstance(envs, list):
            raise TypeError(
                f"{where}.envs must be a list of env labels, got {envs!r} ({type(envs).__name__})"
            )
        if not envs:
            raise ValueError(f"{where}.envs must be a non-empty list of env labels, got []")
        envs = tuple(_text(f"{where}.envs[{i}]", label) for i, label in enumerate(envs))
    default_label = name if reward_model is None else f"{name}+{reward_model['type']}"
    return SweepAgent(
        name=name,
        label=_text(f"{where}.label", entry.get("label", default_label)),
        kwargs=kwargs,
        steps=_steps(f"{where}.steps", entry.get("steps"), optional=True),
        envs=envs,
        reward_model=reward_model,
    )


def _reward_model(where: str, name: str, value: Any) -> dict[str, Any] | None:
    """An SB3 agent's ``reward_model`` mapping, checked as far as it can be without torch.

    ``type`` names a reward model class, or a replay buffer that computes its own rewards
    (:data:`~delayed_rl.deep.GUIDANCE_BUFFERS`, for off-policy algorithms only). Its settings
    are checked when :func:`~delayed_rl.sweep.runs.check_sweep` builds the agent.
    """
    from delayed_rl.deep import GUIDANCE_BUFFERS, REWARD_MODELS

    if value is None:
        return None
    if not name.startswith(SB3_PREFIX):
        raise ValueError(
            f"{where} is for stable-baselines3 agents (sb3:...): the library's agent {name!r} "
            "learns from the delayed rewards itself"
        )
    kinds = (*REWARD_MODELS, *GUIDANCE_BUFFERS)
    model = dict(_plain(where, _mapping(where, value, "a mapping with 'type'")))
    if "type" not in model:
        raise ValueError(f"{where} must name the model's class in 'type', one of {kinds}")
    kind = _text(f"{where}.type", model["type"])
    if kind not in kinds:
        close = difflib.get_close_matches(kind, kinds, n=1)
        close = close or [k for k in kinds if k.lower().startswith(kind.lower())]  # "IRCR"
        hint = f"; did you mean {close[0]!r}?" if close else ""
        raise ValueError(f"{where}.type must be one of {kinds}, got {kind!r}{hint}")
    if kind in GUIDANCE_BUFFERS and name.removeprefix(SB3_PREFIX) in SB3_ON_POLICY:
        off_policy = [SB3_PREFIX + a for a in SB3_ALGORITHMS if a not in SB3_ON_POLICY]
        raise ValueError(
            f"{where}.type {kind!r} is a replay buffer, for the off-policy algorithms "
            f"({', '.join(off_policy)}), got the on-policy {name!r}"
        )
    if "seed" in model:
        seeded = "buffer" if kind in GUIDANCE_BUFFERS else "model"
        raise ValueError(f"{where} must not set 'seed': the run's seed seeds the {seeded}")
    _check_agent_kwargs(where, name, {k: v for k, v in model.items() if k != "type"})
    return model


def env_id_hint(env_id: str) -> str | None:
    """``None`` for a registered Gymnasium id (or ``module:Id``, imported on make), else a hint.

    The hint ends the message that refuses ``env_id``: the closest registered ids, or where to
    see them. The sweep file's ``envs`` and ``delayed-rl train/evaluate --env`` share it.

    >>> env_id_hint("delayed_rl/GridWorld-3x3-v0") is None
    True
    >>> env_id_hint("delayed_rl/GridWorld-3x3")
    '; did you mean delayed_rl/GridWorld-3x3-v0, ...?'
    """
    if env_id in gym.registry or ":" in env_id:
        return None
    close = difflib.get_close_matches(env_id, list(gym.registry), n=3)
    return f"; did you mean {', '.join(close)}?" if close else "; see delayed-rl list"


def _check_env_id(where: str, env_id: Any) -> str:
    env_id = _text(where, env_id)
    hint = env_id_hint(env_id)
    if hint is None:
        return env_id
    raise ValueError(f"{where} must be a registered Gymnasium id, got {env_id!r}{hint}")


def _parse_env(where: str, entry: Any) -> SweepEnv:
    entry = _named_entry(where, entry, "id", _ENV_KEYS, "a Gymnasium id")
    env_id = _check_env_id(f"{where}.id", entry["id"])
    why = "set the delays in 'delays'"
    kwargs = _kwargs(f"{where}.kwargs", entry.get("kwargs", {}), _ENV_DELAY_KWARGS, why)
    return SweepEnv(
        id=env_id,
        label=_text(f"{where}.label", entry.get("label", env_id)),
        kwargs=kwargs,
        steps=_steps(f"{where}.steps", entry.get("steps"), optional=True),
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
        count = check_int(f"{prefix}eval_episodes", episodes, 1)
        return Evaluation(
            "episode", check_limit(f"{prefix}eval_episodes", count, MAX_EVAL_EPISODES)
        )
    if steps is not None:
        count = check_int(f"{prefix}eval_steps", steps, 1)
        return Evaluation("step", check_limit(f"{prefix}eval_steps", count, MAX_EVAL_STEPS))
    return None


def _distribution(where: str, value: Any) -> dict[str, Any]:
    """A delay as its ``to_dict()`` description: a number is a Poisson mean."""
    if not isinstance(value, Mapping) and (
        not isinstance(value, numbers.Real) or isinstance(value, bool)
    ):
        raise TypeError(
            f"{where} must be a number (a Poisson mean) or a distribution's description such as "
            f"{{type: Geometric, p: 0.25}}, got {value!r} ({type(value).__name__})"
        )
    return as_delay(dict(value) if isinstance(value, Mapping) else value, where).to_dict()


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
    """``seeds``: a count in ``[1, MAX_SEED_COUNT]``, or up to that many distinct seeds in a list.

    Each seed of a list lies in ``[0, MAX_SWEEP_SEED_VALUE]``.
    """
    if not isinstance(value, list):
        count = check_int("seeds", value, 1, note=" (a count), or a list of seeds")
        return tuple(range(check_limit("seeds", count, MAX_SEED_COUNT)))
    if not value:
        raise ValueError("seeds must be a count >= 1 or a non-empty list of seeds, got []")
    if len(value) > MAX_SEED_COUNT:
        raise ValueError(f"seeds must list at most {MAX_SEED_COUNT.text}, got {len(value):,} seeds")
    seeds = tuple(
        check_limit(f"seeds[{i}]", check_int(f"seeds[{i}]", seed, 0), MAX_SWEEP_SEED_VALUE)
        for i, seed in enumerate(value)
    )
    first: dict[int, int] = {}
    for i, seed in enumerate(seeds):
        if first.setdefault(seed, i) != i:
            raise ValueError(
                f"seeds[{i}] repeats the seed {seed} of seeds[{first[seed]}]: seeds must differ"
            )
    return seeds
