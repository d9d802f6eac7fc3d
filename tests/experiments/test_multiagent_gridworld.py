"""``delayed-rl bench multiagent-gridworld``: its tasks, shared runs, learners, claims, and a quick run."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from delayed_rl.agents import DeconvolutionQLearning, QLearning
from delayed_rl.delays import Poisson
from delayed_rl.experiments import LONG_NAMES, Config, get_experiment, run_experiment
from delayed_rl.experiments.beyond import multiagent_gridworld as game
from delayed_rl.experiments.framework.experiment import VERDICTS
from delayed_rl.experiments.framework.pool import pool_key


def test_the_full_run_has_both_delays_every_learner_and_five_seeds_sharing_the_oracle():
    experiment = get_experiment("multiagent-gridworld")
    assert "multiagent-gridworld" in LONG_NAMES and experiment.resumable
    tasks = experiment.tasks(Config(seeds=experiment.default_seeds))
    assert experiment.default_seeds >= 5
    assert len(tasks) == len(game.LAMS) * len(game.LEARNERS) * 5 == 40
    assert {t.lam for t in tasks} == {5, 10} and {t.steps for t in tasks} == {150_000}
    keys = {pool_key(experiment.run_of(t)) for t in tasks}
    assert len(keys) == 40 - 5  # Q undelayed: one run per seed, whatever the delay
    oracle = [t for t in tasks if t.agent == "Q undelayed" and t.seed == 3]
    assert len({pool_key(experiment.run_of(t)) for t in oracle}) == 1
    assert "lam" not in experiment.run_of(oracle[0]).task.to_json()
    deconv = [t for t in tasks if t.agent == "DeconvQ known" and t.seed == 3]
    assert len({pool_key(experiment.run_of(t)) for t in deconv}) == 2


def test_the_quick_run_is_one_delay_and_few_steps():
    tasks = get_experiment("multiagent-gridworld").tasks(Config(quick=True, seeds=2))
    assert len(tasks) == len(game.LEARNERS) * 2
    assert {(t.lam, t.steps) for t in tasks} == {(game.QUICK_LAM, game.QUICK_STEPS)}


def test_each_agent_gets_its_own_learner_of_the_tasks_kind():
    task = game.MultiagentGridTask(
        agent="DeconvQ known", lam=10, size=5, episode_steps=100, steps=1, seed=0
    )
    env = game.make_game(task)
    assert env.on_episode_end == "flush" and env.delays["agent_1"] == Poisson(10)
    spaces = game.AgentSpaces(env, "agent_0")
    assert spaces.observation_space.n == 25 and spaces.action_space.n == 4
    learner = game.make_learner(task, spaces, game.learner_seed(0, 0))
    assert isinstance(learner, DeconvolutionQLearning) and learner.on_episode_end == "flush"
    np.testing.assert_allclose(learner.delay_pmf[:20], Poisson(10).pmf(np.arange(20)), rtol=1e-6)
    assert (learner.learning_rate, learner.gamma, learner.q_init) == (0.1, 0.9, 25.0)
    learned = game.make_learner(dataclasses.replace(task, agent="DeconvQ learned"), spaces, 1)
    assert learned.delay is None and learned.delay_pmf.size == game.LAMBDA_MAX + 1
    assert type(game.make_learner(dataclasses.replace(task, agent="Q"), spaces, 1)) is QLearning
    undelayed = game.make_game(dataclasses.replace(task, agent="Q undelayed"))
    assert type(undelayed).__name__ == "CooperativeGridWorldEnv"  # no delay wrapper
    seeds = {game.learner_seed(s, i) for s in range(3) for i in range(2)}
    assert len(seeds) == 6 and all(0 <= s < 2**63 for s in seeds)


class Policy:
    """A learner stand-in whose greedy action is ``policy(cell)``."""

    def __init__(self, policy):
        self.policy = policy

    def predict(self, cells, deterministic=False):
        assert deterministic
        return np.array([self.policy(int(cell)) for cell in cells]), None


def test_the_greedy_score_is_the_optimum_for_the_optimal_joint_walk():
    walk = Policy(lambda cell: 0 if cell >= 5 else 3)  # up to the top row, then left
    stuck = Policy(lambda cell: 2)  # down: into the bottom wall for ever
    assert game.greedy_score({"agent_0": walk, "agent_1": walk}, 5, 100) == game.optimum()
    assert game.optimum() == pytest.approx(1.1)
    assert game.greedy_score({"agent_0": walk, "agent_1": stuck}, 5, 100) == -1.0
    assert game.greedy_score({"agent_0": stuck, "agent_1": stuck}, 5, 100) == -2.0


def test_a_tiny_run_trains_both_learners_and_gives_json_results():
    task = game.MultiagentGridTask(
        agent="DeconvQ learned", lam=3, size=3, episode_steps=20, steps=600, seed=1
    )
    result = game.train_and_score(task)
    assert result == json.loads(json.dumps(result))  # kept as JSON by a resumable run
    assert result["steps"] == list(range(20, 601, 20)) and len(result["greedy"]) == 30
    assert result["score"] == result["greedy"][-1]
    assert len(result["curve"]) == len(result["curve_steps"]) and result["curve_steps"][-1] == 600
    assert result["average"] == pytest.approx(result["curve"][-1])
    assert len(result["estimates"]) == 2 and 0 <= result["mean_delay"] <= game.LAMBDA_MAX
    assert game.train_and_score(task) == result  # seeded: the same run again
    other = game.train_and_score(dataclasses.replace(task, seed=2))
    assert other["curve"] != result["curve"]


def _result(score, mean_delay=None):
    result = {"steps": [1, 2], "greedy": [0.0, score], "score": score, "average": score / 2}
    result.update(curve_steps=[1, 2], curve=[0.0, score / 2])
    if mean_delay is not None:
        result.update(mean_delay=mean_delay, estimates=[[0.5, 0.5], [0.4, 0.6]])
    return result


def _summary(scores, delays):
    """A summary of made-up results: ``scores[agent]`` per seed, at λ = 10."""
    config = Config(seeds=len(scores["Q"]))
    tasks = [t for t in get_experiment("multiagent-gridworld").tasks(config) if t.lam == 10]
    results = [
        _result(scores[t.agent][t.seed], delays[t.seed]) for t in tasks
    ]  # every agent gets a mean delay: only DeconvQ learned's is read
    return game.summarize(tasks, results, config)


def test_the_claims_follow_the_runs():
    best = game.optimum()
    scores = {
        "Q": [0.0, -1.0, 0.0, 0.0, 1.1],
        "DeconvQ known": [best] * 5,
        "DeconvQ learned": [best, best, best, best, 0.0],
        "Q undelayed": [best] * 5,
    }
    claims = {c.quantity: c for c in _summary(scores, [10.2, 9.8, 10.1, 10.4, 9.9]).claims}
    label = "Poisson(10)"
    assert claims["Q undelayed, score / optimum (seeds ≥ 0.95)"].verdict == "agrees"
    assert claims[f"{label}: DeconvQ known minus Q score"].verdict == "agrees"
    assert claims[f"{label}: DeconvQ known minus Q score"].mean == pytest.approx(
        best - np.mean(scores["Q"])
    )
    assert claims[f"{label}: DeconvQ learned minus Q score"].verdict == "inconclusive"
    assert claims[f"{label}: DeconvQ learned, score / optimum (seeds ≥ 0.95)"].verdict == "agrees"
    assert claims[f"{label}: Q minus Q undelayed score"].verdict == "agrees"  # below 0
    assert claims[f"{label}: DeconvQ learned mean delay"].verdict == "agrees"
    assert claims[f"{label}: Q score"].verdict == "reference"
    scores["DeconvQ learned"] = [best, best, best, 0.0, 0.0]  # 3 of 5 optimal: below 4
    scores["Q"] = [best] * 5
    claims = {c.quantity: c for c in _summary(scores, [14.0, 13.0, 15.0, 12.5, 14.0]).claims}
    assert claims[f"{label}: DeconvQ learned, score / optimum (seeds ≥ 0.95)"].verdict == "differs"
    assert claims[f"{label}: DeconvQ known minus Q score"].verdict == "differs"  # ties: not above
    assert claims[f"{label}: Q minus Q undelayed score"].verdict == "differs"
    assert claims[f"{label}: DeconvQ learned mean delay"].verdict == "differs"


def test_the_table_counts_the_optimal_seeds():
    best = game.optimum()
    scores = {"Q": [0.0] * 5, "DeconvQ known": [best, best, 0.5, best, 1.0]}
    scores |= {"DeconvQ learned": [0.0] * 5, "Q undelayed": [best] * 5}
    table = _summary(scores, [10.0] * 5).extra["table"]["Poisson(10)"]
    assert table["DeconvQ known"]["optimal_seeds"] == 3  # 1.0 < 0.95 × 1.1
    assert table["DeconvQ known"]["scores"] == scores["DeconvQ known"]
    assert table["DeconvQ learned"]["mean_delay"] == [10.0] * 5


@pytest.mark.experiment
def test_a_tiny_quick_run_writes_its_files_and_resumes(tmp_path):
    config = Config(quick=True, seeds=2, steps=600)
    experiment = get_experiment("multiagent-gridworld")
    summary = run_experiment(experiment, config, tmp_path, False)
    assert summary.extra["runs"] == 2 * len(game.LEARNERS)
    payload = json.loads((tmp_path / "summary.json").read_text())
    for claim in payload["claims"]:
        assert claim["verdict"] in VERDICTS and claim["criterion"]
        assert math.isfinite(claim["mean"]) or claim["verdict"] == "inconclusive"
    assert set(payload["table"]["Poisson(10)"]) == set(game.LEARNERS)
    assert sorted(p.name for p in tmp_path.glob("*.png")) == [
        "delay_estimate_poisson10.png",
        "greedy_score_poisson10.png",
    ]
    assert len(list((tmp_path / "runs").glob("*.json"))) == 2 * len(game.LEARNERS)
    again = run_experiment(experiment, config, tmp_path, False)
    assert [c.mean for c in again.claims] == [c.mean for c in summary.claims]
