"""The SB3-like shell: construction, learn/predict/update, schedules, callbacks, logging, errors."""

from __future__ import annotations

import io
import subprocess
import sys
import textwrap

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces
from gymnasium.wrappers import DiscretizeObservation

import delayed_rl
from delayed_rl.agents import (
    RECORD_KEYS,
    FixedDelayQLearning,
    LinearSchedule,
    MultipleModelQLearning,
    QLearning,
)
from delayed_rl.agents.common.callbacks import BaseCallback, ProgressBarCallback
from delayed_rl.envs.gridworld import GridWorldEnv

GRID5 = "delayed_rl/GridWorld-5x5-v0"


class ShiftedEnv(gym.Env):
    """States 5..7 (Discrete(3, start=5)), actions −1..0 (Discrete(2, start=−1)); 10-step episodes."""

    def __init__(self):
        self.observation_space = spaces.Discrete(3, start=5)
        self.action_space = spaces.Discrete(2, start=-1)
        self.state, self.t = 5, 0

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.state, self.t = 5, 0
        return self.state, {}

    def step(self, action):
        assert self.action_space.contains(action), action
        self.state = 5 + (self.state - 5 + (1 if action == 0 else 2)) % 3
        self.t += 1
        return self.state, float(self.state == 7), self.t >= 10, False, {}


def test_public_exports():
    assert delayed_rl.MultipleModelQLearning is MultipleModelQLearning is MultipleModelQLearning
    assert delayed_rl.QLearning is QLearning
    assert delayed_rl.FixedDelayQLearning is FixedDelayQLearning
    from delayed_rl.agents import ProportionalController
    from delayed_rl.agents.proportional import ProportionalController as Controller

    assert ProportionalController is Controller


@pytest.mark.sb3
def test_env_id_string_and_get_env():
    agent = QLearning(GRID5, seed=0)
    assert isinstance(agent.env, gym.Env)
    assert agent.observation_space == spaces.Discrete(25)
    venv = agent.get_env()
    assert venv.num_envs == 1 and venv.envs[0] is agent.env
    assert agent.get_vec_normalize_env() is None


def test_set_env_checks_spaces():
    agent = QLearning(GRID5)
    agent.set_env(gym.make(GRID5, reward_delay=2))
    with pytest.raises(ValueError, match=r"observation_space is Discrete\(9\).*Discrete\(25\)"):
        agent.set_env("delayed_rl/GridWorld-3x3-v0")
    with pytest.raises(TypeError, match="env must be a gymnasium.Env or a registered env id"):
        agent.set_env(42)


@pytest.mark.sb3
def test_vec_env_is_refused_with_a_hint():
    from stable_baselines3.common.vec_env import DummyVecEnv

    with pytest.raises(TypeError, match=r"venv.envs\[0\]"):
        QLearning(DummyVecEnv([lambda: GridWorldEnv(size=3)]))


def test_non_discrete_spaces_say_how_to_discretise():
    with pytest.raises(TypeError, match="Discrete observation_space.*DiscretizeObservation"):
        QLearning(gym.make("MountainCar-v0"))
    continuous_actions = DiscretizeObservation(gym.make("MountainCarContinuous-v0"), bins=5)
    with pytest.raises(TypeError, match="Discrete action_space.*DiscretizeAction"):
        MultipleModelQLearning(continuous_actions)
    # following the hint works
    agent = QLearning(DiscretizeObservation(gym.make("MountainCar-v0"), bins=10), seed=0)
    assert agent.q_table.shape == (100, 1, 3)
    assert agent.learn(300).num_timesteps == 300


