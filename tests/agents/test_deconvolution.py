"""Deconvolution Q-learning: the regression's exactness, the delay it learns, and the agent."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import delayed_rl  # noqa: F401  (registers the ids)
from delayed_rl.agents import QLearning, load_agent
from delayed_rl.agents.deconvolution import DeconvolutionQLearning
from delayed_rl.agents.deconvolution.regression import RewardRegression, project_to_simplex
from delayed_rl.delays import Constant, Empirical, Geometric, Poisson
from delayed_rl.envs.gridworld import GridWorldEnv
from delayed_rl.experiments.framework.training import greedy_average_reward
from delayed_rl.wrappers import RewardDelay


def _random_walk(env, steps, seed, n_actions=4):
    """Feed a uniformly random policy's steps to a regression; return it and the true R."""
    base = env.unwrapped
    n_pairs = base.observation_space.n * n_actions
    rng = np.random.default_rng(seed)
    obs, _ = env.reset(seed=seed)
    true = np.zeros(n_pairs)
    steps_seen = []
    for _ in range(steps):
        action = int(rng.integers(n_actions))
        pair = obs * n_actions + action
        obs, reward, terminated, truncated, info = env.step(action)
        true[pair] = info["undelayed_reward"]  # for the check only: the regression never sees it
        steps_seen.append((pair, reward, terminated or truncated))
        if terminated or truncated:
            obs, _ = env.reset()
    return steps_seen, true


@pytest.mark.parametrize("mode", ["flush", "drop", "carry"])
@pytest.mark.parametrize(
    ("delay", "support"), [(Constant(2), 4), (Constant(0), 3), (Constant(5), 5)]
)
def test_constant_delays_are_undone_exactly_under_every_episode_end_mode(mode, delay, support):
    """With a constant delay and deterministic rewards there is no noise: R̂ must be R exactly.

    7-step episodes make every episode-end correction matter (rows after the end, flushed rows).
    """
    env = RewardDelay(GridWorldEnv(size=3, max_steps=7), delay, on_episode_end=mode)
    steps, true = _random_walk(env, 4000, seed=1)
    regression = RewardRegression(36, support, flush=mode == "flush", carry=mode == "carry")
    for pair, reward, ended in steps:
        regression.observe(pair, reward, ended)
    pmf = np.asarray(delay.pmf(np.arange(support + 1)), dtype=float)
    estimate = regression.solve_rewards(pmf, ridge=1e-9)
    # the pairs some real row speaks of (under "drop" a reward due after the episode's end never
    # comes: pairs late in the 7-step episodes then carry no information)
    informed = np.diagonal(regression.normal_equations(pmf)[0]) > 0.5
    assert informed.sum() >= (8 if (mode, delay.k) == ("drop", 5) else 30)
    np.testing.assert_allclose(estimate[informed], true[informed], atol=1e-6)


@pytest.mark.parametrize(
    "delay",
    [Poisson(3.0), Geometric(0.3), Empirical([0.3, 0, 0, 0, 0, 0, 0.7])],
    ids=["poisson", "geometric", "bimodal"],
)
def test_the_delay_is_learned_from_the_delivered_rewards_alone(delay):
    """A random walk on a continuing 5×5 grid, 60k steps: the learned pmf is close to the truth.

    Bounds: total variation below 0.15 and the mean within 0.5 steps (measured with this seed:
    about a third of both), from one fixed seed.
    """
    env = RewardDelay(GridWorldEnv(size=5), delay)
    steps, _ = _random_walk(env, 60_000, seed=2)
    support = 15
    regression = RewardRegression(100, support)
    for pair, reward, ended in steps:
        regression.observe(pair, reward, ended)
    pmf = np.full(support + 1, 1.0 / (support + 1))
    for _ in range(15):
        rewards = regression.solve_rewards(pmf, ridge=1e-3)
        pmf = regression.solve_delay(rewards, pmf)
    true = np.asarray(delay.pmf(np.arange(support + 1)), dtype=float)
    assert 0.5 * np.abs(pmf - true / true.sum()).sum() < 0.15
    assert abs(pmf @ np.arange(support + 1) - delay.mean) < 0.5


def test_project_to_simplex():
    p = project_to_simplex(np.array([0.5, 0.7, -0.2]))
    np.testing.assert_allclose(p, [0.4, 0.6, 0.0])
    assert project_to_simplex(np.array([0.2, 0.3, 0.5])) == pytest.approx([0.2, 0.3, 0.5])


def _grid(size=5, lam=3.0, **kwargs):
    return gym.make("delayed_rl/GridWorld-v0", size=size, reward_delay=lam, **kwargs)


