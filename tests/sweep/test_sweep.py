"""``delayed-rl sweep FILE``: the sweep file's checks, its runs, resuming, determinism, backends.

The Ray and Dask tests run the same tiny sweep as the joblib ones on a real local Ray instance
and Dask cluster, and compare the tables: every number but ``wall_s`` must be the same.
"""

from __future__ import annotations

import copy
import csv
import json
import math
import re
import sys
from pathlib import Path

import pytest

from delayed_rl.cli import main
from delayed_rl.delays import Constant, Poisson
from delayed_rl.sweep import (
    RESULT_COLUMNS,
    RunError,
    load_sweep,
    make_env,
    parse_sweep,
    read_sweep_file,
    resolve_placeholders,
    run_sweep,
)
from delayed_rl.sweep import results as sweep_results
from delayed_rl.sweep import runs as sweep_runs
from delayed_rl.wrappers import ObservationDelay, RewardDelay

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "sweep.yaml"
GRID = "delayed_rl/GridWorld-3x3-v0"

#: A sweep of seconds: 4 agents × 2 envs × 2 delays × 2 seeds = 32 runs.
TINY = {
    "name": "tiny",
    "agents": [
        "q",
        {"name": "fixed", "kwargs": {"delay_estimate": "$delay_steps"}},
        {"name": "expected-credit", "kwargs": {"delay": "$delay", "max_delay_estimate": 10}},
        "oracle",
    ],
    "envs": [
        {"id": GRID, "label": "grid", "eval_steps": 50},
        {"id": "Taxi-v4", "steps": 1000},
    ],
    "delays": [1.5, {"observation": 1, "label": "observation 1"}],
    "seeds": 2,
    "steps": 1500,
    "eval_episodes": 1,
}
COLUMNS = [*RESULT_COLUMNS, "eval_unit", "run_id"]


def tiny(**changes) -> dict:
    """A deep copy of :data:`TINY` with top-level ``changes``."""
    return {**copy.deepcopy(TINY), **changes}


def read_rows(out: Path) -> list[dict[str, str]]:
    with open(out / "results.csv", newline="") as handle:
        return list(csv.DictReader(handle))


def numbers(out: Path) -> list[dict[str, str]]:
    """The rows of ``out/results.csv`` without ``wall_s``: what must not depend on the backend."""
    return [{k: v for k, v in row.items() if k != "wall_s"} for row in read_rows(out)]


@pytest.fixture(scope="module")
def joblib_table(tmp_path_factory) -> list[dict[str, str]]:
    """The tiny sweep run in this process: the table every other run must reproduce."""
    out = tmp_path_factory.mktemp("joblib")
    outcome = run_sweep(parse_sweep(tiny()), out)
    assert (outcome.runs, outcome.ran, outcome.skipped) == (32, 32, 0)
    return numbers(out)


