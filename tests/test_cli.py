"""The ``delayed-rl train`` and ``evaluate`` commands: round trip, exit codes and messages."""

from __future__ import annotations

import re

import gymnasium as gym
import numpy as np
import pytest

from delayed_rl.agents import MultipleModelQLearning, QLearning, load_agent
from delayed_rl.cli import main

GRID = "delayed_rl/GridWorld-3x3-v0"


def _train(tmp_path, *extra: str) -> list[str]:
    return ["train", "--env", GRID, "--reward-delay", "3", "--steps", "30000", "--seed", "0",
            "--no-progress", "--save", str(tmp_path / "agent"), *extra]  # fmt: skip


def _average(text: str, unit: str) -> float:
    match = re.search(rf"(-?\d+\.\d+) per {unit}", text)
    assert match, text
    return float(match.group(1))


def test_train_saves_an_agent_that_evaluate_runs_greedily(tmp_path, capsys):
    assert main(_train(tmp_path, "--agent", "q")) == 0
    out = capsys.readouterr().out
    assert "trained QLearning on delayed_rl/GridWorld-3x3-v0" in out and "λ = 3" in out
    assert str(tmp_path / "agent.npz") in out
    training_average = _average(out, "step")
    assert 0.5 < training_average <= 2.0  # learned something; 2.0 = +10 every 5 steps (optimal)
    agent = load_agent(tmp_path / "agent.npz")
    assert isinstance(agent, QLearning) and agent.num_timesteps == 30_000
    assert agent.gamma == 0.9 and agent.exploration_rate == 0.1

    argv = ["evaluate", str(tmp_path / "agent.npz"), "--env", GRID, "--reward-delay", "3",
            "--steps", "500", "--seed", "1"]  # fmt: skip
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "for 500 steps" in out and "no episode ended" in out
    # evaluate reports the greedy policy's own average: replay it here, on the same seed.
    env = gym.make(GRID, reward_delay=3)
    obs, _ = env.reset(seed=1)
    total = 0.0
    for _ in range(500):
        obs, _, terminated, truncated, info = env.step(agent.predict(obs, deterministic=True)[0])
        total += info["undelayed_reward"]
        assert not (terminated or truncated)
    assert _average(out, "step") == pytest.approx(total / 500, abs=5e-5)


def test_train_passes_the_agent_options(tmp_path, capsys):
    options = ["--agent", "mmq", "--max-delay-estimate", "6", "--learning-rate", "0.2",
               "--gamma", "0.8", "--epsilon", "0.05", "--q-init", "10"]  # fmt: skip
    assert main(_train(tmp_path, *options)) == 0
    agent = load_agent(tmp_path / "agent.npz")
    assert isinstance(agent, MultipleModelQLearning)
    assert agent.delay_estimates == list(range(7))
    assert (agent.current_learning_rate, agent.gamma, agent.exploration_rate) == (0.2, 0.8, 0.05)
    assert agent.q_init == 10.0
    capsys.readouterr()
    assert main(_train(tmp_path, "--agent", "fixed", "--delay", "3")) == 0
    assert load_agent(tmp_path / "agent.npz").delay_estimates == [3]


def test_evaluate_counts_episodes_on_an_episodic_env(tmp_path, capsys):
    env = "delayed_rl/EPuckLineFollow-v0"
    argv = ["train", "--env", env, "--agent", "q", "--steps", "500", "--seed", "0",
            "--no-progress", "--save", str(tmp_path / "line")]  # fmt: skip
    assert main(argv) == 0
    capsys.readouterr()
    assert main(["evaluate", str(tmp_path / "line.npz"), "--env", env, "--episodes", "2"]) == 0
    out = capsys.readouterr().out
    assert "over 2 episode(s)" in out
    per_step, per_episode = _average(out, "step"), _average(out, "episode")
    steps = int(re.search(r"for (\d+) steps", out).group(1))
    # both are printed to 4 decimals: the per-step mean's rounding grows with the steps
    assert per_episode == pytest.approx(per_step * steps / 2, abs=1e-4 * (steps / 2 + 1))
    assert -1.0 <= per_step <= 1.0  # Eq. 5.7 rewards