@pytest.mark.parametrize(
    ("kwargs", "error", "message"),
    [
        ({"learning_rate": 0.0}, ValueError, r"learning_rate must be a number in \(0, 1\], got 0.0"),
        ({"learning_rate": 1.5}, ValueError, r"learning_rate must be a number in \(0, 1\], got 1.5"),
        ({"learning_rate": "fast"}, TypeError, r"learning_rate must be a number in \(0, 1\]"),
        ({"gamma": 1.2}, ValueError, r"gamma must be a number in \[0, 1\], got 1.2"),
        ({"gamma": "0.5"}, TypeError, r"gamma must be a number in \[0, 1\], got '0.5' \(str\)"),
        ({"gamma": float("nan")}, ValueError, "gamma must be a number in"),
        ({"exploration_initial_eps": -0.1}, ValueError, "exploration_initial_eps must be a number"),
        ({"exploration_final_eps": 2}, ValueError, "exploration_final_eps must be a number in"),
        ({"exploration_final_eps": None}, TypeError, "exploration_final_eps must be a number in"),
        ({"exploration_fraction": 0}, ValueError, r"exploration_fraction must be a number in \(0, 1\]"),
        ({"q_init": float("inf")}, ValueError, "q_init must be a finite number, got inf"),
        ({"q_init": "high"}, TypeError, "q_init must be a finite number, got 'high'"),
        ({"q_init": True}, TypeError, "q_init must be a finite number, got True"),
        ({"seed": -1}, ValueError, "seed must be None or an integer >= 0, got -1"),
        ({"seed": 1.5}, TypeError, "seed must be None or an integer >= 0, got 1.5"),
        ({"seed": "5"}, TypeError, "seed must be None or an integer >= 0, got '5'"),
        ({"verbose": -1}, ValueError, "verbose must be an integer >= 0"),
        ({"verbose": "1"}, TypeError, "verbose must be an integer >= 0"),
    ],
)  # fmt: skip
def test_bad_hyperparameters_name_argument_and_value(kwargs, error, message):
    """Wrong type: TypeError; right type out of range: ValueError; the message names both."""
    with pytest.raises(error, match=message) as raised:
        MultipleModelQLearning(GRID5, max_delay_estimate=3, **kwargs)
    assert type(raised.value) is error


def test_bad_learn_arguments():
    agent = QLearning(GRID5)
    for value, error in ((-1, ValueError), (1.5, TypeError), (True, TypeError), ("10", TypeError)):
        with pytest.raises(error, match="total_timesteps must be an integer >= 0"):
            agent.learn(value)
    with pytest.raises(ValueError, match="log_interval must be None or an integer >= 1, got 0"):
        agent.learn(10, log_interval=0)
    with pytest.raises(TypeError, match=r"reset_num_timesteps must be a bool, got 1 \(int\)"):
        agent.learn(10, reset_num_timesteps=1)
    with pytest.raises(TypeError, match="compiled must be a bool, got 'yes'"):
        agent.learn(10, compiled="yes")
    with pytest.raises(TypeError, match="callback must be None, a callback object"):
        agent.learn(10, callback=42)
    with pytest.raises(TypeError, match=r"callback\[1\] must be None"):
        agent.learn(10, callback=[lambda *_: True, "x"])
    assert agent.num_timesteps == 0


def test_bad_update_arguments():
    agent = QLearning(GRID5)
    with pytest.raises(ValueError, match=r"obs must be an integer in Discrete\(25\), got 25"):
        agent.update(25, 0, 0.0, 1)
    with pytest.raises(TypeError, match=r"obs must be an integer in Discrete\(25\), got '3'"):
        agent.update("3", 0, 0.0, 1)
    with pytest.raises(ValueError, match="next_obs must be an integer"):
        agent.update(0, 0, 0.0, -1)
    with pytest.raises(ValueError, match=r"action must be an integer in Discrete\(4\), got 4"):
        agent.update(0, 4, 0.0, 1)
    with pytest.raises(ValueError, match="reward must be a finite number, got nan"):
        agent.update(0, 0, float("nan"), 1)
    with pytest.raises(TypeError, match="reward must be a finite number, got '1'"):
        agent.update(0, 0, "1", 1)
    with pytest.raises(TypeError, match="terminated must be a bool, got 'yes'"):
        agent.update(0, 0, 0.0, 1, terminated="yes")
    assert agent.num_timesteps == 0 and np.all(agent.q_table == 0.0)