@pytest.mark.parametrize("known", [True, False], ids=["known-delay", "learned-delay"])
def test_the_agent_finds_the_optimal_loop_where_q_learning_does_not(known):
    """5×5, Poisson(4), 60k steps, seeds 0–2: DeconvQ's greedy loop is optimal (10/9 per step)."""
    optimum = 10 / 9
    for seed in range(3):
        delay = Poisson(4.0) if known else None
        agent = DeconvolutionQLearning(
            _grid(lam=4.0), delay=delay, max_delay_estimate=20, q_init=25.0, seed=seed
        )
        agent.learn(60_000, log_interval=None)
        assert agent.last_learn_path == "compiled"
        assert greedy_average_reward(agent, 5) == pytest.approx(optimum, abs=0.002)
        if not known:  # the learned pmf is near Poisson(4). Measured over seeds 0-9 at 60k
            # steps: total variation 0.13-0.20; means 4.02-5.10, average 4.73, sd 0.34 (thin
            # spurious mass in the long tail biases the mean up: 4.64 at 200k). The mean's band
            # is that average ± 2.3 sd, about 1 in 50 per seed outside it by chance
            true = Poisson(4.0).pmf(np.arange(21))
            assert 0.5 * np.abs(agent.delay_pmf - true / true.sum()).sum() < 0.25
            assert 3.95 < agent.mean_delay < 5.5
    q_results = [
        greedy_average_reward(QLearning(_grid(lam=4.0), q_init=25.0, seed=seed).learn(60_000), 5)
        for seed in range(3)
    ]
    assert min(q_results) < optimum - 0.01  # the control: plain Q-learning misses on some seed


class _StripOracleKeys(gym.Wrapper):
    """Removes every key a reward-delay wrapper adds that would tell the agent the truth."""

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        for key in ("undelayed_reward", "drawn_reward_delay", "reward_arrivals", "pending_reward"):
            info.pop(key, None)
        return obs, reward, terminated, truncated, info


def test_it_is_anonymous_the_oracle_keys_change_nothing():
    tables = []
    for wrap in (lambda env: env, _StripOracleKeys):
        env = wrap(RewardDelay(GridWorldEnv(size=4), Poisson(3.0), record_arrivals=True))
        agent = DeconvolutionQLearning(
            env, max_delay_estimate=12, solve_interval=2_000, q_init=20.0, seed=4
        )
        agent.learn(10_000, compiled=False)  # the Python path: the one that sees info at all
        tables.append((agent.q_table.copy(), agent.delay_pmf))
    np.testing.assert_array_equal(tables[0][0], tables[1][0])
    np.testing.assert_array_equal(tables[0][1], tables[1][1])


def test_save_load_resumes_exactly(tmp_path):
    def fresh_env():
        return RewardDelay(GridWorldEnv(size=4, max_steps=40), Poisson(2.0), on_episode_end="drop")

    original = DeconvolutionQLearning(
        fresh_env(), max_delay_estimate=10, solve_interval=1_500, q_init=20.0, seed=6
    )
    original.learn(5_000)
    path = original.save(tmp_path / "deconv")
    loaded = load_agent(path, env=fresh_env())
    assert type(loaded) is DeconvolutionQLearning and loaded.assumed_episode_end == "drop"
    original.set_env(fresh_env())
    for agent in (original, loaded):
        agent.learn(4_000, reset_num_timesteps=False)
    np.testing.assert_array_equal(original.q_table, loaded.q_table)
    np.testing.assert_array_equal(original.delay_pmf, loaded.delay_pmf)
    np.testing.assert_array_equal(original.reward_model, loaded.reward_model)