def test_evaluate_with_episodes_on_a_continuing_env_fails_clearly(tmp_path, capsys):
    assert main(_train(tmp_path, "--agent", "q", "--steps", "100")) == 0
    capsys.readouterr()
    argv = ["evaluate", str(tmp_path / "agent.npz"), "--env", GRID, "--max-episode-steps", "50"]
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert err.startswith("error: no episode") and "--steps" in err and "Traceback" not in err


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["train", "--env", "delayed_rl/GridWorld-3x3", "--agent", "q", "--save", "x"],
         "unknown env id 'delayed_rl/GridWorld-3x3'; did you mean delayed_rl/GridWorld-3x3-v0"),
        (["train", "--env", GRID, "--agent", "sarsa", "--save", "x"], "invalid choice: 'sarsa'"),
        (["train", "--env", GRID, "--agent", "q"], "--save"),
        (["train", "--env", GRID, "--agent", "q", "--steps", "0", "--save", "x"],
         "--steps: must be an integer >= 1, got '0'"),
        (["train", "--env", GRID, "--agent", "q", "--steps", "ten", "--save", "x"],
         "--steps: must be an integer >= 1, got 'ten'"),
        (["train", "--env", GRID, "--agent", "q", "--gamma", "1.5", "--save", "x"],
         "--gamma: must be a number in [0.0, 1.0], got '1.5'"),
        (["train", "--env", GRID, "--agent", "q", "--learning-rate", "0", "--save", "x"],
         "--learning-rate: must be a number in (0.0, 1.0], got '0'"),
        (["train", "--env", GRID, "--agent", "q", "--reward-delay", "-2", "--save", "x"],
         "--reward-delay: must be a number >= 0.0, got '-2'"),
        (["train", "--env", GRID, "--agent", "q", "--q-init", "nan", "--save", "x"],
         "--q-init: must be a finite number, got 'nan'"),
        (["train", "--env", GRID, "--agent", "fixed", "--save", "x"], "--agent fixed needs --delay"),
        (["train", "--env", GRID, "--agent", "q", "--delay", "2", "--save", "x"],
         "--delay is for --agent fixed"),
        (["train", "--env", GRID, "--agent", "q", "--max-delay-estimate", "9", "--save", "x"],
         "--max-delay-estimate is for --agent mmq"),
        (["evaluate", "m.npz", "--env", "Nope-v9"], "unknown env id 'Nope-v9'"),
        (["evaluate", "m.npz", "--env", GRID, "--steps", "5", "--episodes", "2"],
         "not allowed with argument"),
    ],
)  # fmt: skip
def test_bad_usage_exits_with_code_2(argv, message, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert message in err and "usage: delayed-rl" in err


def test_every_command_has_help(capsys):
    for command in ("list", "train", "evaluate", "bench", "reproduce"):
        with pytest.raises(SystemExit) as exit_info:
            main([command, "--help"])
        assert exit_info.value.code == 0
        assert f"usage: delayed-rl {command}" in capsys.readouterr().out


def test_runtime_failures_exit_with_code_1_and_one_line(tmp_path, capsys):
    missing = ["evaluate", str(tmp_path / "missing"), "--env", GRID, "--steps", "5"]
    assert main(missing) == 1
    err = capsys.readouterr().err
    assert err == f"error: no model file at {tmp_path / 'missing'} (nor {tmp_path}/missing.npz)\n"

    assert main(_train(tmp_path, "--agent", "q", "--steps", "50")) == 0
    capsys.readouterr()
    other = ["evaluate", str(tmp_path / "agent.npz"), "--env", "delayed_rl/GridWorld-5x5-v0",
             "--steps", "5"]  # fmt: skip
    assert main(other) == 1
    err = capsys.readouterr().err
    assert err.startswith("error: cannot load") and "Discrete(25)" in err and "Discrete(9)" in err
    assert err.count("\n") == 1

    np.savez(tmp_path / "junk.npz", x=np.arange(3))  # an archive, but no delayed-rl model
    assert main(["evaluate", str(tmp_path / "junk.npz"), "--env", GRID, "--steps", "5"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "junk.npz" in err and err.count("\n") == 1

    continuous = ["train", "--env", "CartPole-v1", "--agent", "q", "--steps", "10",
                  "--save", str(tmp_path / "cart")]  # fmt: skip
    assert main(continuous) == 1
    err = capsys.readouterr().err
    assert err.startswith("error: cannot train QLearning on CartPole-v1") and "Discrete" in err
    assert not (tmp_path / "cart.npz").exists()


def test_train_fails_before_training_when_it_cannot_save(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    argv = _train(tmp_path, "--agent", "q")
    argv[argv.index("--save") + 1] = str(blocker / "agent")
    assert main(argv) == 1
    assert capsys.readouterr().err.startswith("error: cannot create the folder of --save")