# ---------------------------------------------------------------------------------- the file
@pytest.mark.parametrize(
    ("change", "error", "message"),
    [
        # the top level
        (lambda d: [d], TypeError, "the sweep file must be a mapping, got [{"),
        (lambda d: d.update(agent=["q"]), ValueError, "unknown key 'agent'; allowed: name, "),
        (lambda d: d.update(agent=["q"]), ValueError, "did you mean 'agents'?"),
        (lambda d: d.__delitem__("envs"), ValueError, "must have the key 'envs'"),
        (lambda d: d.update(name=3), TypeError, "name must be a string, got 3 (int)"),
        (lambda d: d.update(steps=0), ValueError, "steps must be an integer >= 1, got 0"),
        (lambda d: d.update(steps="many"), TypeError, "steps must be an integer >= 1, got 'many'"),
        (lambda d: d.update(seeds=0), ValueError, "seeds must be an integer >= 1 (a count)"),
        (lambda d: d.update(seeds="3"), TypeError, "seeds must be an integer >= 1 (a count), or"),
        (lambda d: d.update(seeds=[]), ValueError, "seeds must be a count >= 1 or a non-empty"),
        (lambda d: d.update(seeds=[0, -1]), ValueError, "seeds[1] must be an integer >= 0, got -1"),
        (lambda d: d.update(seeds=[3, 3]), ValueError, "seeds[1] repeats the seed 3"),
        (lambda d: d.update(eval_steps=5), ValueError, "eval_episodes and eval_steps are both"),
        (lambda d: d.update(eval_episodes=0), ValueError, "eval_episodes must be an integer >= 1"),
        # agents
        (lambda d: d.update(agents="q"), TypeError, "agents must be a list, got 'q' (str)"),
        (lambda d: d.update(agents=[]), ValueError, "agents must be a non-empty list, got []"),
        (lambda d: d.update(agents=[3]), TypeError, "agents[0] must be an agent's name or a"),
        (
            lambda d: d.update(agents=["no-such-agent"]),
            ValueError,
            "agents[0].name must be one of ('q',",
        ),
        (lambda d: d.update(agents=["sb3:PPO2"]), ValueError, "did you mean 'sb3:PPO'?"),
        (lambda d: d.update(agents=[{"kwargs": {}}]), ValueError, "agents[0] must have the key"),
        (
            lambda d: d.update(agents=[{"name": "q", "kwarg": {}}]),
            ValueError,
            "agents[0] has the unknown key 'kwarg'; allowed: name, label, kwargs, reward_model, steps, envs; "
            "did you mean 'kwargs'?",
        ),
        (
            lambda d: d.update(agents=[{"name": "q", "kwargs": [1]}]),
            TypeError,
            "agents[0].kwargs must be a mapping, got [1] (list)",
        ),
        (
            lambda d: d.update(agents=[{"name": "mmq", "kwargs": {"gammma": 0.5}}]),
            ValueError,
            "agents[0].kwargs has 'gammma', which is not an argument of MultipleModelQLearning",
        ),
        (
            lambda d: d.update(agents=[{"name": "q", "kwargs": {"seed": 1}}]),
            ValueError,
            "agents[0].kwargs must not set 'seed'",
        ),
        (
            lambda d: d.update(agents=[{"name": "fixed", "kwargs": {"delay_estimate": "$dealy"}}]),
            ValueError,
            "agents[0].kwargs.delay_estimate must be one of the placeholders ('$delay',",
        ),
        (
            lambda d: d.update(agents=[{"name": "q", "kwargs": {"q_init": {1, 2}}}]),
            TypeError,
            "agents[0].kwargs.q_init must be a number, string, bool, null, list or mapping",
        ),
        (
            lambda d: d.update(agents=[{"name": "q", "kwargs": {"q_init": float("nan")}}]),
            ValueError,
            "agents[0].kwargs.q_init must be a finite number, got nan",
        ),
        (
            lambda d: d.update(agents=[{"name": "q", "steps": 0}]),
            ValueError,
            "agents[0].steps must be None or an integer >= 1, got 0",
        ),
        (
            lambda d: d.update(agents=[{"name": "q", "envs": "grid"}]),
            TypeError,
            "agents[0].envs must be a list of env labels, got 'grid' (str)",
        ),
        (
            lambda d: d.update(agents=[{"name": "q", "envs": ["Grid"]}]),
            ValueError,
            "agents[0].envs[0] (an env label) must be one of ('grid', 'Taxi-v4'), got 'Grid'",
        ),
        (lambda d: d.update(agents=[{"name": "q", "label": 5}]), TypeError, "agents[0].label"),
        (
            lambda d: d.update(agents=["q", "mmq", "q"]),
            ValueError,
            "agents[2] has the label 'q' of agents[0]: give one of them a 'label' of its own",
        ),
        # envs
        (lambda d: d.update(envs={}), TypeError, "envs must be a list, got {} (dict)"),
        (
            lambda d: d.update(envs=["delayed_rl/GridWorld-3x3"]),
            ValueError,
            "envs[0].id must be a registered Gymnasium id, got 'delayed_rl/GridWorld-3x3'; did "
            "you mean delayed_rl/GridWorld-3x3-v0",
        ),
        (lambda d: d.update(envs=[{"id": 7}]), TypeError, "envs[0].id must be a string, got 7"),
        (
            lambda d: d.update(envs=[{"id": GRID, "kwargs": {"reward_delay": 3}}]),
            ValueError,
            "envs[0].kwargs must not set 'reward_delay': set the delays in 'delays'",
        ),
        (
            lambda d: d.update(envs=[{"id": GRID, "eval": 5}]),
            ValueError,
            "envs[0] has the unknown key 'eval'",
        ),
        (
            lambda d: d.update(envs=[{"id": GRID, "eval_steps": 5, "eval_episodes": 1}]),
            ValueError,
            "envs[0].eval_episodes and envs[0].eval_steps are both given (1, 5): give one",
        ),
        (
            lambda d: d.update(envs=[{"id": GRID, "eval_steps": 2.5}]),
            TypeError,
            "envs[0].eval_steps must be an integer >= 1, got 2.5 (float)",
        ),
        (lambda d: d.update(envs=[GRID, GRID]), ValueError, "envs[1] has the label"),
        # delays
        (lambda d: d.update(delays=3), TypeError, "delays must be a list, got 3 (int)"),
        (
            lambda d: d.update(delays=["3"]),
            TypeError,
            "delays[0] must be a number (a Poisson mean) or a distribution's description",
        ),
        (lambda d: d.update(delays=[True]), TypeError, "got True (bool)"),
        (
            lambda d: d.update(delays=[-1]),
            ValueError,
            "delays[0] must be a number in [0, 9.22337e+18] (a Poisson mean), got -1",
        ),
        (
            lambda d: d.update(delays=[{"type": "Geometric", "p": 2}]),
            ValueError,
            "delays[0]: p must be a number in",
        ),
        (
            lambda d: d.update(delays=[{"type": "Lognormal"}]),
            ValueError,
            "delays[0] must be a dict with a 'type' in ('Poisson', 'Constant'",
        ),
        (
            lambda d: d.update(delays=[{"rewards": 3}]),
            ValueError,
            "delays[0] has the unknown key 'rewards'; allowed: action, observation, reward, "
            "label; did you mean 'reward'?",
        ),
        (
            lambda d: d.update(delays=[{"label": "none"}]),
            ValueError,
            "delays[0] must delay at least one of ('action', 'observation', 'reward')",
        ),
        (
            lambda d: d.update(delays=[{"action": "x"}]),
            TypeError,
            "delays[0].action must be a number (a Poisson mean)",
        ),
        (lambda d: d.update(delays=[2, 2.0]), ValueError, "delays[1] has the label 'Poisson"),
    ],
)
def test_every_field_is_checked_with_a_message_naming_it(change, error, message):
    data = tiny()
    changed = change(data)
    with pytest.raises(error) as info:
        parse_sweep(changed if isinstance(changed, list) else data)
    assert message in str(info.value)


