"""stable-baselines3's tools driving the tabular agents: callbacks, evaluate_policy, loggers."""

from __future__ import annotations

import csv
import warnings

import numpy as np
import pytest

from delayed_rl.agents import MultipleModelQLearning, QLearning
from delayed_rl.envs.gridworld import GridWorldEnv

# Every test imports stable-baselines3 (and so torch, over a second), each in its body: not at
# collection.
pytestmark = pytest.mark.sb3


def grid(size=5, max_steps=50):
    return GridWorldEnv(size=size, max_steps=max_steps)


def greedy_return(agent, env, steps):
    """The undiscounted return of the greedy policy over one episode, rolled out by hand."""
    obs, _ = env.reset()
    total = 0.0
    for _ in range(steps):
        obs, reward, terminated, truncated, _ = env.step(agent.predict(obs, deterministic=True)[0])
        total += reward
        if terminated or truncated:
            break
    return total


def test_eval_callback(tmp_path):
    from stable_baselines3.common.callbacks import EvalCallback
    from stable_baselines3.common.monitor import Monitor

    agent = QLearning(grid(max_steps=200), q_init=20.0, seed=0)
    callback = EvalCallback(
        Monitor(grid(max_steps=30)),
        eval_freq=500,
        n_eval_episodes=2,
        best_model_save_path=str(tmp_path),
        log_path=str(tmp_path),
        verbose=0,
    )
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # e.g. "Training and eval env are not of the same type"
        agent.learn(3_000, callback=callback)
    evaluations = np.load(tmp_path / "evaluations.npz")
    np.testing.assert_array_equal(evaluations["timesteps"], [500, 1000, 1500, 2000, 2500, 3000])
    assert evaluations["results"].shape == (6, 2)
    # the last evaluation is the greedy policy's deterministic return on the eval env
    assert evaluations["results"][-1, 0] == greedy_return(agent, grid(max_steps=30), 30)
    assert callback.last_mean_reward == evaluations["results"][-1].mean()
    best = QLearning.load(tmp_path / "best_model.npz")
    assert best.num_timesteps in evaluations["timesteps"]
    evals = [row for row in agent.logger.dumps if "eval/mean_reward" in row]  # SB3 logs via ours
    assert [row["step"] for row in evals] == [500, 1000, 1500, 2000, 2500, 3000]


def test_checkpoint_callback(tmp_path):
    from stable_baselines3.common.callbacks import CheckpointCallback

    agent = MultipleModelQLearning(grid(), max_delay_estimate=3, seed=0)
    agent.learn(2_000, callback=CheckpointCallback(save_freq=500, save_path=str(tmp_path)))
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == [f"rl_model_{n}_steps.zip" for n in (1000, 1500, 2000, 500)]
    assert MultipleModelQLearning.load(tmp_path / "rl_model_1500_steps.zip").num_timesteps == 1_500
    np.testing.assert_array_equal(
        MultipleModelQLearning.load(tmp_path / "rl_model_2000_steps.zip").q_table, agent.q_table
    )


def test_stop_on_max_episodes():
    from stable_baselines3.common.callbacks import StopTrainingOnMaxEpisodes

    agent = QLearning(grid(max_steps=100), seed=0)
    agent.learn(10_000, callback=StopTrainingOnMaxEpisodes(max_episodes=3))
    assert agent.num_timesteps == 300


@pytest.mark.filterwarnings("ignore::tqdm.TqdmExperimentalWarning")
def test_callback_list_and_progress_bar(tmp_path):
    from stable_baselines3.common.callbacks import (
        CallbackList,
        CheckpointCallback,
        ProgressBarCallback,
        StopTrainingOnMaxEpisodes,
    )

    progress = ProgressBarCallback()
    stop = StopTrainingOnMaxEpisodes(max_episodes=5)
    checkpoint = CheckpointCallback(save_freq=100, save_path=str(tmp_path))
    agent = MultipleModelQLearning(grid(max_steps=40), max_delay_estimate=4, seed=0)
    agent.learn(1_000, callback=CallbackList([progress, stop, checkpoint]))
    assert agent.num_timesteps == 200
    assert progress.pbar.n == 200 and progress.pbar.total == 1_000
    assert len(list(tmp_path.iterdir())) == 2
    # a plain list works too, and SB3 callbacks mix with progress_bar=True
    stop = StopTrainingOnMaxEpisodes(max_episodes=2)
    agent.learn(1_000, callback=[stop], progress_bar=True)
    assert agent.num_timesteps == 80


def test_evaluate_policy_matches_a_hand_rollout():
    from stable_baselines3.common.evaluation import evaluate_policy
    from stable_baselines3.common.monitor import Monitor

    agent = MultipleModelQLearning(
        grid(size=3, max_steps=500), max_delay_estimate=2, q_init=15.0, seed=1
    )
    agent.learn(5_000)
    mean, std = evaluate_policy(agent, Monitor(grid(size=3, max_steps=60)), n_eval_episodes=3)
    assert std == 0.0  # deterministic policy, deterministic env
    assert mean == greedy_return(agent, grid(size=3, max_steps=60), 60)
    assert mean == pytest.approx(60 / 5 * 10, abs=10)  # ~optimal: +10 every 5 steps
    rewards, lengths = evaluate_policy(
        agent, Monitor(grid(size=3, max_steps=20)), n_eval_episodes=2, return_episode_rewards=True
    )
    assert lengths == [20, 20] and len(rewards) == 2


def test_configure_logger_records_metrics(tmp_path):
    from stable_baselines3.common.logger import configure

    agent = MultipleModelQLearning(grid(max_steps=100), max_delay_estimate=5, seed=0)
    agent.set_logger(configure(str(tmp_path), ["csv"]))
    agent.learn(3_000, log_interval=1_000)
    with open(tmp_path / "progress.csv") as file:
        rows = list(csv.DictReader(file))
    assert [int(row["time/total_timesteps"]) for row in rows] == [1000, 2000, 3000]
    assert {
        "rollout/undelayed_reward_per_step",
        "rollout/ep_rew_mean",
        "rollout/exploration_rate",
        "train/learning_rate",
        "mmq/acting_delay_mean",
    } <= set(rows[0])
    assert float(rows[-1]["rollout/ep_len_mean"]) == 100.0
    assert int(rows[-1]["time/episodes"]) == 30
    with pytest.raises(TypeError, match="record\\(\\) and dump\\(\\)"):
        agent.set_logger(object())
