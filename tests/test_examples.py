"""The scripts in ``examples/`` run, on a smoke setting, and say what they should."""

from __future__ import annotations

import runpy
import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def run_example(name: str, *args: str, capsys: pytest.CaptureFixture) -> str:
    """Run ``examples/<name>`` as a script with ``args``; return what it printed."""
    argv = sys.argv
    sys.argv = [name, *args]
    try:
        runpy.run_path(str(EXAMPLES / name), run_name="__main__")
    finally:
        sys.argv = argv
    return capsys.readouterr().out


def test_own_tabular_env_trains_on_the_compiled_path(capsys):
    out = run_example("own_tabular_env.py", "--steps", "50000", capsys=capsys)
    lines = out.strip().splitlines()
    assert len(lines) == 2 and all("trained on the compiled path" in line for line in lines)
    assert "DeconvolutionQLearning: trained on the compiled path, greedy actions [1, 1]" in lines[1]


@pytest.mark.sb3
def test_sb3_ppo_and_dqn_train_on_delayed_rewards(capsys):
    out = run_example("sb3_delayed_rewards.py", "--steps", "300", capsys=capsys)
    assert "PPO, CartPole-v1, Poisson(5.0) reward delays: return" in out
    assert "DQN, Taxi-v4, Poisson(5.0) reward delays: return" in out


def test_minigrid_shows_the_flush_trap_and_carry(capsys):
    out = run_example("minigrid_carry.py", "--episodes", "30", capsys=capsys)
    flush, carry = out.strip().splitlines()
    assert flush == (
        'on_episode_end="flush": 30 of 30 rewards arrived at an episode\'s final step; warned: True'
    )
    at_end, total = (int(word) for word in carry.split(": ")[1].split()[:3:2])
    assert total >= 20 and at_end < total / 2 and carry.endswith("warned: False")


def test_robot_loop_learns_online_through_update(capsys):
    out = run_example("robot_loop.py", "--steps", "2000", capsys=capsys)
    lines = out.strip().splitlines()
    assert [line.split(":")[0] for line in lines] == [f"step {n}" for n in (500, 1000, 1500, 2000)]


@pytest.mark.sb3
def test_the_rl_zoo3_file_wraps_the_env_and_trains(tmp_path):
    import gymnasium as gym
    import yaml
    from rl_zoo3.utils import get_wrapper_class

    from delayed_rl.wrappers import PoissonRewardDelay

    config = EXAMPLES / "rl_zoo3" / "delayed_cartpole.yml"
    hyperparams = yaml.safe_load(config.read_text())["CartPole-v1"]
    wrapper = get_wrapper_class(hyperparams)
    env = wrapper(gym.make("CartPole-v1"))
    assert isinstance(env, PoissonRewardDelay) and env.lam == 5.0
    command = [
        sys.executable, "-m", "rl_zoo3.train", "--algo", "ppo", "--env", "CartPole-v1",
        "--conf-file", str(config), "-n", "1000", "--log-folder", str(tmp_path),
    ]  # fmt: skip
    subprocess.run(command, check=True, capture_output=True, timeout=300)
    saved = next(tmp_path.glob("ppo/CartPole-v1_*/CartPole-v1/config.yml")).read_text()
    assert "delayed_rl.wrappers.PoissonRewardDelay" in saved


@pytest.mark.sb3
@pytest.mark.parametrize(
    ("algo", "env_id", "conf", "options"),
    [
        ("sac", "Pendulum-v1", "delayed_pendulum_sac.yml", ["-n", "400", "--log-interval", "1"]),
        (
            "ppo",
            "CartPole-v1",
            "delayed_cartpole_ppo.py",
            ["-n", "1280", "--hyperparams", "n_steps:64"],
        ),
    ],
)
def test_the_rl_zoo3_files_train_with_a_reward_model(tmp_path, algo, env_id, conf, options):
    command = [
        sys.executable, "-m", "rl_zoo3.train", "--algo", algo, "--env", env_id, "--seed", "0",
        "--conf-file", str(EXAMPLES / "rl_zoo3" / conf), "--log-folder", str(tmp_path),
        "--eval-freq", "-1", *options,
    ]  # fmt: skip
    done = subprocess.run(command, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "| reward_model/" in done.stdout  # the callback logged the model (SB3 nests keys)
    rows = [line.split("|") for line in done.stdout.splitlines() if line.count("|") == 3]
    steps = [int(row[2]) for row in rows if row[1].strip() == "updates"]
    assert steps and steps[-1] > 0  # and it trained inside rl-zoo3's run


@pytest.mark.sb3
@pytest.mark.cold_cache
def test_rl_zoo3_seed_makes_a_reward_model_run_repeatable(tmp_path):
    """``--seed`` seeds the mapping's model through the algorithm: two runs, the same bits."""
    import torch
    from stable_baselines3 import SAC

    def train(folder):
        command = [
            sys.executable, "-m", "rl_zoo3.train", "--algo", "sac", "--env", "Pendulum-v1",
            "--seed", "3", "--conf-file", str(EXAMPLES / "rl_zoo3" / "delayed_pendulum_sac.yml"),
            "--log-folder", str(folder), "--eval-freq", "-1", "-n", "300",
        ]  # fmt: skip
        done = subprocess.run(command, capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, done.stderr[-3000:]
        agent = SAC.load(next(folder.rglob("Pendulum-v1.zip")), device="cpu")
        return agent.policy.state_dict(), agent.replay_buffer_kwargs["reward_model"]

    (policy, model), (again, model_again) = train(tmp_path / "a"), train(tmp_path / "b")
    assert model.ready and model.updates_taken == model_again.updates_taken
    assert model.seed == model_again.seed
    assert all(torch.equal(policy[name], again[name]) for name in policy)
    weights, weights_again = model.network.state_dict(), model_again.network.state_dict()
    assert all(torch.equal(weights[name], weights_again[name]) for name in weights)
