"""The e-puck line follower on the compiled path (delayed_rl.compiled.robot).

The compiled step must be the env's step to the last bit: a compiled run's logged actions,
replayed on a fresh env seeded alike, give the same observations, rewards and episode ends, and
leave the env in the same state, whatever the noise, lag, slip and episode-end settings.
"""

from __future__ import annotations

import copy
import math
import pickle
import warnings

import numpy as np
import pytest

from delayed_rl import agents
from delayed_rl.compiled import CompiledRun, NotCompilable
from delayed_rl.delays import Poisson
from delayed_rl.envs.linefollow.env import EPuckLineFollowEnv
from delayed_rl.wrappers import RewardDelay

#: Configurations that reach every branch of the step: lost-line recovery and termination,
#: truncation, motor lag, wheel slip, camera noise, line contrast and other control periods.
CONFIGS = {
    "clean, recover": dict(lost_line="recover", max_steps=None, lost_line_steps=8),
    "noisy, recover": dict(
        lost_line="recover",
        max_steps=None,
        lost_line_steps=6,
        motor_lag=0.05,
        wheel_slip=0.1,
        camera_noise=0.02,
        line_contrast=0.9,
        control_period=0.2,
    ),
    "terminate, truncate": dict(
        lost_line="terminate", lost_line_steps=4, max_steps=150, camera_noise=0.01, track="oval"
    ),
    "seeded random track": dict(track="random", track_seed=3, wheel_slip=0.05, max_steps=120),
}
STEPS = 3000


def random_walker(kwargs: dict, seed: int, agent=agents.QLearning, **options) -> tuple:
    """An agent acting uniformly at random (ε = 1) on an e-puck env under Poisson(5) delays."""
    env = RewardDelay(EPuckLineFollowEnv(**kwargs), Poisson(5.0))
    walker = agent(
        env,
        seed=seed,
        exploration_initial_eps=1.0,
        exploration_final_eps=1.0,
        **options,
    )
    return walker, env.unwrapped


def replay(kwargs: dict, seed: int, actions: np.ndarray) -> dict:
    """Step a fresh env through ``actions`` as the Python loop would: reset, step, reset at ends."""
    env = EPuckLineFollowEnv(**kwargs)
    obs, _ = env.reset(seed=seed)
    out = {"obs": [], "reward": [], "end": [], "terminated": [], "recovered": 0}
    for action in actions.tolist():
        out["obs"].append(int(obs))
        obs, reward, terminated, truncated, info = env.step(action)
        out["reward"].append(reward)
        out["end"].append(terminated or truncated)
        out["terminated"].append(terminated)
        out["recovered"] += info["recovered"]
        if terminated or truncated:
            obs, _ = env.reset()
    return {**{k: np.array(v) for k, v in out.items()}, "env": env, "next_obs": int(obs)}


def env_state(env: EPuckLineFollowEnv) -> tuple:
    """Everything a step reads or reports, as exact values."""
    return (
        env.robot.pose,
        tuple(env.robot.body.velocity),
        env.robot.body.angular_velocity,
        env.robot.wheel_speeds,
        env._s,
        env._lateral,
        env._segment,
        env._progress,
        env._lost,
        env._steps,
        env._pixels.tobytes(),
        env.np_random.bit_generator.state["state"]["state"],
    )


@pytest.mark.parametrize("name", CONFIGS)
def test_compiled_steps_are_the_envs_steps(name):
    kwargs = CONFIGS[name]
    walker, env = random_walker(kwargs, seed=11)
    walker.learn(STEPS, log_interval=None, record=True, compiled=True)
    log = walker.training_log
    python = replay(kwargs, 11, log["action"])
    np.testing.assert_array_equal(log["obs"], python["obs"])
    assert log["undelayed_reward"].tobytes() == python["reward"].astype(np.float64).tobytes()
    np.testing.assert_array_equal(log["episode_end"], python["end"])
    assert walker._compiled[1].state[0] == python["next_obs"]
    assert env_state(env) == env_state(python["env"])
    if kwargs.get("lost_line") == "recover":
        assert python["recovered"] > 0  # the recoveries were exercised
    if kwargs.get("max_steps"):
        assert python["end"].sum() > 0  # so were the resets
    if kwargs.get("lost_line") == "terminate":
        assert python["terminated"].sum() > 0