def test_predict_single_batched_and_validated():
    agent = MultipleModelQLearning(GRID5, max_delay_estimate=3, q_init=5.0, seed=0).learn(2_000)
    action, state = agent.predict(24, deterministic=True)
    assert isinstance(action, int) and state is None
    assert agent.predict(np.int64(24), deterministic=True)[0] == action
    assert agent.predict(np.array(24), deterministic=True)[0] == action
    batch, _ = agent.predict([24, 0, 12], deterministic=True)
    assert batch.shape == (3,) and batch[0] == action
    rows = agent.q_table.reshape(25, -1)
    np.testing.assert_array_equal(
        agent.predict(np.arange(25), deterministic=True)[0], rows.argmax(axis=1) % 4
    )
    for bad, error in (
        (25, ValueError),
        (-1, ValueError),
        ([[1, 2]], ValueError),
        (2.5, TypeError),
        ("3", TypeError),
        (True, TypeError),
    ):
        with pytest.raises(error, match="observation"):
            agent.predict(bad)


def test_predict_explores_without_touching_training_stream():
    agent = QLearning(GRID5, exploration_initial_eps=1.0, exploration_final_eps=1.0, seed=0)
    state_before = agent._uniform.get_state()
    actions = agent.predict(np.zeros(4000, dtype=int))[0]
    counts = np.bincount(actions, minlength=4)  # ε = 1: uniform; sd of a count ≈ 27.4
    assert np.all(np.abs(counts - 1000) < 5 * np.sqrt(4000 * 0.25 * 0.75))
    after = agent._uniform.get_state()
    assert state_before[0] == after[0] and np.array_equal(state_before[1], after[1])


def test_shifted_discrete_spaces():
    agent = QLearning(ShiftedEnv(), q_init=1.0, seed=0).learn(500, record=True)
    assert set(np.unique(agent.training_log["obs"])) <= {5, 6, 7}
    assert set(np.unique(agent.training_log["action"])) == {-1, 0}
    assert agent.predict(7, deterministic=True)[0] in (-1, 0)
    agent.update(5, -1, 1.0, 7)
    with pytest.raises(ValueError, match="obs must be an integer"):
        agent.update(4, -1, 1.0, 5)


def test_learn_on_continuing_env_and_record():
    env = gym.make(GRID5, reward_delay=3)
    agent = MultipleModelQLearning(env, max_delay_estimate=6, q_init=10.0, seed=1)
    assert agent.learn(3_000, record=True, compiled=False) is agent  # steps the env object itself
    log = agent.training_log
    assert set(log) == set(RECORD_KEYS)
    assert all(len(v) == 3_000 for v in log.values())
    assert not log["episode_end"].any() and agent.num_timesteps == 3_000
    # every reward emitted is either delivered or still pending (the wrapper's own books)
    pending = env.get_wrapper_attr("pending_reward")
    assert log["reward"].sum() + pending == pytest.approx(log["undelayed_reward"].sum())
    assert not np.array_equal(log["reward"], log["undelayed_reward"])
    # obs[t + 1] is where action t led (no episode ends here)
    world = GridWorldEnv(size=5)
    np.testing.assert_array_equal(
        world.next_state[log["obs"][:-1], log["action"][:-1]], log["obs"][1:]
    )


def test_episode_end_resets_env_and_history():
    env = GridWorldEnv(size=5, max_steps=100)
    agent = MultipleModelQLearning(env, max_delay_estimate=5, q_init=10.0, seed=2).learn(
        1_050, record=True, compiled=False
    )
    done = agent.training_log["episode_end"]
    np.testing.assert_array_equal(np.flatnonzero(done), np.arange(99, 1_000, 100))
    starts = np.flatnonzero(done) + 1
    assert np.all(agent.training_log["obs"][starts] == 24)  # reset to the start cell
    assert agent._episode_step == 50  # the history restarted at the last reset
    assert agent.logger.dumps[-1]["time/episodes"] == 10


@pytest.mark.parametrize("compiled", [False, True])
def test_reset_num_timesteps_false_continues_exactly(compiled):
    """learn(a) + learn(b, reset_num_timesteps=False) == learn(a + b) with constant schedules."""
    one = MultipleModelQLearning(
        gym.make(GRID5, reward_delay=2), max_delay_estimate=4, q_init=8.0, seed=3
    )
    one.learn(1_500, compiled=compiled)
    two = MultipleModelQLearning(
        gym.make(GRID5, reward_delay=2), max_delay_estimate=4, q_init=8.0, seed=3
    )
    two.learn(1_000, compiled=compiled).learn(500, reset_num_timesteps=False, compiled=compiled)
    assert two.num_timesteps == 1_500
    np.testing.assert_array_equal(one.q_table, two.q_table)
    if compiled:  # the compiled path never stepped the env object: nothing pending to report
        return
    # the default restarts the clock and resets the env (to the start cell)
    with pytest.warns(UserWarning, match="reset\\(\\) in the middle of an episode"):
        two.learn(
            10, record=True, compiled=False
        )  # the wrapper reports the pending rewards it drops
    assert two.num_timesteps == 10 and two.training_log["obs"][0] == 24