def test_a_sweep_is_planned_with_its_defaults_and_overrides():
    sweep = parse_sweep(
        {
            "agents": ["q", {"name": "mmq", "steps": 7, "envs": ["Taxi-v4"]}],
            "envs": [{"id": GRID, "eval_steps": 9, "steps": 5}, "Taxi-v4"],
            "delays": [0, {"type": "Geometric", "p": 0.5}, {"reward": 2, "action": 1}],
        },
        name="mine",
    )
    assert sweep.name == "mine" and sweep.seeds == (0, 1, 2) and sweep.steps == 100_000
    assert [d.label for d in sweep.delays] == [
        "Poisson(lam=0)",
        "Geometric(p=0.5)",
        "action Poisson(lam=1) + reward Poisson(lam=2)",
    ]
    runs = sweep.runs()
    assert len(runs) == (2 + 1) * 3 * 3  # mmq runs on Taxi only
    config = {(r["agent"], r["env"]): (r["config"]["steps"], r["config"]["eval"]) for r in runs}
    assert config[("q", GRID)] == (5, {"unit": "step", "count": 9})  # the env's
    assert config[("q", "Taxi-v4")] == (100_000, {"unit": "episode", "count": 10})  # defaults
    assert config[("mmq", "Taxi-v4")][0] == 7  # the agent's steps win
    assert len({run["run_id"] for run in runs}) == len(runs)


def test_placeholders_are_the_runs_reward_delay():
    kwargs = {"delay": "$delay", "mean": "$delay_mean", "k": "$delay_steps", "other": 3}
    resolved = resolve_placeholders(kwargs, Poisson(2.6))
    assert resolved == {"delay": Poisson(2.6), "mean": 2.6, "k": 3, "other": 3}


def test_the_oracle_gets_a_reward_delay_that_records_arrivals():
    sweep = parse_sweep(tiny(agents=["oracle", "q"]))
    configs = {(r["agent"], r["delay"]): r["config"] for r in sweep.runs()}
    env = make_env(configs[("oracle", "observation 1")])  # no reward delay: Constant(0)
    assert isinstance(env, RewardDelay) and env.record_arrivals and env.delay == Constant(0)
    assert isinstance(env.env, ObservationDelay)
    plain = make_env(configs[("q", "observation 1")])
    assert isinstance(plain, ObservationDelay)
    delayed = make_env(configs[("q", "Poisson(lam=1.5)")])
    assert isinstance(delayed, RewardDelay) and not delayed.record_arrivals


