"""The compiled path of ``learn()``: the same rule as the Python path, chosen automatically."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import delayed_rl  # noqa: F401
from delayed_rl.agents import FixedDelayQLearning, MultipleModelQLearning, QLearning
from delayed_rl.agents.common.callbacks import BaseCallback
from delayed_rl.agents.common.schedules import LinearSchedule
from delayed_rl.compiled import NotCompilable
from delayed_rl.compiled.kernel import replay
from delayed_rl.delays import Geometric
from delayed_rl.wrappers import RewardDelay


@pytest.mark.parametrize("lags", [[0], [3], list(range(10)), [0, 2, 5, 11]])
def test_scripted_transitions_give_identical_tables(lags):
    """Python ``update()`` and the compiled loop on one scripted sequence: equal to the bit."""
    rng = np.random.default_rng(len(lags))
    n = 3000
    transitions = rng.integers(0, [6, 4, 6], size=(n, 3))  # (s, a, s') on 6 of the 81 cells
    rewards = rng.normal(scale=2.0, size=n)
    terminated = rng.random(n) < 0.02
    agent = MultipleModelQLearning(
        "delayed_rl/GridWorld-v0", delay_estimates=lags, q_init=1.0, gamma=0.9
    )
    for (s, a, s2), reward, done in zip(transitions, rewards, terminated, strict=True):
        agent.update(int(s), int(a), float(reward), int(s2), bool(done))
    q = np.full(agent.q_table.shape, 1.0)
    replay(q, np.array(lags), transitions, terminated, rewards, 0.1, 0.9)
    np.testing.assert_array_equal(agent.q_table, q)


def _mean_rewards(make_agent, compiled: bool, seeds: range) -> np.ndarray:
    """Each seed's mean undelayed training reward over 20k steps, on one path."""
    out = []
    for seed in seeds:
        agent = make_agent(seed)
        agent.learn(20_000, record=True, compiled=compiled)
        assert agent.last_learn_path == ("compiled" if compiled else "python")
        out.append(agent.training_log["undelayed_reward"].mean())
    return np.array(out)


def _assert_paths_agree(make_agent, n_seeds: int) -> tuple[np.ndarray, np.ndarray]:
    """Both paths on disjoint seeds: mean rewards equal within 4 standard errors of the gap."""
    compiled = _mean_rewards(make_agent, True, range(n_seeds))
    python = _mean_rewards(make_agent, False, range(100, 100 + n_seeds))
    gap_se = np.sqrt(compiled.var(ddof=1) / compiled.size + python.var(ddof=1) / python.size)
    assert abs(compiled.mean() - python.mean()) < 4 * gap_se + 1e-3 * compiled.mean(), (
        compiled,
        python,
    )
    return compiled, python


@pytest.mark.statistical
def test_seeded_runs_agree_in_distribution():
    """MMQ on GridWorld-5x5 under Poisson(5) delays, 6 seeds a path."""

    def make_agent(seed):
        env = gym.make("delayed_rl/GridWorld-5x5-v0", reward_delay=5)
        return MultipleModelQLearning(env, delay_estimates=list(range(9)), q_init=10.0, seed=seed)

    compiled, _ = _assert_paths_agree(make_agent, 6)
    assert compiled.mean() > 0.3  # both learn the 9-step route (optimum 10/9 ≈ 1.11)


@pytest.mark.statistical
def test_seeded_runs_agree_on_a_gymnasium_env_with_other_delays():
    """Q-learning on FrozenLake (its own ``P`` tables, slippery) under Geometric delays."""

    def make_agent(seed):
        lake = gym.make("FrozenLake-v1").unwrapped
        return QLearning(RewardDelay(lake, Geometric(0.3)), q_init=1.0, seed=seed)

    _, python = _assert_paths_agree(make_agent, 8)
    assert python.mean() > 0.005  # both learn to reach the goal (random play: about 0.002 a step)


@pytest.mark.filterwarnings("ignore:reset\\(\\) in the middle of an episode")
def test_auto_falls_back_and_can_be_switched_off_or_forced():
    scaled = gym.make("delayed_rl/GridWorld-3x3-v0", reward_delay=2)
    scaled = gym.wrappers.TransformReward(scaled, lambda r: 2.0 * r)
    agent = QLearning(scaled, seed=0).learn(500)
    assert agent.last_learn_path == "python"
    with pytest.raises(NotCompilable, match="TransformReward"):
        agent.learn(500, compiled=True)
    scheduled = QLearning(
        "delayed_rl/GridWorld-3x3-v0", learning_rate=LinearSchedule(0.5, 0.1, 1.0)
    )
    assert scheduled.learn(500).last_learn_path == "python"
    with pytest.raises(NotCompilable, match="schedule"):
        scheduled.learn(500, compiled=True)
    plain = QLearning("delayed_rl/GridWorld-3x3-v0", seed=0)
    assert plain.learn(500).last_learn_path == "compiled"
    assert plain.learn(500, compiled=False).last_learn_path == "python"
    with pytest.raises(TypeError, match="compiled must be a bool"):
        plain.learn(10, compiled="yes")