def test_same_seed_same_run_other_seed_other_run():
    def table(seed):
        return (
            QLearning(gym.make(GRID5, reward_delay=2), q_init=5.0, seed=seed).learn(2_000).q_table
        )

    np.testing.assert_array_equal(table(4), table(4))
    assert not np.array_equal(table(4), table(5))


def test_learning_rate_schedule_gets_progress_remaining():
    seen = []

    def schedule(progress_remaining):
        seen.append(progress_remaining)
        return 0.1

    scheduled = QLearning(gym.make(GRID5), learning_rate=schedule, q_init=5.0, seed=0).learn(1_000)
    constant = QLearning(gym.make(GRID5), learning_rate=0.1, q_init=5.0, seed=0)
    constant.learn(
        1_000, compiled=False
    )  # a schedule runs on the Python path: compare like with like
    np.testing.assert_array_equal(scheduled.q_table, constant.q_table)
    assert seen[-1] == pytest.approx(1 / 1_000) and max(seen) == 1.0
    assert all(a >= b for a, b in zip(seen[1:], seen[2:], strict=False))
    with pytest.raises(
        ValueError, match=r"learning_rate schedule must return a number in \(0, 1\]"
    ):
        QLearning(gym.make(GRID5), learning_rate=lambda p: 2.0)
    fading = QLearning(gym.make(GRID5), learning_rate=lambda p: 0.1 if p > 0.5 else 0.0)
    with pytest.raises(ValueError, match="got 0.0 at progress_remaining=0.5"):
        fading.learn(10)


@pytest.mark.sb3
def test_exploration_schedule_matches_sb3_linear_schedule():
    from stable_baselines3.common.utils import LinearSchedule as SB3Linear

    ours, theirs = LinearSchedule(1.0, 0.05, 0.3), SB3Linear(1.0, 0.05, 0.3)
    for p in np.linspace(0, 1, 11):
        assert ours(p) == pytest.approx(theirs(p))
    agent = QLearning(
        GRID5, exploration_initial_eps=1.0, exploration_final_eps=0.0, exploration_fraction=0.5
    )
    agent.learn(2_000, log_interval=500)
    rates = [row["rollout/exploration_rate"] for row in agent.logger.dumps]
    assert rates[0] == pytest.approx(1.0 - 499 / 1_000) and rates[-1] == 0.0
    assert agent.exploration_rate == 0.0


def test_callable_callback_sees_locals_and_can_stop():
    calls = []

    def callback(locals_, globals_):
        calls.append(
            (locals_["self"].num_timesteps, locals_["undelayed_reward"], locals_["dones"][0])
        )
        assert set(locals_) >= {"new_obs", "actions", "rewards", "infos", "total_timesteps"}
        return None if len(calls) < 30 else False

    agent = QLearning(gym.make(GRID5, reward_delay=2), seed=0)
    agent.learn(1_000, callback=callback)
    assert agent.num_timesteps == 30 and [c[0] for c in calls] == list(range(1, 31))


def test_own_callback_class_and_list():
    class Count(BaseCallback):
        def _on_training_start(self):
            self.start_total = self.locals["total_timesteps"]

        def _on_step(self):
            return True

    first, second = Count(), Count()
    agent = QLearning(GRID5).learn(100)
    agent.learn(50, callback=[first, second], reset_num_timesteps=False)
    assert first.n_calls == second.n_calls == 50
    assert first.start_total == 150 and first.model is agent and second.num_timesteps == 150


def test_text_progress_bar():
    stream = io.StringIO()
    QLearning(GRID5).learn(2_000, callback=ProgressBarCallback(stream=stream, use_tqdm=False))
    assert "100%" in stream.getvalue() and "2000/2000 steps" in stream.getvalue()


