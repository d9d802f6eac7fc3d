"""Fingerprints of seeded runs of every agent, on both training paths: proof that a change kept them.

``python benchmarks/seeded_runs.py`` trains every agent of the library, with its options, on
both the Python and the compiled path, on several envs and under every episode-end mode, and
prints one SHA-256 per run of everything the run produced: the Q-table, every learned array
(delay estimates, pmfs, reward models), the training record (``learn(..., record=True)``), the
greedy actions, and the arrays a saved model file holds. It adds the runs of
``tests/cpu_probe.py`` (the e-puck, DeconvQ on Taxi, ``bench all --quick``).

``--write`` stores them in ``benchmarks/seeded_runs.json`` with the package versions (``--write
NAME ...`` adds or replaces those runs' fingerprints, all of an agent's for its name, and keeps
the others, on the same package versions and steps); an agent class that does not override
``compiled_tables`` (no compiled rule) runs on the Python path only; ``--check`` compares
against that file and lists every run that changed, and, run whole, every stored run it no
longer runs. A run whose output
changed on purpose (a renamed label in a summary, say) is re-recorded with a ``history`` entry
saying what changed and why. A change that must
keep behaviour (a re-layering, a rename) is checked with ``--check`` on the same package
versions; the numbers are the same on any x86-64 CPU (the docs' "Same seed, same bits").
"""

from __future__ import annotations

import argparse
import importlib.metadata
import inspect
import json
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

import gymnasium as gym
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

import cpu_probe  # noqa: E402  (tests/cpu_probe.py: the Digest and the CPU probe's runs)

import delayed_rl  # noqa: E402, F401  (registers the envs)
from delayed_rl import agents  # noqa: E402
from delayed_rl.agents.registry import REGISTRY  # noqa: E402
from delayed_rl.delays import Delay, Geometric, Poisson  # noqa: E402
from delayed_rl.wrappers import PoissonRewardDelay, RewardDelay  # noqa: E402

RESULTS = Path(__file__).with_suffix(".json")
PACKAGES = ("numpy", "numba", "gymnasium", "pymunk", "llvmlite")
STEPS = 4000

#: Settings renamed after the fingerprints were recorded, by class: ``{recorded: current}``.
#: A file's setting is hashed under its recorded name, so that a rename alone (CHANGELOG.md)
#: changes no fingerprint while a changed value still does.
RECORDED_NAMES: dict[str, dict[str, str]] = {
    "DeconvolutionQLearning": {"max_delay": "max_delay_estimate"},
    "ExpectedCreditQLearning": {"max_delay": "max_delay_estimate"},
}

#: Every agent with its options: (name, class name, keyword arguments).
AGENT_RUNS: list[tuple[str, str, dict]] = [
    ("q", "QLearning", {}),
    ("q-decay", "QLearning", {"exploration_initial_eps": 1.0, "exploration_final_eps": 0.05}),
    ("fixed", "FixedDelayQLearning", {"delay_estimate": 3}),
    ("mmq", "MultipleModelQLearning", {"max_delay_estimate": 8}),
    ("mmq-step", "MultipleModelQLearning", {"max_delay_estimate": 9, "delay_step": 3}),
    ("mmq-trace", "MultipleModelQLearning", {"max_delay_estimate": 8, "delay_trace": 0.9}),
    ("mmq-greedy", "MultipleModelQLearning", {"max_delay_estimate": 8, "greedy_window": 200}),
    ("mmq-kernel", "MultipleModelQLearning", {"max_delay_estimate": 8, "reward_kernel": 1.5}),
    (
        "expected-credit",
        "ExpectedCreditQLearning",
        {"delay": Poisson(3.0), "max_delay_estimate": 20},
    ),
    ("oracle", "OracleQLearning", {}),
    (
        "deconv-known",
        "DeconvolutionQLearning",
        {"delay": Poisson(3.0), "max_delay_estimate": 20, "solve_interval": 1000},
    ),
    (
        "deconv-learned",
        "DeconvolutionQLearning",
        {"max_delay_estimate": 20, "solve_interval": 1000},
    ),
]
#: A registered agent without a row above runs with its registry entry's ``example_arguments``,
#: under its registry name (so a new agent needs no row here, only ``--write`` to record its
#: fingerprints).
AGENT_RUNS += [
    (name, entry.class_name, dict(entry.example_arguments))
    for name, entry in REGISTRY.items()
    if entry.class_name not in {class_name for _, class_name, _ in AGENT_RUNS}
]


def _delayed(env_id: str, delay: Delay, on_episode_end: str) -> Callable[[str, bool], gym.Env]:
    """A maker of ``env_id`` behind a ``RewardDelay`` of ``delay`` (clipped at 20 steps)."""
    return lambda mode, rec: RewardDelay(
        gym.make(env_id), delay, max_delay=20, on_episode_end=on_episode_end, record_arrivals=rec
    )


#: The envs: (name, maker, whether the oracle's arrivals are recorded by the maker).
ENVS: dict[str, Callable[[str, bool], gym.Env]] = {
    "grid5-flush": lambda mode, rec: PoissonRewardDelay(
        gym.make("delayed_rl/GridWorld-5x5-v0"), lam=3.0, max_delay=20, record_arrivals=rec
    ),
    "frozenlake-carry": _delayed("FrozenLake-v1", Geometric(0.4), "carry"),
    "taxi-drop": _delayed("Taxi-v4", Poisson(2.0), "drop"),
}