def test_compiled_fills_the_diagnostics_and_the_record():
    agent = MultipleModelQLearning(
        gym.make("delayed_rl/GridWorld-5x5-v0", reward_delay=3), max_delay_estimate=6, seed=1
    )
    agent.learn(5000, record=True, log_interval=1000)
    assert agent.last_learn_path == "compiled" and agent.num_timesteps == 5000
    assert {key: len(value) for key, value in agent.training_log.items()} == dict.fromkeys(
        agent.training_log, 5000
    )
    assert agent.acting_delay_share.sum() == pytest.approx(1.0)
    counts = np.bincount(agent.training_log["acting_delay_index"], minlength=7)
    np.testing.assert_allclose(agent.acting_delay_share, counts / 5000)
    agent.learn(3000, reset_num_timesteps=False)
    assert agent.num_timesteps == 8000


def test_grid_dynamics_and_cache_hold_on_the_fused_path():
    agent = FixedDelayQLearning(gym.make("delayed_rl/GridWorld-3x3-v0"), delay_estimate=0, seed=4)
    agent.learn(4000, record=True)
    log = agent.training_log
    env = gym.make("delayed_rl/GridWorld-3x3-v0").unwrapped
    np.testing.assert_array_equal(
        log["undelayed_reward"], env.reward_table[log["obs"], log["action"]]
    )
    np.testing.assert_array_equal(log["obs"][1:], env.next_state[log["obs"], log["action"]][:-1])
    flat = agent.q_table.reshape(9, -1)
    np.testing.assert_array_equal(agent._table.v_max, flat.max(axis=1))


def test_callbacks_see_every_step_and_stop_at_the_chunk_end():
    class Recorder(BaseCallback):
        def _init_callback(self):
            self.seen = []

        def _on_step(self):
            step = self.locals
            done = bool(step["dones"][0])
            self.seen.append(
                (self.num_timesteps, step["obs"], step["action"], step["undelayed_reward"], done)
            )
            return self.num_timesteps < 2700

    recorder = Recorder()
    agent = QLearning("delayed_rl/GridWorld-3x3-v0", seed=0)
    agent.compiled_chunk = 500
    agent.learn(10_000, callback=recorder, record=True, compiled=True)
    assert agent.last_learn_path == "compiled"
    assert recorder.n_calls == 2700 and agent.num_timesteps == 3000  # stops at its chunk's end
    steps, obs, actions, rewards, _ = map(np.array, zip(*recorder.seen, strict=True))
    np.testing.assert_array_equal(steps, np.arange(1, 2701))
    log = agent.training_log
    np.testing.assert_array_equal(obs, log["obs"][:2700])
    np.testing.assert_array_equal(actions, log["action"][:2700])
    np.testing.assert_array_equal(rewards, log["undelayed_reward"][:2700])


@pytest.mark.parametrize("mode", ["flush", "drop", "carry"])
def test_the_compiled_delay_line_is_the_reward_delay_rule(mode, monkeypatch):
    """Every step's delivered reward is the rule's (``ReferenceRewardDelay``), fed the same delays.

    Taxi: rewards at every step (−1, −10, +20), episodes cut by its time limit below the
    wrapper, so flushes, drops and carries all happen.
    """
    from delayed_rl.compiled.run import CompiledRun
    from delayed_rl.delays import Poisson
    from delayed_rl.wrappers.reference import ReferenceRewardDelay

    drawn: list[np.ndarray] = []
    draw = CompiledRun._draw_delays

    def recorded(self, n):
        delays = draw(self, n)
        drawn.append(delays.copy())
        return delays

    monkeypatch.setattr(CompiledRun, "_draw_delays", recorded)
    env = RewardDelay(gym.make("Taxi-v4"), Poisson(4.0), on_episode_end=mode)
    agent = QLearning(env, q_init=0.0, seed=3).learn(6_000, compiled=True, record=True)
    assert agent.last_learn_path == "compiled"
    log, delays = agent.training_log, np.concatenate(drawn)
    assert delays.size == log["reward"].size and log["episode_end"].sum() >= 20
    reference = ReferenceRewardDelay(mode)
    for emitted, delay, ended, delivered in zip(
        log["undelayed_reward"].tolist(), delays.tolist(), log["episode_end"].tolist(),
        log["reward"].tolist(), strict=True,
    ):  # fmt: skip
        assert delivered == pytest.approx(reference.delivered(emitted, delay, ended), abs=1e-9)


def test_the_compiled_path_warns_at_the_line_that_called_learn():
    """Both warnings of a compiled ``learn()`` name the caller's line, not the library's.

    A TimeLimit above the RewardDelay makes the resets discard pending reward, and a delay far
    longer than the episodes trips the flush-trap watch.
    """
    grid = gym.make("delayed_rl/GridWorld-v0", size=4).unwrapped
    env = gym.wrappers.TimeLimit(RewardDelay(grid, Geometric(0.01)), 30)
    agent = QLearning(env, seed=0)
    with pytest.warns(UserWarning) as caught:
        agent.learn(3000, compiled=True)
    messages = {str(w.message).split(":")[0]: w for w in caught}
    cut = messages["a TimeLimit above the RewardDelay cut episodes short"]
    assert cut.filename == __file__
    assert all(w.filename == __file__ for w in caught), [(w.filename, w.message) for w in caught]