def test_check_sweep_builds_each_agent_on_each_env_first(tmp_path):
    data = tiny(agents=["q"], envs=["CartPole-v1"])
    path = tmp_path / "cart.json"
    path.write_text(json.dumps(data))
    with pytest.raises(TypeError) as info:
        load_sweep(path)
    text = str(info.value)
    assert text.startswith(f"{path}: agent 'q' on env 'CartPole-v1' under delay 'Poisson(lam=1.5)'")
    assert "Discrete observation_space" in text
    data = tiny(agents=[{"name": "q", "kwargs": {"gamma": 2}}])
    path.write_text(json.dumps(data))
    with pytest.raises(ValueError, match="agent 'q' on env 'grid' .*gamma must be a number in"):
        load_sweep(path)
    assert load_sweep(path, check=False).agents[0].kwargs == {"gamma": 2}


def test_yaml_and_json_files_give_the_same_sweep(tmp_path):
    import yaml  # the sweep extra: CI installs it

    (tmp_path / "s.yaml").write_text(yaml.safe_dump(TINY))
    (tmp_path / "s.json").write_text(json.dumps(TINY))
    from_yaml, from_json = load_sweep(tmp_path / "s.yaml"), load_sweep(tmp_path / "s.json")
    assert from_yaml.runs() == from_json.runs()


@pytest.mark.parametrize(
    ("name", "text", "message"),
    [
        ("s.txt", "{}", "a sweep file must end in .yaml, .yml or .json"),
        ("s.json", "{agents: [q]}", "s.json is not valid JSON"),
        ("s.yaml", "agents: [q\n", "s.yaml is not valid YAML"),
    ],
)
def test_a_file_that_does_not_read_says_so(tmp_path, name, text, message):
    (tmp_path / name).write_text(text)
    with pytest.raises(ValueError, match=message):
        read_sweep_file(tmp_path / name)


def test_yaml_without_pyyaml_names_the_extra(tmp_path, monkeypatch):
    (tmp_path / "s.yaml").write_text("agents: [q]\n")
    monkeypatch.setitem(sys.modules, "yaml", None)
    with pytest.raises(RuntimeError, match=r"needs PyYAML: pip install 'delayed-rl\[sweep\]'"):
        read_sweep_file(tmp_path / "s.yaml")


def test_the_example_sweep_is_what_its_comments_say_and_every_run_works(tmp_path):
    sweep = load_sweep(EXAMPLE)
    assert [a.name for a in sweep.agents] == ["q", "mmq", "deconv", "expected-credit", "oracle"]
    assert [e.id for e in sweep.envs] == ["delayed_rl/GridWorld-5x5-v0", "Taxi-v4"]
    assert len(sweep.runs()) == 5 * 2 * 2 * 3
    data = read_sweep_file(EXAMPLE)  # the same runs, scaled down to seconds
    data.update(steps=300, eval_episodes=1, seeds=1)
    data["envs"][0]["eval_steps"], data["envs"][1]["steps"] = 50, 300
    outcome = run_sweep(parse_sweep(data), tmp_path)
    assert outcome.ran == 5 * 2 * 2


# ---------------------------------------------------------------------------------- running
@pytest.mark.experiment
def test_a_sweep_writes_one_row_per_run_a_summary_and_a_figure_per_env(tmp_path, joblib_table):
    outcome = run_sweep(parse_sweep(tiny(seeds=[0])), tmp_path)
    rows = read_rows(tmp_path)
    assert list(rows[0]) == COLUMNS and len(rows) == outcome.runs == 16
    assert [r["agent"] for r in rows[:4]] == ["q"] * 4
    assert {r["eval_unit"] for r in rows if r["env"] == "grid"} == {"step"}
    assert {r["eval_unit"] for r in rows if r["env"] == "Taxi-v4"} == {"episode"}
    assert {r["steps"] for r in rows if r["env"] == "Taxi-v4"} == {"1000"}
    for row in rows:
        assert all(math.isfinite(float(row[k])) for k in ("train_reward", "eval_reward", "wall_s"))
    # seed 0's rows are those of the two-seed sweep (run on its own, a run is the same)
    seed0 = [{k: v for k, v in row.items() if k != "wall_s"} for row in rows]
    assert seed0 == [row for row in joblib_table if row["seed"] == "0"]

    with open(tmp_path / "summary.csv", newline="") as handle:
        summary = list(csv.DictReader(handle))
    assert len(summary) == 4 * 2 * 2 and summary[0]["seeds"] == "1"
    assert summary[0]["eval_reward_ci95"] == "nan"  # one seed: no interval, not a zero-width one
    text = (tmp_path / "summary.md").read_text()
    assert "(one seed)" in text and "±" not in text.split("## grid")[1]
    assert text.startswith("# tiny\n") and "## grid" in text and "## Taxi-v4" in text
    assert "| agent | Poisson(lam=1.5) | observation 1 |" in text
    assert "per episode" in text and "per step" in text
    assert outcome.figures == {"grid": "eval_reward_grid.png", "Taxi-v4": "eval_reward_taxi-v4.png"}
    for name in outcome.figures.values():
        assert (tmp_path / name).stat().st_size > 10_000 and f"]({name})" in text