def test_the_episode_end_mode_is_read_from_the_wrapper_and_conflicts_are_refused():
    agent = DeconvolutionQLearning(
        RewardDelay(GridWorldEnv(size=3, max_steps=9), 2.0, on_episode_end="carry")
    )
    assert agent.assumed_episode_end == "carry"
    agent.learn(200)
    with pytest.raises(
        ValueError, match="on_episode_end='carry' but this env's RewardDelay uses 'drop'"
    ):
        agent.set_env(RewardDelay(GridWorldEnv(size=3, max_steps=9), 2.0, on_episode_end="drop"))
    assert (
        DeconvolutionQLearning(GridWorldEnv(size=3), on_episode_end="drop").assumed_episode_end
        == "drop"
    )


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"delay": "poisson"}, TypeError, "delay must be None"),
        ({"delay": -1.0}, ValueError, "^delay must be a number in \\[0, "),
        (
            {"max_delay_estimate": -1},
            ValueError,
            "max_delay_estimate must be None or an integer >= 0",
        ),
        ({"max_delay_estimate": 2.5}, TypeError, "max_delay_estimate must be None or an integer"),
        ({"solve_interval": 0}, ValueError, "solve_interval must be an integer >= 1"),
        ({"ridge": 0.0}, ValueError, "ridge must be a number > 0"),
        ({"ridge": "small"}, TypeError, "ridge must be a number > 0"),
        ({"delay_iterations": 0}, ValueError, "delay_iterations must be an integer >= 1"),
        ({"on_episode_end": "keep"}, ValueError, "on_episode_end must be one of"),
        ({"on_episode_end": 1}, TypeError, "on_episode_end must be one of"),
        (
            {"max_delay_estimate": 1025},
            ValueError,
            "max_delay_estimate must be at most MAX_DELAY_ESTIMATE = 1024",
        ),
        (
            {"solve_interval": 2**40 + 1},
            ValueError,
            r"solve_interval must be at most MAX_SOLVE_INTERVAL = 2\*\*40",
        ),
        ({"ridge": 1e300}, ValueError, r"ridge must be at most MAX_ABS_VALUE = 2\*\*200"),
        (
            {"delay_iterations": 101},
            ValueError,
            "delay_iterations must be at most MAX_DELAY_ITERATIONS = 100",
        ),
        (
            {"delay": Poisson(2000.0)},
            ValueError,
            "delay must be modelled on at most MAX_DELAY_ESTIMATE = 1024 .* give a max_delay_estimate",
        ),
        ({"delay": [0.5, 0.6]}, ValueError, r"delay \(a saved pmf\): pmf must sum to 1"),
    ],
)
def test_bad_arguments(kwargs, error, match):
    with pytest.raises(error, match=match):
        DeconvolutionQLearning(GridWorldEnv(size=3), **kwargs)


def _fed(layout, steps, mode="flush", support=6, seed=3):
    """A regression of ``layout`` fed a random walk on 4×4 grids of 11-step episodes."""
    env = RewardDelay(GridWorldEnv(size=4, max_steps=11), Poisson(2.5), on_episode_end=mode)
    walk, _ = _random_walk(env, steps, seed=seed)
    regression = RewardRegression(64, support, mode == "flush", mode == "carry", layout=layout)
    for pair, reward, ended in walk:
        regression.observe(pair, reward, ended)
    return regression


@pytest.mark.parametrize("layout", ["direct", "hashed"])
@pytest.mark.parametrize("mode", ["flush", "drop", "carry"])
def test_the_statistics_are_the_counts_and_sums_of_their_definitions(mode, layout):
    """Counts per lag and reward sums by lag, recounted from the steps by their definitions.

    The steps' rewards include zeros of both signs (``+0.0`` and ``-0.0``) and negative
    values; a segment ends at each episode end (not under ``"carry"``), and under ``"flush"``
    the reward of a segment's last step is kept apart from the sums.
    """
    n_pairs, k_max = 6, 4
    rng = np.random.default_rng(11)
    steps = []
    for _ in range(400):
        reward = float(rng.choice([0.0, -0.0, 1.5, -2.0, 0.25]))
        steps.append((int(rng.integers(n_pairs)), reward, bool(rng.random() < 0.1)))
    regression = RewardRegression(n_pairs, k_max, mode == "flush", mode == "carry", layout=layout)
    regression.reserve(len(steps))
    for pair, reward, ended in steps:
        regression.observe(pair, reward, ended)
    counts = np.zeros((k_max + 1, n_pairs, n_pairs), dtype=np.int64)
    sums = np.zeros((k_max + 1, n_pairs))
    segment: list[int] = []  # the open segment's pairs
    for pair, reward, ended in steps:
        segment.append(pair)
        last_flushed = ended and mode == "flush"
        for lag in range(min(k_max + 1, len(segment))):
            earlier = segment[-1 - lag]
            counts[lag, earlier, pair] += 1
            if not last_flushed:
                sums[lag, earlier] += reward
        if ended and mode != "carry":
            segment = []
    for lag in range(k_max + 1):
        np.testing.assert_array_equal(regression.counts(lag), counts[lag])
    by_lag = regression.stats.by_lag
    np.testing.assert_array_equal(by_lag, sums)
    assert not np.signbit(by_lag[by_lag == 0.0]).any()  # no sum of rewards is a −0.0