def _file_arrays(agent) -> dict:
    """What a saved model file holds: its arrays, and its metadata but the class's module path.

    (Not the zip's bytes, which hold dates; not ``class`` and ``library_version``, which name
    where the code lives rather than what it learned.)
    """
    with tempfile.TemporaryDirectory() as folder:
        path = agent.save(Path(folder) / "model")
        with np.load(path, allow_pickle=False) as archive:
            content = {name: archive[name] for name in sorted(archive.files)}
    metadata = json.loads(str(content.pop("metadata")))
    metadata.pop("class")
    metadata.pop("library_version")
    settings = metadata.get("hyperparameters", {})
    for old, new in RECORDED_NAMES.get(type(agent).__name__, {}).items():
        if new in settings:
            settings[old] = settings.pop(new)
    return {**content, "metadata": json.dumps(metadata, sort_keys=True)}  # text: its big ints


def agent_run(name: str, env_name: str, compiled: bool) -> str:
    """Train one agent on one env on one path; hash everything it learned and recorded."""
    _, class_name, kwargs = next(entry for entry in AGENT_RUNS if entry[0] == name)
    cls = getattr(agents, class_name)
    entry = next(entry for entry in REGISTRY.values() if entry.class_name == class_name)
    env = ENVS[env_name](env_name, entry.needs_arrivals)
    # an agent that models the delay is told the env's episode-end mode
    takes_mode = "on_episode_end" in inspect.signature(cls).parameters
    extra = {"on_episode_end": env.on_episode_end} if takes_mode else {}
    agent = cls(env, q_init=2.0, seed=7, **kwargs, **extra)
    agent.learn(STEPS, compiled=compiled, record=True, log_interval=None)
    digest = cpu_probe.Digest()
    digest.add(agent.q_table)
    for attribute in ("delay_pmf", "reward_model", "mean_delay", "delay_estimates"):
        value = getattr(agent, attribute, None)
        if value is not None:
            digest.add(np.asarray(value))
    digest.add(dict(agent.training_log))
    states = np.arange(env.observation_space.n)
    digest.add(agent.predict(states, deterministic=True)[0])
    digest.add(_file_arrays(agent))
    return digest.hexdigest()


def paths(cls: type) -> tuple[bool, ...]:
    """The training paths of agent class ``cls``: ``compiled`` False, and True if it has that rule."""
    python_only = cls.compiled_tables is agents.TabularAgent.compiled_tables
    return (False,) if python_only else (False, True)


def runs() -> dict[str, Callable[[], str]]:
    """Every run by name: the agents' grid (each on its paths), then the CPU probe's."""
    table: dict[str, Callable[[], str]] = {}
    for name, class_name, _ in AGENT_RUNS:
        for env_name in ENVS:
            for compiled in paths(getattr(agents, class_name)):
                path = "compiled" if compiled else "python"
                key = f"{name}/{env_name}/{path}"
                table[key] = lambda n=name, e=env_name, c=compiled: agent_run(n, e, c)
    for key, run in cpu_probe.runs().items():
        table[f"probe/{key}"] = run
    return table


def main() -> int:
    """Print, write (``--write``) or check (``--check``) the fingerprints."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    action = parser.add_mutually_exclusive_group()
    action.add_argument("--write", action="store_true", help=f"store them in {RESULTS.name}")
    action.add_argument("--check", action="store_true", help=f"compare with {RESULTS.name}")
    parser.add_argument(
        "names",
        nargs="*",
        help="runs to do: a run's name, a row of AGENT_RUNS or a registered agent's name, for all "
        "of its runs (default: all)",
    )
    args = parser.parse_args()
    table = runs()
    keys = []
    for name in args.names:  # a run, a row of AGENT_RUNS or a registered agent (all its rows)
        entry = REGISTRY.get(name)
        rows = {row for row, cls, _ in AGENT_RUNS if entry and cls == entry.class_name} | {name}
        found = [key for key in table if key == name or key.partition("/")[0] in rows]
        if not found:
            agents_and_probes = sorted({key.partition("/")[0] for key in table})
            parser.error(f"no run is named {name!r}: give a run or one of {agents_and_probes}")
        keys += found
    hashes = {}
    for key in keys or table:
        hashes[key] = table[key]()
        print(f"{key}: {hashes[key]}", file=sys.stderr)
    versions = {name: importlib.metadata.version(name) for name in PACKAGES}
    if args.write:  # (the history of deliberate changes, if any, is kept)
        stored = json.loads(RESULTS.read_text()) if RESULTS.exists() else {}
        if args.names:  # the named runs join (or replace theirs in) the stored ones
            recorded = (stored.get("versions", versions), stored.get("steps", STEPS))
            if recorded != (versions, STEPS):
                parser.error(
                    f"the stored runs were recorded with {recorded[0]} and {recorded[1]} steps, "
                    f"these with {versions} and {STEPS}: record them all (--write with no "
                    "names) on one set"
                )
            hashes = {**stored.get("hashes", {}), **hashes}
        history = stored.get("history", [])
        payload = {"versions": versions, "steps": STEPS, "hashes": hashes, "history": history}
        RESULTS.write_text(json.dumps(payload, indent=1) + "\n")
        return 0
    if args.check:
        stored = json.loads(RESULTS.read_text())
        if stored["versions"] != versions:
            print(f"note: recorded with {stored['versions']}, running {versions}")
        changed = [k for k in hashes if stored["hashes"].get(k) != hashes[k]]
        for key in changed:
            print(f"changed: {key}")
        missing = [] if args.names else sorted(stored["hashes"].keys() - hashes.keys())
        for key in missing:  # a stored run the table no longer holds (a path lost, say)
            print(f"missing: {key}")
        print(f"{len(hashes) - len(changed)} of {len(hashes)} runs unchanged")
        return 1 if changed or missing else 0
    json.dump(hashes, sys.stdout, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
