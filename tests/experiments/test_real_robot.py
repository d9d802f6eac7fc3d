"""The stand-in real robot (``EPuckLineFollowReal-v0``) and the ``real-robot`` experiment."""

from __future__ import annotations

import json
import math

import gymnasium as gym
import numpy as np
import pytest

import delayed_rl  # noqa: F401  (registers the ids)
from delayed_rl.envs.linefollow.env import (
    CONTROL_PERIOD,
    MAX_WHEEL_SPEED,
    PHYSICS_SUBSTEPS,
    REAL_ROBOT,
    EPuckLineFollowEnv,
)
from delayed_rl.envs.linefollow.robot import METRES_PER_STEP
from delayed_rl.envs.registration import DelayableEntryPoint
from delayed_rl.experiments import Config, get_experiment, run_experiment
from delayed_rl.experiments.thesis.real_robot import RealRobotTask
from delayed_rl.wrappers import PoissonRewardDelay

REAL_ID = "delayed_rl/EPuckLineFollowReal-v0"
STRAIGHT = 3  # Table 5.2: both wheels at 300


def drive(env: EPuckLineFollowEnv, actions, seed: int = 0, **reset_options):
    """Poses after each action from a seeded reset."""
    env.reset(seed=seed, options=reset_options or None)
    poses = []
    for action in actions:
        env.step(action)
        poses.append(env.robot.pose)
    return poses


def distance(a, b) -> float:
    return math.hypot(a[0] - b[0], a[1] - b[1])


# ---------------------------------------------------------------- the registered configuration
def test_the_real_id_builds_the_documented_configuration():
    env = gym.make(REAL_ID)
    base = env.unwrapped
    assert isinstance(base, EPuckLineFollowEnv)
    for name, value in REAL_ROBOT.items():
        assert getattr(base, name) == value
    assert base.track.name == "racetrack"  # the default track: the shape of the print
    assert base.physics_substeps == 13 and base.latency_substeps == 7
    assert base.robot.physics_dt == pytest.approx(0.2 / 13)
    # the caller's arguments override the preset, and the spec rebuilds the same stack
    delayed = gym.make(REAL_ID, reward_delay=90, wheel_slip=0.2, max_steps=None)
    layer = delayed
    while not isinstance(layer, PoissonRewardDelay):
        layer = layer.env
    assert layer.lam == 90 and delayed.unwrapped.wheel_slip == 0.2
    again = gym.make(delayed.spec)
    assert again.unwrapped.wheel_slip == 0.2 and again.unwrapped.control_period == 0.2


def test_the_clean_defaults_are_unchanged():
    env = EPuckLineFollowEnv()
    assert (env.control_period, env.command_latency, env.line_contrast) == (CONTROL_PERIOD, 0, 1)
    assert env.physics_substeps == PHYSICS_SUBSTEPS and env.latency_substeps == 0
    assert env.robot.physics_dt == CONTROL_PERIOD / PHYSICS_SUBSTEPS


def test_preset_entry_points_check_their_preset():
    with pytest.raises(TypeError, match=r"preset must be a 'module:Name' string, got 3 \(int\)"):
        DelayableEntryPoint("delayed_rl.envs.linefollow.env:EPuckLineFollowEnv", preset=3)
    with pytest.raises(ValueError, match=r"preset must be a 'module:Name' string, got 'x'"):
        DelayableEntryPoint("delayed_rl.envs.linefollow.env:EPuckLineFollowEnv", preset="x")
    assert "preset=" in repr(delayed_rl.envs.registration.EPuckLineFollowReal)