@pytest.mark.parametrize("mode", ["flush", "drop", "carry"])
def test_the_hashed_layout_holds_the_same_counts_and_gives_the_same_solves(mode):
    """Both layouts, the same steps: equal counts per lag, normal equations, R̂ and pmf."""
    direct, hashed = _fed("direct", 3000, mode), _fed("hashed", 3000, mode)
    assert (direct.layout, hashed.layout) == ("direct", "hashed")
    for lag in range(direct.max_delay_estimate + 1):
        np.testing.assert_array_equal(direct.counts(lag), hashed.counts(lag))
    pmf = Poisson(2.5).pmf(np.arange(7))
    pmf = pmf / pmf.sum()
    for ours, theirs in zip(
        direct.normal_equations(pmf), hashed.normal_equations(pmf), strict=True
    ):
        np.testing.assert_allclose(ours, theirs, rtol=1e-12, atol=1e-9)
    rewards = direct.solve_rewards(pmf, 1e-3)
    np.testing.assert_allclose(hashed.solve_rewards(pmf, 1e-3), rewards, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(
        hashed.solve_delay(rewards, pmf), direct.solve_delay(rewards, pmf), atol=1e-12
    )


def test_conjugate_gradients_agree_with_the_dense_solve(monkeypatch):
    """Above DENSE_SOLVE_PAIRS pairs R̂ comes from CG: the same solution as the dense Cholesky solve, to 1e-7."""
    from delayed_rl.agents.deconvolution import regression as regression_module

    regression = _fed("hashed", 4000, "flush")
    pmf = Poisson(2.5).pmf(np.arange(7))
    dense = regression.solve_rewards(pmf, 1e-3)
    monkeypatch.setattr(regression_module, "DENSE_SOLVE_PAIRS", 10)
    regression._last_rewards = np.zeros(64)  # a cold start
    np.testing.assert_allclose(regression.solve_rewards(pmf, 1e-3), dense, atol=1e-7)


def test_the_layout_is_chosen_by_size_and_the_hashed_table_grows_with_what_is_seen():
    """Direct while the counts fit DIRECT_LIMIT; hashed above, sized by the couples that occur."""
    assert RewardRegression(100, 50).layout == "direct"
    big = GridWorldEnv(size=20)  # 1600 pairs: 1600² · 51 · 4 bytes = 498 MiB direct
    agent = DeconvolutionQLearning(big, max_delay_estimate=50, q_init=20.0, seed=0)
    assert agent._regression.layout == "hashed"
    agent.learn(3_000)
    regression = agent._regression
    used = int(regression.stats.counters[6])
    assert 0 < used <= 3_000 * 51  # at most K + 1 new couples a step
    assert regression.stats.keys.size <= 4 * (used + 256 * 51)  # half full after a chunk's room
    row_bytes = 51 * 4 + 8  # a row's 51 int32 counts and its int64 key
    assert regression.nbytes == regression.stats.keys.size * row_bytes  # rows for what was seen
    assert regression.nbytes < 1600**2 * 51 * 4 / 3  # well below the direct layout's 498 MiB
    with pytest.raises(ValueError, match="direct layout, more than the limit"):
        RewardRegression(1600, 50, layout="direct")


def test_a_hashed_table_that_would_outgrow_the_limit_is_refused(monkeypatch):
    from delayed_rl.agents.deconvolution import regression as regression_module

    monkeypatch.setattr(regression_module, "STATISTICS_LIMIT", 2**20)
    agent = DeconvolutionQLearning(
        GridWorldEnv(size=20), max_delay_estimate=50, q_init=20.0, seed=0
    )
    with pytest.raises(ValueError, match=r"max_delay_estimate=50: the co-occurrence rows .* MiB"):
        agent.learn(20_000)


def test_statistics_of_earlier_versions_load():
    """A saved ``cooc[m, i, j]`` with five counters restores to the same solves."""
    regression = _fed("direct", 2000, "drop")
    old = regression.state()
    old["cooc"] = np.stack([regression.counts(m) for m in range(7)]).astype(np.int32)
    old["counters"] = old["counters"][:5]
    del old["keys"]
    restored = RewardRegression(64, 6, flush=False)
    restored.restore(old)
    pmf = np.full(7, 1 / 7)
    np.testing.assert_array_equal(
        restored.normal_equations(pmf)[0], regression.normal_equations(pmf)[0]
    )


def test_the_compiled_and_python_paths_learn_the_same_from_the_same_steps():
    """Scripted steps through the compiled loop (``replay``) and through ``update()``.

    The same Q-table, statistics, reward model and learned pmf, to the last bit.
    """
    from delayed_rl.compiled.kernel import replay

    rng = np.random.default_rng(11)
    n = 7_000
    rows = np.column_stack(
        [rng.integers(16, size=n), rng.integers(4, size=n), rng.integers(16, size=n)]
    )
    ends = rng.random(n) < 0.02
    rewards = np.where(rng.random(n) < 0.1, rng.choice([-1.0, 10.0], size=n), 0.0)
    env = RewardDelay(GridWorldEnv(size=4), Poisson(2.0), on_episode_end="drop")
    python, compiled = (
        DeconvolutionQLearning(env, max_delay_estimate=8, solve_interval=2_500, q_init=5.0, seed=0)
        for _ in range(2)
    )
    for (s, a, s2), reward, end in zip(rows.tolist(), rewards.tolist(), ends.tolist(), strict=True):
        python.update(s, a, reward, s2, terminated=end)
    done = 0
    while done < n:
        tables = compiled.compiled_tables()
        stop = done + tables.chunk_limit
        replay(
            tables.q, tables.delay_estimates, rows[done:stop], ends[done:stop],
            rewards[done:stop], compiled.learning_rate, compiled.gamma, tables.reward_model,
        )  # fmt: skip
        tables.after_chunk(min(stop, n) - done)
        done = min(stop, n)
    np.testing.assert_array_equal(python.q_table, compiled.q_table)
    np.testing.assert_array_equal(python.reward_model, compiled.reward_model)
    np.testing.assert_array_equal(python.delay_pmf, compiled.delay_pmf)
    for ours, theirs in zip(python._regression.state().values(), compiled._regression.state().values(), strict=True):  # fmt: skip
        np.testing.assert_array_equal(ours, theirs)


@pytest.mark.parametrize(
    ("env_id", "layout"),
    [("Taxi-v4", "hashed"), ("CliffWalking-v1", "direct"), ("FrozenLake-v1", "direct")],
)
def test_the_python_path_runs_gymnasiums_tabular_envs_with_the_defaults(env_id, layout):
    """Taxi's 3000 pairs would need 1.7 GiB of direct counts at K = 50: hashed rows instead.

    After a solve, the reward model of the most visited pair is close to its true mean reward.
    """
    from delayed_rl.wrappers import PoissonRewardDelay

    env = PoissonRewardDelay(gym.make(env_id), 3.0)
    agent = DeconvolutionQLearning(env, seed=0).learn(6_000, compiled=False, record=True)
    assert agent.last_learn_path == "python" and agent._regression.layout == layout
    assert agent._regression.nbytes < 64 * 2**20
    agent.solve()  # the last solve may be thousands of steps old: the check is of the estimator
    log = agent.training_log
    pairs = log["obs"] * agent.n_actions + log["action"]
    top = int(np.bincount(pairs).argmax())
    table = gym.make(env_id).unwrapped.P
    s, a = divmod(top, agent.n_actions)
    true = sum(p * r for p, _, r, _ in table[s][a])
    # a pair seen n times carries about n·Σ_k p(k)² of the normal equations' weight, so its
    # estimate's standard error is about σ / √(n·Σ p²), σ at most the delivered rewards' spread
    pmf = agent.delay_pmf
    error = log["reward"].std() / np.sqrt(np.bincount(pairs)[top] * (pmf @ pmf))
    assert abs(agent.reward_model.ravel()[top] - true) < 4 * error


def test_a_solve_whose_mean_rewards_pass_max_abs_value_is_refused(monkeypatch):
    agent = DeconvolutionQLearning(GridWorldEnv(size=3), max_delay_estimate=4, seed=0)
    agent.update(0, 0, 1.0, 1)
    monkeypatch.setattr(RewardRegression, "solve_rewards", lambda *args: np.full(36, np.inf))
    with pytest.raises(ValueError, match=r"mean reward of inf, beyond MAX_ABS_VALUE = 2\*\*200"):
        agent.solve()
    assert np.all(agent.reward_model == 0.0)  # the Q-learning step never sees it


def test_a_shorter_solve_interval_given_to_load_shortens_the_pending_gap(tmp_path):
    """Saved 500 steps into a 1000-step gap; loaded with ``solve_interval=200``: it solves next."""
    agent = DeconvolutionQLearning(
        GridWorldEnv(size=3), max_delay_estimate=4, q_init=5.0, seed=0
    ).learn(1_500)
    path = agent.save(tmp_path / "deconv")
    kept = load_agent(path, GridWorldEnv(size=3))
    shortened = load_agent(path, GridWorldEnv(size=3), custom_objects={"solve_interval": 200})
    for loaded in (kept, shortened):
        np.testing.assert_array_equal(loaded.reward_model, agent.reward_model)
        loaded.update(0, 0, 1.0, 1)
    np.testing.assert_array_equal(kept.reward_model, agent.reward_model)
    assert not np.array_equal(shortened.reward_model, agent.reward_model)