def test_progress_bar_flag_shows_a_bar(capsys):
    QLearning(GRID5).learn(1_000, progress_bar=True)
    assert "1000/1000" in capsys.readouterr().err.replace(",", "")


def test_default_logger_prints_when_verbose(capsys):
    QLearning(GRID5, verbose=1).learn(200, log_interval=100)
    out = capsys.readouterr().out
    assert out.count("time/total_timesteps") == 2 and "rollout/undelayed_reward_per_step" in out
    QLearning(GRID5, verbose=0).learn(200, log_interval=100)
    assert capsys.readouterr().out == ""


@pytest.mark.cold_cache
def test_works_without_stable_baselines3_or_tqdm():
    """A fresh interpreter where stable_baselines3 and tqdm cannot be imported."""
    code = textwrap.dedent(
        """
        import sys
        sys.modules["stable_baselines3"] = None
        sys.modules["tqdm"] = None
        import delayed_rl
        from delayed_rl.agents import MultipleModelQLearning
        steps = []
        agent = MultipleModelQLearning("delayed_rl/GridWorld-3x3-v0", max_delay_estimate=3, seed=0)
        agent.learn(500, callback=lambda l, g: steps.append(l["reward"]), progress_bar=True)
        assert len(steps) == 500 and agent.num_timesteps == 500
        venv = agent.get_env()
        assert type(venv).__name__ == "SingleEnvVecView" and venv.num_envs == 1
        obs = venv.reset()
        assert obs.shape == (1,)
        assert "torch" not in sys.modules
        print("ok")
        """
    )
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "ok"
    assert "100%" in result.stderr and "500/500 steps" in result.stderr


class HugeEnv(gym.Env):
    """10⁸ states: its spaces are cheap, a Q-table of it is not."""

    observation_space = spaces.Discrete(10**8)
    action_space = spaces.Discrete(4)


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (
            lambda: FixedDelayQLearning(GRID5, delay_estimate=10**9),
            r"delay_estimate must keep the tables within MAX_TABLE_BYTES = 1 GiB .*got 1000000000",
        ),
        (
            lambda: MultipleModelQLearning(GRID5, max_delay_estimate=1025),
            r"max_delay_estimate must be at most MAX_DELAY_ESTIMATE = 1024 .*got 1025",
        ),
        (  # the same limit as every agent's, however coarse Λ's step
            lambda: MultipleModelQLearning(GRID5, max_delay_estimate=10**30, delay_step=10**29),
            r"max_delay_estimate must be at most MAX_DELAY_ESTIMATE = 1024 .*got 10{30}",
        ),
        (
            lambda: MultipleModelQLearning(GRID5, delay_estimates=[0, 10**30]),
            r"delay_estimates must keep the tables .*got \[0, 10+\]",
        ),
        pytest.param(  # 100,000 delays checked one by one under tracemalloc
            lambda: MultipleModelQLearning(GRID5, delay_estimates=range(0, 10**8, 10**3)),
            r"delay_estimates must keep the tables .*got \[0, \.\.\., 99999000\] \(100000 values\)",
            marks=pytest.mark.large,
        ),
        (
            lambda: MultipleModelQLearning(HugeEnv()),
            r"MultipleModelQLearning\(max_delay_estimate=50\) on an env of 100000000 states and 4 "
            r"actions needs 15\d GiB of tables .*over MAX_TABLE_BYTES",
        ),
        (lambda: QLearning(HugeEnv()), r"^QLearning on an env of 100000000 states .* 4.4\d GiB"),
    ],
)
def test_tables_over_the_limit_are_refused_before_allocating(make, message):
    import tracemalloc

    tracemalloc.start()
    try:
        with pytest.raises(ValueError, match=message):
            make()
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 64 * 2**20


def test_the_table_limit_fits_the_thesis_and_far_larger():
    from delayed_rl.agents.common.q_table import MAX_TABLE_BYTES, table_bytes

    assert table_bytes(81, 4, 51, 50) < 2**18  # the thesis's 9×9 grid world, Λ = 0..50
    assert table_bytes(10**5, 10, 101, 100) < MAX_TABLE_BYTES  # 10⁵ states, 101 delay models
    agent = MultipleModelQLearning("delayed_rl/GridWorld-9x9-v0", max_delay_estimate=50)
    assert agent.q_table.nbytes == 81 * 51 * 4 * 8
    QLearning(DiscretizeObservation(gym.make("MountainCar-v0"), bins=300))  # 90 000 states