# ---------------------------------------------------------------- each documented difference
def test_a_longer_control_period_moves_the_robot_further_per_step():
    short, long_ = EPuckLineFollowEnv(max_steps=None), EPuckLineFollowEnv(control_period=0.2)
    start = {"start_progress": 0.0}
    (p_short,) = drive(short, [STRAIGHT], **start)
    (p_long,) = drive(long_, [STRAIGHT], **start)
    origin = short.track.point_at(0.0)
    speed = MAX_WHEEL_SPEED * METRES_PER_STEP
    # one physics sub-step of actuation latency either way (see the env's docstring)
    assert distance(origin, p_short) == pytest.approx(speed * (0.064 - 0.016), rel=1e-6)
    assert distance(origin, p_long) == pytest.approx(speed * (0.2 - 0.2 / 13), rel=1e-6)


def test_with_slip_the_robot_travels_less_for_the_same_commands():
    actions = [STRAIGHT] * 30
    slip = EPuckLineFollowEnv(max_steps=None, wheel_slip=REAL_ROBOT["wheel_slip"])
    grip = EPuckLineFollowEnv(max_steps=None)
    slip.reset(seed=0, options={"start_progress": 0.1})
    grip.reset(seed=0, options={"start_progress": 0.1})
    for action in actions:
        *_, info_slip = slip.step(action)
        *_, info_grip = grip.step(action)
    assert info_slip["wheel_speeds"] == info_grip["wheel_speeds"]  # the same commands
    ratio = info_slip["lap_progress"] / info_grip["lap_progress"]
    assert 0.9 < ratio < 0.99  # mean factor 1 − slip / 2 = 0.95


def test_a_one_step_latency_delays_every_action_by_one_step():
    late = EPuckLineFollowEnv(max_steps=None, command_latency=CONTROL_PERIOD)
    now = EPuckLineFollowEnv(max_steps=None)
    assert late.latency_substeps == PHYSICS_SUBSTEPS
    actions = [0, 6, 3, 1, 5]
    start = {"start_progress": 0.3}
    late_poses = drive(late, actions + [STRAIGHT], **start)
    now_poses = drive(now, actions, **start)
    assert late_poses[0] == pytest.approx(late.track.point_at(0.3 * late.track.length))  # stopped
    assert np.array(late_poses[1:]) == pytest.approx(
        np.array(now_poses)
    )  # each action acts one step later


def test_a_fractional_latency_splits_a_step_between_two_commands():
    env = EPuckLineFollowEnv(control_period=0.2, command_latency=0.1)
    assert env.latency_substeps == 7  # 0.1 s rounded up to sub-steps of 0.2 / 13 s
    env.reset(seed=0, options={"start_progress": 0.0})
    origin = env.robot.pose
    env.step(STRAIGHT)  # 7 sub-steps stopped, 6 at full speed (the first of them still at rest)
    speed = MAX_WHEEL_SPEED * METRES_PER_STEP
    assert distance(origin, env.robot.pose) == pytest.approx(speed * 5 * 0.2 / 13, rel=1e-6)
    *_, info = env.step(STRAIGHT)
    assert info["wheel_speeds"] == (300.0, 300.0)  # info reports the commanded speeds


def test_a_recovery_stops_the_commands_in_flight():
    env = EPuckLineFollowEnv(
        command_latency=CONTROL_PERIOD, lost_line="recover", lost_line_steps=1, max_steps=None
    )
    env.reset(seed=0, options={"pose": (0.0, 0.0, 0.0)})  # off the track: lost at once
    *_, info = env.step(STRAIGHT)
    assert info["recovered"]
    pose = env.robot.pose
    env.step(STRAIGHT)  # the STRAIGHT in flight was dropped: the first sub-steps are stopped
    fresh = EPuckLineFollowEnv(command_latency=CONTROL_PERIOD, max_steps=None)
    fresh.reset(seed=0, options={"pose": pose})
    fresh.step(STRAIGHT)
    assert env.robot.pose == pytest.approx(fresh.robot.pose)


