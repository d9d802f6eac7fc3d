"""``delayed-rl bench multiagent-pursuit``: its tasks, shared runs, the PPO wiring, and a quick run."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from delayed_rl.delays import Poisson
from delayed_rl.experiments import LONG_NAMES, Config, get_experiment, run_experiment
from delayed_rl.experiments.beyond import multiagent_pursuit as pursuit
from delayed_rl.experiments.framework import multiagent_training as training
from delayed_rl.experiments.framework.experiment import VERDICTS
from delayed_rl.experiments.framework.pool import pool_key
from delayed_rl.multiagent import sb3_vec_env

SETTING = f"pursuit-poisson{pursuit.LAM}"


def _tiny(method: str, seed: int = 0, **changes) -> dict:
    """A run of the setting cut to a few hundred pursuer-steps."""
    task = {
        **pursuit.SETTINGS[SETTING],
        "env_kwargs": {**pursuit.SETTINGS[SETTING]["env_kwargs"], "max_cycles": 40},
        "ppo": {"n_steps": 64, "batch_size": 64},
        "steps": 512,
        "eval_every": 256,
        "eval_episodes": 1,
        "method": method,
        "seed": seed,
    }
    return {**task, **changes}


def test_the_full_run_has_every_method_five_seeds_and_the_oracle_ignores_the_delay():
    experiment = get_experiment("multiagent-pursuit")
    assert "multiagent-pursuit" in LONG_NAMES and experiment.resumable
    tasks = experiment.tasks(Config(seeds=experiment.default_seeds))
    assert experiment.default_seeds >= 5
    assert len(tasks) == (len(training.METHODS) + 1) * 5
    assert {t.steps for t in tasks} == {300_000}
    runs = {t.method: experiment.run_of(t).task for t in tasks if t.seed == 2}
    assert "delay" not in runs["oracle"] and runs["raw"]["delay"] == Poisson(30).to_dict()
    assert (
        "max_delay_estimate" in runs["deconv-learned"]
        and "max_delay_estimate" not in runs["deconv-known"]
    )
    assert "steps" not in runs["random"]
    assert len({pool_key(experiment.run_of(t)) for t in tasks}) == len(tasks)


def test_the_quick_run_is_two_seeds_of_few_steps():
    tasks = get_experiment("multiagent-pursuit").tasks(Config(quick=True, seeds=2))
    assert len(tasks) == (len(training.METHODS) + 1) * 2
    assert {(t.steps, t.eval_every) for t in tasks} == {pursuit.QUICK[SETTING]}


@pytest.mark.sb3
def test_every_agent_is_a_sub_env_and_a_seed_fixes_the_env_and_the_delays():
    env = training.make_env(_tiny("raw"), delayed=True)
    assert type(env).__name__ == "ParallelRewardDelay" and env.on_episode_end == "flush"
    assert env.delays["pursuer_3"] == Poisson(30)
    assert type(training.make_env(_tiny("oracle"), delayed=False)).__name__ != "ParallelRewardDelay"

    def rollout(seed: int) -> tuple[np.ndarray, list]:
        venv = sb3_vec_env(training.make_env(_tiny("raw"), delayed=True))
        assert venv.num_envs == 4  # one sub-env a pursuer
        venv.seed(seed)
        first = venv.reset()
        actions = np.random.default_rng(0).integers(0, 5, (80, 4))
        delays = []
        for row in actions:  # two 40-step episodes: SuperSuit resets between them unseeded
            _, _, _, infos = venv.step(row)
            delays.append([info.get("drawn_reward_delay") for info in infos])
        return first, delays

    first, delays = rollout(7)
    again, delays_again = rollout(7)
    other, delays_other = rollout(8)
    np.testing.assert_array_equal(first, again)
    assert delays == delays_again
    assert delays != delays_other
    assert {d for row in delays for d in row} - {None}  # the delays are reported


@pytest.mark.sb3
def test_a_seed_gives_the_same_run_and_another_seed_another():
    first = training.train_and_score(_tiny("deconv-learned", max_delay_estimate=20))
    again = training.train_and_score(_tiny("deconv-learned", max_delay_estimate=20))
    other = training.train_and_score(_tiny("deconv-learned", seed=1, max_delay_estimate=20))
    for result in (first, again, other):
        result.pop("train_seconds")
    assert first == again and first != other
    assert first["steps"] == [0, 256, 512] and len(first["scores"]) == 3
    assert first["updates"] > 0 and math.isfinite(first["mean_delay"])


def test_the_random_policy_is_seeded_and_scores_the_undelayed_game():
    task = _tiny("random", eval_episodes=2)
    assert training.random_score(task) == training.random_score(task)
    assert training.random_score(task) != training.random_score({**task, "seed": 1})
    # 40 steps at −0.1 each, with a catch (+5, shared by the 4) now and then
    assert -4.0 - 1e-9 <= training.random_score(task)["score"] < 10.0


@pytest.mark.experiment
@pytest.mark.sb3
def test_a_tiny_quick_run_writes_its_files_and_resumes(tmp_path):
    full = get_experiment("multiagent-pursuit")
    short = {**pursuit.SETTINGS[SETTING]["env_kwargs"], "max_cycles": 40}

    def tiny_tasks(config: Config) -> list[pursuit.PursuitTask]:  # 40-step episodes, two rollouts
        tiny = {"env_kwargs": short, "ppo": {"n_steps": 64, "batch_size": 64}, "steps": 512}
        return [dataclasses.replace(t, **tiny, eval_every=512) for t in full.tasks(config)]

    experiment = dataclasses.replace(full, tasks=tiny_tasks)
    config = Config(quick=True, seeds=2)
    summary = run_experiment(experiment, config, tmp_path, False)
    assert summary.extra["runs"] == 2 * (len(training.METHODS) + 1)
    payload = json.loads((tmp_path / "summary.json").read_text())
    for claim in payload["claims"]:
        assert claim["verdict"] in VERDICTS and claim["criterion"]
    assert set(payload["table"][SETTING]) == {*training.METHODS, "random"}
    assert [p.name for p in tmp_path.glob("*.png")] == [f"curves_{SETTING}.png"]
    again = run_experiment(experiment, config, tmp_path, False)
    assert [c.mean for c in again.claims] == [c.mean for c in summary.claims]