def test_a_figure_without_matplotlib_is_a_note(tmp_path, monkeypatch):
    def no_matplotlib(*args):
        raise ImportError("No module named 'matplotlib'")

    monkeypatch.setattr(sweep_results, "plot_env", no_matplotlib)
    run_sweep(parse_sweep(tiny(agents=["q"], seeds=1)), tmp_path)
    assert (
        "eval_reward_grid.png not drawn: install the plot extra"
        in (tmp_path / "summary.md").read_text()
    )


@pytest.mark.parametrize(
    ("options", "error", "message"),
    [
        ({"workers": 0}, ValueError, "workers must be an integer >= 1, got 0"),
        ({"backend": "spark"}, ValueError, "backend must be one of ('loky', 'ray', 'dask')"),
        ({"address": "tcp://127.0.0.1:1"}, ValueError, "address is for the ray and dask backends"),
        ({"backend": "dask", "address": 8786}, TypeError, "address must be a string, got 8786"),
    ],
)
def test_bad_run_options_fail_before_anything_is_written(tmp_path, options, error, message):
    with pytest.raises(error, match=re.escape(message)):
        run_sweep(parse_sweep(tiny()), tmp_path / "out", **options)
    assert not (tmp_path / "out").exists()


@pytest.mark.cold_cache
def test_the_same_file_gives_the_same_numbers_in_a_process_pool(tmp_path, joblib_table):
    run_sweep(parse_sweep(tiny()), tmp_path, workers=2)
    assert numbers(tmp_path) == joblib_table