def test_line_contrast_loses_line_pixels_at_the_given_rate():
    def seen(contrast: float) -> float:
        env = EPuckLineFollowEnv(
            observation_mode="pixels", action_mode="continuous", line_contrast=contrast
        )
        obs, _ = env.reset(seed=0, options={"start_progress": 0.0})
        counts = [obs.sum()]
        for _ in range(400):
            obs, *_ = env.step(np.zeros(2, np.float32))  # stand still on the line
            counts.append(obs.sum())
        return float(np.mean(counts))

    full = seen(1.0)
    assert full == 6.0  # pixels 18–23, every reading
    assert seen(0.5) == pytest.approx(0.5 * full, abs=0.25)


def test_seeded_real_runs_reproduce_and_seeds_differ():
    def run(seed: int) -> list:
        env = gym.make(REAL_ID, reward_delay=90, lost_line="recover", max_steps=None)
        env.action_space.seed(seed)
        obs, _ = env.reset(seed=seed)
        out = [int(obs)]
        for _ in range(200):
            obs, reward, *_, info = env.step(env.action_space.sample())
            out.append((int(obs), reward, info["undelayed_reward"], info["pose"]))
        return out

    assert run(3) == run(3)
    assert run(3) != run(4)


def test_a_copy_mid_run_continues_identically():
    import copy
    import pickle

    env = EPuckLineFollowEnv(max_steps=None, **REAL_ROBOT)
    env.reset(seed=5)
    for action in (0, 3, 6, 2):
        env.step(action)
    copies = [copy.deepcopy(env), pickle.loads(pickle.dumps(env))]
    runs = []
    for e in (env, *copies):
        runs.append([e.step(a)[:2] + (e.robot.pose,) for a in (1, 4, 3, 3, 5)])
    assert runs[0] == runs[1] == runs[2]


@pytest.mark.parametrize(
    ("kwargs", "error", "message"),
    [
        (
            {"line_contrast": 0.0},
            ValueError,
            r"line_contrast must be a number in \(0, 1\], got 0.0",
        ),
        (
            {"line_contrast": 1.5},
            ValueError,
            r"line_contrast must be a number in \(0, 1\], got 1.5",
        ),
        ({"line_contrast": "0.9"}, TypeError, r"line_contrast must be .*got '0.9' \(str\)"),
        ({"control_period": 0}, ValueError, r"control_period must be a number > 0 \(s\), got 0"),
        ({"control_period": math.inf}, ValueError, r"control_period must be .*got inf"),
        ({"control_period": True}, TypeError, r"control_period must be .*got True \(bool\)"),
        ({"command_latency": -0.1}, ValueError, r"command_latency must be a number >= 0 \(s\)"),
        ({"command_latency": math.nan}, ValueError, r"command_latency must be .*got nan"),
        ({"command_latency": None}, TypeError, r"command_latency must be .*got None"),
    ],
)
def test_bad_real_robot_arguments(kwargs, error, message):
    with pytest.raises(error, match=message):
        EPuckLineFollowEnv(**kwargs)
    with pytest.raises(error, match=message):
        gym.make(REAL_ID, **kwargs)


# ---------------------------------------------------------------- the experiment
def test_tasks_follow_the_thesis_protocol():
    experiment = get_experiment("real-robot")
    tasks = experiment.tasks(Config(seeds=experiment.default_seeds))
    assert experiment.default_seeds == 4 and len(tasks) == 12
    assert {(t.pretrain_steps, t.steps) for t in tasks} == {(500_000, 1_500)}
    assert {t.agent for t in tasks} == {"MMQ", "Q", "DeconvQ learned"}
    quick = experiment.tasks(Config(quick=True, seeds=2))
    assert {(t.pretrain_steps, t.steps) for t in quick} == {(5_000, 300)}