# ---------------------------------------------------------------------- clear errors, bounded work
@pytest.mark.parametrize(
    ("args", "error", "match"),
    [
        ((0, np.array([1, 2]), 1.0, 1), TypeError, r"action must be an integer in Discrete\(4\) "
         r"\(one int, or a 0-d integer array\), got array\(\[1, 2\]\): an array of shape \(2,\)"),
        ((np.array([3]), 0, 1.0, 1), TypeError, r"obs must be an integer .* of shape \(1,\)"),
        ((0, 0, 1.0, np.zeros((2, 2), np.int64)), TypeError, r"next_obs must be an integer .* "
         r"of shape \(2, 2\)"),
        ((0, np.array(1.5), 1.0, 1), TypeError, r"action must be an integer .* dtype float64"),
        ((0, np.array(True), 1.0, 1), TypeError, r"action must be an integer .* dtype bool"),
        ((0, 0, 1e300, 1), ValueError, r"reward must be within ±MAX_ABS_VALUE = 2\*\*200"),
    ],
)  # fmt: skip
def test_update_names_the_argument_and_what_is_allowed(args, error, match):
    agent = QLearning(GRID5)
    with pytest.raises(error, match=match):
        agent.update(*args)
    assert agent.num_timesteps == 0 and np.all(agent.q_table == 0.0)
    agent.update(np.int64(0), np.array(1), 1.0, np.array(5.0))  # 0-d integral arrays still do
    assert agent.num_timesteps == 1


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"q_init": 1e300}, r"q_init must be within ±MAX_ABS_VALUE = 2\*\*200 \(delayed_rl"),
        (
            {"seed": 2**64},
            r"seed must be at most MAX_SEED_VALUE = 2\*\*63 - 1 .*got 18446744073709551616",
        ),
        ({"greedy_window": 2**41}, r"greedy_window must be at most MAX_TIMESTEPS = 2\*\*40"),
    ],
)
def test_hyperparameters_above_their_stated_limits_are_refused(kwargs, match):
    with pytest.raises(ValueError, match=match):
        MultipleModelQLearning(GRID5, max_delay_estimate=2, **kwargs)


def test_learn_refuses_work_above_its_limits_before_starting():
    import tracemalloc

    from delayed_rl.agents.common.python_loop import MAX_RECORD_BYTES, MAX_TIMESTEPS

    agent = QLearning(GRID5, seed=0).learn(10)
    with pytest.raises(
        ValueError, match=r"total_timesteps must be at most MAX_TIMESTEPS = 2\*\*40"
    ):
        agent.learn(MAX_TIMESTEPS + 1)
    agent.num_timesteps = MAX_TIMESTEPS - 5
    with pytest.raises(ValueError, match="keep the agent's step count within MAX_TIMESTEPS"):
        agent.learn(10, reset_num_timesteps=False)
    tracemalloc.start()
    try:
        with pytest.raises(ValueError, match="record within MAX_RECORD_BYTES = 1 GiB"):
            agent.learn(MAX_RECORD_BYTES // 41 + 1, record=True)  # 41 bytes a step
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 4 * 2**20
    assert agent.num_timesteps == MAX_TIMESTEPS - 5  # nothing started


@pytest.mark.parametrize(
    ("path", "error", "match"),
    [
        ("", ValueError, r"path must name a model file .*got '', which has no file name"),
        (".", ValueError, r"path must name a model file .*got '\.', which has no file name"),
        ("runs/..", ValueError, r"got 'runs/\.\.', which has no file name"),
        (None, TypeError, r"path must be a str or os\.PathLike naming a model file, got None"),
        (3, TypeError, r"path must be a str or os\.PathLike .*got 3 \(int\)"),
    ],
)
def test_save_and_load_name_a_path_without_a_file_name(path, error, match):
    agent = QLearning(GRID5)
    with pytest.raises(error, match=match):
        agent.save(path)
    with pytest.raises(error, match=match):
        QLearning.load(path)