@pytest.mark.experiment
def test_a_rerun_runs_only_what_results_csv_lacks(tmp_path, joblib_table):
    sweep = parse_sweep(tiny())
    assert run_sweep(sweep, tmp_path).ran == 32
    before = read_rows(tmp_path)
    again = run_sweep(sweep, tmp_path)
    assert (again.ran, again.skipped) == (0, 32)
    assert read_rows(tmp_path) == before  # wall_s included: nothing ran again

    rows = read_rows(tmp_path)
    removed = rows.pop(5)
    with open(tmp_path / "results.csv", "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=COLUMNS)
        writer.writeheader()
        writer.writerows(rows)
    with open(tmp_path / "results.csv", "a") as handle:
        handle.write("q,grid,Poisson(lam=1.5),1,15")  # a row cut short by an interruption
    with pytest.warns(UserWarning, match=r"results.csv, line 33: a row cut short"):
        again = run_sweep(sweep, tmp_path)
    assert (again.ran, again.skipped) == (1, 31)
    after = read_rows(tmp_path)
    assert [r["run_id"] for r in after] == [r["run_id"] for r in before]  # the sweep's order
    assert after[5]["run_id"] == removed["run_id"] and after[:5] + after[6:] == rows
    assert numbers(tmp_path) == joblib_table


def test_a_changed_configuration_runs_again_and_the_old_rows_stay(tmp_path):
    data = tiny(agents=["q"], seeds=1)
    run_sweep(parse_sweep(data), tmp_path)
    data["envs"][1]["steps"] = 1200
    again = run_sweep(parse_sweep(data), tmp_path)
    assert (again.ran, again.skipped) == (2, 2)  # the Taxi runs
    rows = read_rows(tmp_path)
    assert [r["steps"] for r in rows if r["env"] == "Taxi-v4"] == ["1200", "1200", "1000", "1000"]
    assert [row["seeds"] for row in again.summary] == [1, 1, 1, 1]  # the new rows only


def test_a_failed_run_keeps_the_rows_of_those_that_finished(tmp_path, monkeypatch):
    monkeypatch.setattr(sweep_runs, "MAX_EVAL_EPISODE_STEPS", 30)
    data = tiny(agents=["q"], seeds=1, delays=[1])
    data["envs"] = [{"id": GRID, "label": "grid", "eval_steps": 20}, GRID.replace("3x3", "5x5")]
    with pytest.raises(RunError) as info:
        run_sweep(parse_sweep(data), tmp_path)
    text = str(info.value)
    assert text.startswith("run (q, delayed_rl/GridWorld-5x5-v0, Poisson(lam=1), seed 0) failed")
    assert "no evaluation episode ended within 30 steps" in text and "eval_steps" in text
    assert [row["env"] for row in read_rows(tmp_path)] == ["grid"]


def test_progress_without_tqdm_is_a_count_on_stderr(tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "tqdm.auto", None)
    run_sweep(parse_sweep(tiny(agents=["q"], seeds=1, delays=[1])), tmp_path, progress=True)
    assert capsys.readouterr().err.splitlines() == [
        "[sweep] 1/2 runs done",
        "[sweep] 2/2 runs done",
    ]


@pytest.mark.sb3
def test_sb3_algorithms_run_by_name(tmp_path):
    data = {
        "agents": [
            {"name": "sb3:PPO", "kwargs": {"n_steps": 64, "batch_size": 32, "n_epochs": 1}},
            {"name": "q", "envs": ["grid"]},
        ],
        "envs": [{"id": "CartPole-v1"}, {"id": GRID, "label": "grid", "eval_steps": 20}],
        "delays": [2],
        "seeds": 1,
        "steps": 64,
        "eval_episodes": 2,
    }
    sweep = parse_sweep(data)
    assert [(r["agent"], r["env"]) for r in sweep.runs()] == [
        ("sb3:PPO", "CartPole-v1"),
        ("sb3:PPO", "grid"),
        ("q", "grid"),
    ]
    run_sweep(sweep, tmp_path / "a")
    rows = read_rows(tmp_path / "a")
    cart = rows[0]
    assert float(cart["train_reward"]) == 1.0  # CartPole pays 1 a step, undelayed
    assert float(cart["eval_reward"]) >= 8  # a greedy episode lasts at least 8 steps
    run_sweep(sweep, tmp_path / "b")
    assert numbers(tmp_path / "a") == numbers(tmp_path / "b")


# ---------------------------------------------------------------------------------- reward models
#: SAC with the deconvolution (delay known) against raw SAC, and PPO with RRD, in seconds.
REWARD_MODEL_SWEEP = {
    "agents": [
        {"name": "sb3:SAC", "kwargs": {"learning_starts": 60, "batch_size": 16}},
        {
            "name": "sb3:SAC",
            "kwargs": {"learning_starts": 60, "batch_size": 16},
            "reward_model": {
                "type": "DeconvolutionRewardModel",
                "delay": "$delay",
                "hidden_sizes": [8],
                "warmup_updates": 5,
            },
        },
        {
            "name": "sb3:PPO",
            "kwargs": {"n_steps": 64, "batch_size": 32, "n_epochs": 1},
            "reward_model": {"type": "ReturnDecompositionRewardModel", "hidden_sizes": [8]},
        },
        {
            "name": "sb3:SAC",
            "kwargs": {"learning_starts": 90, "batch_size": 16},  # two episodes first
            "reward_model": {"type": "IRCRReplayBuffer", "heap_episodes": 2},
        },
    ],
    "envs": [{"id": "Pendulum-v1", "kwargs": {"max_episode_steps": 40}}],
    "delays": [3],
    "seeds": 1,
    "steps": 128,
    "eval_episodes": 1,
}


def test_a_reward_model_is_checked_and_named_in_the_labels():
    sweep = parse_sweep(REWARD_MODEL_SWEEP)
    runs = sweep.runs()
    assert [r["agent"] for r in runs] == [
        "sb3:SAC",
        "sb3:SAC+DeconvolutionRewardModel",
        "sb3:PPO+ReturnDecompositionRewardModel",
        "sb3:SAC+IRCRReplayBuffer",
    ]
    assert "reward_model" not in runs[0]["config"]["agent"]  # a plain run keeps its run_id
    assert runs[1]["config"]["agent"]["reward_model"]["delay"] == "$delay"
    assert len({r["run_id"] for r in runs}) == 4


@pytest.mark.parametrize(
    ("model", "error", "match"),
    [
        ({"type": "Deconvolution"}, ValueError, "did you mean 'DeconvolutionRewardModel'"),
        ({"delay": 3}, ValueError, r"agents\[0\].reward_model must name the model's class"),
        ({"type": "DeconvolutionRewardModel", "seed": 1}, ValueError, "must not set 'seed'"),
        ({"type": "DeconvolutionRewardModel", "delay": "$lag"}, ValueError, "placeholders"),
        ("DeconvolutionRewardModel", TypeError, r"agents\[0\].reward_model"),
        ({"type": "IRCR"}, ValueError, "did you mean 'IRCRReplayBuffer'"),
        ({"type": "IRCRReplayBuffer", "seed": 1}, ValueError, "must not set 'seed'"),
    ],
)
def test_a_bad_reward_model_is_refused_by_field(model, error, match):
    data = {**REWARD_MODEL_SWEEP, "agents": [{"name": "sb3:SAC", "reward_model": model}]}
    with pytest.raises(error, match=match):
        parse_sweep(data)


@pytest.mark.parametrize("algorithm", ["sb3:PPO", "sb3:A2C"])
def test_a_guidance_buffer_is_for_off_policy_algorithms_only(algorithm):
    data = tiny(agents=[{"name": algorithm, "reward_model": {"type": "IRCRReplayBuffer"}}])
    message = (
        r"agents\[0\].reward_model.type 'IRCRReplayBuffer' is a replay buffer, for the off-policy "
        rf"algorithms \(sb3:DDPG, sb3:DQN, sb3:SAC, sb3:TD3\), got the on-policy '{algorithm}'"
    )
    with pytest.raises(ValueError, match=message):
        parse_sweep(data)


def test_a_reward_model_is_for_sb3_agents_only():
    data = tiny(agents=[{"name": "q", "reward_model": {"type": "DeconvolutionRewardModel"}}])
    with pytest.raises(ValueError, match=r"agents\[0\].reward_model is for stable-baselines3"):
        parse_sweep(data)


@pytest.mark.sb3
def test_a_sweep_with_reward_models_runs_and_repeats(tmp_path):
    from delayed_rl.sweep import check_sweep

    sweep = parse_sweep(REWARD_MODEL_SWEEP)
    run_sweep(sweep, tmp_path / "a")
    rows = read_rows(tmp_path / "a")
    assert [row["agent"] for row in rows] == [r["agent"] for r in sweep.runs()]
    assert all(math.isfinite(float(row["eval_reward"])) for row in rows)
    run_sweep(sweep, tmp_path / "b")
    assert numbers(tmp_path / "a") == numbers(tmp_path / "b")
    # a setting the class does not take fails before any run, naming the agent
    bad = copy.deepcopy(REWARD_MODEL_SWEEP)
    bad["agents"][1]["reward_model"]["windw"] = 3
    with pytest.raises(TypeError, match="sb3:SAC.*windw"):
        check_sweep(parse_sweep(bad))
    taken = copy.deepcopy(REWARD_MODEL_SWEEP)
    taken["agents"][1]["kwargs"]["replay_buffer_kwargs"] = {}
    with pytest.raises(ValueError, match="must not set replay_buffer_kwargs"):
        check_sweep(parse_sweep(taken))
    # a guidance buffer's settings are its own arguments, checked alike
    bad = copy.deepcopy(REWARD_MODEL_SWEEP)
    bad["agents"][3]["reward_model"]["heap_episodes"] = 0
    with pytest.raises(ValueError, match="heap_episodes must be an integer in"):
        check_sweep(parse_sweep(bad))


# ---------------------------------------------------------------------------------- the CLI
@pytest.mark.experiment
def test_the_cli_runs_a_sweep_file_and_resumes_it(tmp_path, capsys, joblib_table):
    path = tmp_path / "tiny.json"
    path.write_text(json.dumps(TINY))
    out = tmp_path / "out"
    assert main(["sweep", str(path), "--out", str(out), "--no-progress"]) == 0
    captured = capsys.readouterr()
    assert captured.out.startswith("# tiny\n") and captured.err == ""
    assert f"ran 32 of 32 runs (0 already in {out / 'results.csv'})" in captured.out
    assert numbers(out) == joblib_table
    assert main(["sweep", str(path), "--out", str(out), "--no-progress"]) == 0
    assert "ran 0 of 32 runs (32 already in" in capsys.readouterr().out


def test_the_cli_writes_to_runs_name_by_default(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    Path("mine.json").write_text(json.dumps(tiny(agents=["q"], seeds=1, delays=[1])))
    assert main(["sweep", "mine.json", "--no-progress"]) == 0
    assert len(read_rows(tmp_path / "runs" / "mine")) == 2


@pytest.mark.parametrize(
    ("content", "args", "message"),
    [
        ({**TINY, "seed": 3}, [], "tiny.json: the sweep file has the unknown key 'seed'"),
        ({**TINY, "steps": -5}, [], "tiny.json: steps must be an integer >= 1, got -5"),
        ("{", [], "tiny.json is not valid JSON"),
        (TINY, ["--address", "tcp://127.0.0.1:1"], "--address is for --backend ray or dask"),
        (TINY, ["--workers", "0"], "argument --workers: must be an integer >= 1, got 0"),
        (TINY, ["--backend", "spark"], "argument --backend: invalid choice: 'spark'"),
    ],
)
def test_a_bad_sweep_file_or_option_exits_with_code_2(tmp_path, capsys, content, args, message):
    path = tmp_path / "tiny.json"
    path.write_text(content if isinstance(content, str) else json.dumps(content))
    with pytest.raises(SystemExit) as exit_info:
        main(["sweep", str(path), "--out", str(tmp_path / "out"), *args])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert "usage: delayed-rl sweep" in err and "Traceback" not in err
    errors = [line for line in err.splitlines() if "error:" in line]
    assert len(errors) == 1 and message in errors[0], err


def test_a_missing_file_or_a_failing_run_exits_with_code_1(tmp_path, capsys, monkeypatch):
    assert main(["sweep", str(tmp_path / "none.yaml")]) == 1
    err = capsys.readouterr().err
    assert err.startswith("error: [Errno 2] No such file") and err.count("\n") == 1
    monkeypatch.setattr(sweep_runs, "MAX_EVAL_EPISODE_STEPS", 10)
    path = tmp_path / "continuing.json"
    data = tiny(agents=["q"], envs=[GRID], seeds=1, delays=[1], eval_episodes=1)
    path.write_text(json.dumps(data))
    assert main(["sweep", str(path), "--out", str(tmp_path / "out"), "--no-progress"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("error: run (q, delayed_rl/GridWorld-3x3-v0, Poisson(lam=1), seed 0)")
    assert err.count("\n") == 1 and "Traceback" not in err


def test_sweep_help_documents_every_option(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["sweep", "--help"])
    assert exit_info.value.code == 0
    text = capsys.readouterr().out
    assert "usage: delayed-rl sweep" in text
    for option in ("FILE", "--out", "--workers", "--backend", "--address", "--progress"):
        assert option in text


# ---------------------------------------------------------------------------------- Ray, Dask
@pytest.mark.distributed
@pytest.mark.sb3
def test_ray_gives_the_same_table(tmp_path, joblib_table):
    import ray

    reward_models = tmp_path / "reward-models"
    run_sweep(parse_sweep(REWARD_MODEL_SWEEP), reward_models / "joblib")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        address = ray.get_runtime_context().gcs_address
        run_sweep(parse_sweep(tiny()), tmp_path, backend="ray", address=address)
        continuing = tiny(agents=["q"], envs=[GRID], seeds=1, delays=[1], eval_episodes=1)
        with pytest.raises(RunError, match="no evaluation episode ended within 100000 steps"):
            run_sweep(parse_sweep(continuing), tmp_path / "failing", backend="ray")
        # SB3 agents with reward models, on Ray: the same rows, each naming its model
        run_sweep(parse_sweep(REWARD_MODEL_SWEEP), reward_models / "ray", backend="ray")
    finally:
        ray.shutdown()
    assert numbers(tmp_path) == joblib_table
    assert numbers(reward_models / "ray") == numbers(reward_models / "joblib")
    assert "sb3:SAC+DeconvolutionRewardModel" in {
        r["agent"] for r in read_rows(reward_models / "ray")
    }


@pytest.mark.distributed
def test_dask_at_an_address_gives_the_same_table(tmp_path, capsys, joblib_table):
    from dask.distributed import LocalCluster

    path = tmp_path / "tiny.json"
    path.write_text(json.dumps(TINY))
    with LocalCluster(n_workers=2, threads_per_worker=1, dashboard_address=None) as cluster:
        argv = ["sweep", str(path), "--out", str(tmp_path / "out"), "--backend", "dask"]
        assert main([*argv, "--address", cluster.scheduler_address, "--no-progress"]) == 0
    assert "ran 32 of 32 runs" in capsys.readouterr().out
    assert numbers(tmp_path / "out") == joblib_table