def test_a_task_continues_one_pretrained_agent_on_both_conditions():
    from delayed_rl.experiments.thesis.real_robot import run_task

    result = run_task(RealRobotTask(agent="MMQ", seed=0, pretrain_steps=300, steps=200))
    for condition in ("real", "control"):
        r = result[condition]
        assert r["steps"][-1] == 200 and r["error"][-1] == r["total_error"]
        assert r["curve"][-1] == pytest.approx(r["average"])
        assert np.all(np.diff(r["error"]) <= 20 * np.diff(r["steps"]))
    assert result["real"]["average"] != result["control"]["average"]
    assert result["pretrain_seconds"] > 0


@pytest.mark.experiment
def test_quick_run_writes_claims_and_figures(tmp_path):
    experiment = get_experiment("real-robot")
    summary = run_experiment(experiment, Config(quick=True, steps=2_000), tmp_path, False)
    quantities = [claim.quantity for claim in summary.claims]
    assert len(quantities) == 10 and any("gap cost" in q for q in quantities)
    for claim in summary.claims:
        assert claim.verdict in {"agrees", "differs", "inconclusive", "reference"}
        assert claim.criterion and np.isfinite(claim.mean)
    payload = json.loads((tmp_path / "summary.json").read_text())
    assert payload["protocol"]["real_config"] == dict(REAL_ROBOT)
    assert set(payload["thesis_runs"]) == {"run 1", "run 2"}
    assert sorted(p.name for p in tmp_path.glob("*.png")) == [
        "fig5_24_26_average_reward.png",
        "fig5_25_27_accumulated_error.png",
    ]


def _fake(mmq: float, q: float, error_ratio: float, control: float, seeds: int = 6):
    """Claims of synthetic runs: real averages ``mmq``, ``q``; control = real + ``control``."""
    from delayed_rl.experiments.thesis.real_robot import summarize

    tasks, results = [], []
    values = {"MMQ": mmq, "Q": q, "DeconvQ learned": q + 0.1}
    errors = {"MMQ": 1000.0, "Q": 1000.0 * error_ratio, "DeconvQ learned": 1200.0}
    for seed in range(seeds):
        jitter = 0.01 * (seed - seeds / 2)
        for agent in values:
            tasks.append(RealRobotTask(agent=agent, seed=seed, pretrain_steps=10, steps=10))
            out = {"pretrain_seconds": 1.0}
            for condition, shift in (("real", 0.0), ("control", control)):
                average = values[agent] + shift + jitter
                out[condition] = {
                    "steps": np.array([5, 10]),
                    "curve": np.full(2, average),
                    "error": np.array([errors[agent] / 2, errors[agent]]) * (1 + jitter),
                    "average": average,
                    "total_error": errors[agent] * (1 + jitter),
                    "visible": 0.9,
                }
            results.append(out)
    summary = summarize(tasks, results, Config(seeds=seeds))
    return {claim.quantity.split(" (")[0]: claim.verdict for claim in summary.claims}


def test_synthetic_results_flip_the_verdicts():
    like = _fake(mmq=0.2, q=-0.25, error_ratio=1.6, control=0.4)
    assert like["MMQ average reward on the real robot"] == "agrees"
    assert like["Q average reward on the real robot"] == "agrees"
    assert like["MMQ minus Q average reward on the real robot"] == "agrees"
    assert like["Q accumulated error / MMQ accumulated error on the real robot"] == "agrees"
    assert like["MMQ gap cost: control minus real average reward"] == "agrees"
    assert like["MMQ average reward, control"] == "agrees"  # 0.2 + 0.4 = Fig. 5.19's 0.6
    unlike = _fake(mmq=-0.3, q=0.3, error_ratio=0.8, control=-0.2)
    assert unlike["MMQ average reward on the real robot"] == "differs"
    assert unlike["Q average reward on the real robot"] == "differs"
    assert unlike["MMQ minus Q average reward on the real robot"] == "differs"
    assert unlike["Q accumulated error / MMQ accumulated error on the real robot"] == "differs"
    assert unlike["MMQ gap cost: control minus real average reward"] == "differs"
    assert unlike["DeconvQ learned average reward on the real robot"] == "reference"