def test_chunks_continue_exactly():
    """Many short learn() calls make the same run as one long one (the env state is carried)."""
    kwargs = CONFIGS["noisy, recover"]
    whole, whole_env = random_walker(kwargs, seed=4)
    whole.learn(2000, log_interval=None, record=True, compiled=True)
    pieces, pieces_env = random_walker(kwargs, seed=4)
    actions = []
    for i in range(8):
        pieces.learn(250, log_interval=None, record=True, compiled=True, reset_num_timesteps=i == 0)
        actions.append(pieces.training_log["action"])
    np.testing.assert_array_equal(np.concatenate(actions), whole.training_log["action"])
    assert env_state(whole_env) == env_state(pieces_env)
    np.testing.assert_array_equal(whole.q_table, pieces.q_table)


def test_copies_continue_alike_and_apart():
    """A deep copy or a pickle of a trained agent continues as the original does, on its own env.

    Copying rebuilds the original's pymunk space, so the original must find its new handles.
    """
    walker, env = random_walker(CONFIGS["clean, recover"], seed=2)
    walker.learn(1500, log_interval=None, compiled=True)
    copied = copy.deepcopy(walker)
    pickled = pickle.loads(pickle.dumps(walker))
    ends = []
    for agent in (walker, copied, pickled):
        agent.learn(1500, log_interval=None, record=True, compiled=True, reset_num_timesteps=False)
        ends.append((agent.training_log["action"].tobytes(), env_state(agent.env.unwrapped)))
    assert ends[0] == ends[1] == ends[2]
    assert copied.env.unwrapped is not env and pickled.env.unwrapped is not env


@pytest.mark.parametrize(
    "make",
    [
        lambda env: agents.QLearning(env, seed=0),
        lambda env: agents.MultipleModelQLearning(env, max_delay_estimate=12, seed=0),
        lambda env: agents.DeconvolutionQLearning(env, max_delay_estimate=12, seed=0),
        lambda env: agents.ExpectedCreditQLearning(
            env, delay=Poisson(5.0), max_delay_estimate=12, seed=0
        ),
    ],
    ids=["Q", "MMQ", "DeconvQ", "expected credit"],
)
def test_every_agent_learns_compiled(make):
    env = RewardDelay(EPuckLineFollowEnv(lost_line="recover", max_steps=None), Poisson(5.0))
    agent = make(env)
    before = agent.q_table.copy()
    agent.learn(4000, log_interval=None, compiled=True)
    assert agent._compiled is not None and agent._compiled[1].robot is not None
    assert np.isfinite(agent.q_table).all() and not np.array_equal(agent.q_table, before)
    assert env.unwrapped._steps == 4000  # the env object was stepped, to the last step


def test_oracle_learns_compiled():
    env = RewardDelay(
        EPuckLineFollowEnv(lost_line="recover", max_steps=None), Poisson(5.0), record_arrivals=True
    )
    agent = agents.OracleQLearning(env, seed=0)
    agent.learn(3000, log_interval=None, compiled=True)
    assert agent._compiled[1].robot is not None and np.isfinite(agent.q_table).all()


def test_seeded_agents_repeat_and_differ():
    runs = []
    for seed in (5, 5, 6):
        walker, env = random_walker(CONFIGS["noisy, recover"], seed=seed)
        walker.learn(800, log_interval=None, record=True, compiled=True)
        runs.append(walker.training_log["action"].tobytes() + repr(env_state(env)).encode())
    assert runs[0] == runs[1] != runs[2]


def test_learned_policy_is_the_python_paths_kind():
    """Both paths learn the task: MMQ on the clean env earns well above a random walk's reward."""
    rewards = {}
    for compiled in (True, False):
        env = RewardDelay(EPuckLineFollowEnv(lost_line="recover", max_steps=None), Poisson(3.0))
        agent = agents.MultipleModelQLearning(env, max_delay_estimate=10, seed=1, q_init=10.0)
        agent.learn(30_000, log_interval=None, record=True, compiled=compiled)
        rewards[compiled] = agent.training_log["undelayed_reward"][-10_000:].mean()
    random_walk = CONFIGS["clean, recover"] | {"lost_line_steps": 50}
    walker, _ = random_walker(random_walk, seed=1)
    walker.learn(10_000, log_interval=None, record=True, compiled=True)
    baseline = walker.training_log["undelayed_reward"].mean()
    assert min(rewards.values()) > baseline + 0.2, (rewards, baseline)


@pytest.mark.parametrize(
    ("kwargs", "named"),
    [
        (dict(observation_mode="pixels"), "observation_mode='pixels'"),
        (dict(command_latency=0.1), "command_latency=0.1"),
        (dict(track="random"), "track="),
        (dict(render_mode="rgb_array"), "render_mode='rgb_array'"),
    ],
)
def test_what_does_not_compile_says_why(kwargs, named):
    env = RewardDelay(EPuckLineFollowEnv(**kwargs), Poisson(2.0))
    with pytest.raises(NotCompilable, match=named.replace("(", r"\(")):
        CompiledRun(env, np.zeros(1, np.int64), 0)


def test_continuous_actions_do_not_compile():
    env = RewardDelay(EPuckLineFollowEnv(action_mode="continuous"), Poisson(2.0))
    with pytest.raises(NotCompilable, match="action_mode='continuous'"):
        CompiledRun(env, np.zeros(1, np.int64), 0)


@pytest.mark.parametrize("missing", ["physics", "camera"])
def test_an_env_without_its_compiled_physics_or_camera_does_not_compile(missing, monkeypatch):
    from delayed_rl.envs.linefollow import _chipmunk

    base = EPuckLineFollowEnv()
    base.reset(seed=0)
    if missing == "physics":  # as where numba cannot call Chipmunk: the Python sub-steps
        base.robot._driver = (_chipmunk.drive_python, base.robot._calls)
    else:  # as where the kernels do not mirror numpy's rounding: the numpy camera
        monkeypatch.setattr(base, "_compiled_arguments", lambda track: None)
        base._compiled_track = None
    with pytest.raises(NotCompilable, match="compiled physics or camera"):
        CompiledRun(RewardDelay(base, Poisson(2.0)), np.zeros(1, np.int64), 0)


def test_automatic_choice_falls_back_to_python():
    """``compiled=None`` runs a latency env on the Python path, ``compiled=True`` says why it cannot."""
    env = RewardDelay(
        EPuckLineFollowEnv(command_latency=0.05, lost_line="recover", max_steps=None), Poisson(2.0)
    )
    agent = agents.QLearning(env, seed=0)
    agent.learn(300, log_interval=None)
    assert agent._compiled is None and env.unwrapped._steps == 300
    with pytest.raises(NotCompilable, match="command_latency"):
        agent.learn(10, log_interval=None, compiled=True, reset_num_timesteps=False)


def test_progress_is_the_envs_arithmetic():
    """Lap progress after a long compiled run equals the Python env's, to the bit, and is a lap count."""
    kwargs = CONFIGS["clean, recover"] | {"lost_line_steps": 50}
    walker, env = random_walker(kwargs, seed=9)
    walker.learn(2500, log_interval=None, record=True, compiled=True)
    python = replay(kwargs, 9, walker.training_log["action"])
    assert env._progress == python["env"]._progress and math.isfinite(env._progress)


def test_a_new_env_or_a_reset_starts_a_new_compiled_run():
    """After ``set_env`` (even of the same env) the run starts on the reset env, not the old run."""
    kwargs = CONFIGS["clean, recover"]
    walker, env = random_walker(kwargs, seed=3)
    walker.learn(700, log_interval=None, compiled=True)
    walker.set_env(walker.env)
    walker.learn(400, log_interval=None, record=True, compiled=True, reset_num_timesteps=False)
    python = replay(kwargs, 3, walker.training_log["action"])  # a fresh env, reset with seed 3
    np.testing.assert_array_equal(walker.training_log["obs"], python["obs"])
    assert env_state(env) == env_state(python["env"])


def test_an_interrupted_compiled_run_is_dropped_and_the_env_reset():
    from delayed_rl.agents.common.callbacks import BaseCallback

    class Interrupt(BaseCallback):
        def _on_step(self) -> bool:
            if self.num_timesteps >= 300:
                raise KeyboardInterrupt
            return True

    walker, env = random_walker(CONFIGS["clean, recover"], seed=1)
    with pytest.raises(KeyboardInterrupt):
        walker.learn(1000, log_interval=None, compiled=True, callback=Interrupt())
    assert walker._compiled is None
    walker.learn(50, log_interval=None, compiled=False, reset_num_timesteps=False)
    assert env._steps == 50  # a fresh episode: the interrupted run's is not continued


def test_python_then_compiled_starts_a_fresh_episode():
    walker, env = random_walker(CONFIGS["clean, recover"], seed=1)
    walker.learn(200, log_interval=None, compiled=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the delay wrapper may say what its reset discards
        walker.learn(100, log_interval=None, compiled=True, reset_num_timesteps=False)
    assert env._steps == 100
