"""Both training paths of every agent against the plain rules of ``delayed_rl.agents.reference``.

Bit for bit: the same tables, to the last bit, on random transitions (hypothesis).

- The Python path: the agent's ``update()``, one transition at a time.
- The compiled path: ``learn(compiled=True, record=True)`` on Gymnasium's slippery FrozenLake
  without a time limit (whose episodes end only by termination, so the record gives every
  transition), the run's record replayed into the reference; and ``kernel.replay`` on scripted
  transitions. The oracle's compiled path keeps its own record of who emitted each
  reward, which the training record does not hold: it is tested equal to its Python path in
  ``test_compiled_credit.py``, which is tested here against the reference.
"""

from __future__ import annotations

import numpy as np
import pytest
from gymnasium.envs.toy_text import FrozenLakeEnv
from hypothesis import given, settings
from hypothesis import strategies as st
from support import examples

import delayed_rl  # noqa: F401  (registers the env ids)
from delayed_rl.agents import (
    DeconvolutionQLearning,
    ExpectedCreditQLearning,
    FixedDelayQLearning,
    MultipleModelQLearning,
    OracleQLearning,
    QLearning,
)
from delayed_rl.agents.reference import ReferenceExpectedCredit, ReferenceMMQ, ReferenceOracle
from delayed_rl.compiled.kernel import replay
from delayed_rl.delays import Constant, Geometric, Poisson
from delayed_rl.envs.gridworld import GridWorldEnv
from delayed_rl.wrappers import RewardDelay

N_STATES, N_ACTIONS = 9, 4
ALPHA, GAMMA = 0.3, 0.9

transitions = st.lists(
    st.tuples(
        st.integers(0, N_STATES - 1),  # s
        st.integers(0, N_ACTIONS - 1),  # a
        st.sampled_from([0.0, 1.0, -1.0, 10.0, 0.25, 3.7]),  # r
        st.integers(0, N_STATES - 1),  # s′
        st.integers(0, 11),  # 0: terminated, 1: truncated, else neither
    ),
    min_size=1,
    max_size=60,
)
delay_sets = st.lists(st.integers(0, 6), min_size=1, max_size=5, unique=True).map(sorted)
options = st.sampled_from([{}, {"reward_kernel": 1.5}, {"delay_trace": 0.7},
                           {"reward_kernel": 0.8, "delay_trace": 0.5}])  # fmt: skip
delays = st.one_of(
    st.floats(0.0, 6.0).map(Poisson),
    st.integers(0, 4).map(Constant),
    st.floats(0.2, 0.9).map(Geometric),
)


def _ends(code: int) -> tuple[bool, bool]:
    return code == 0, code == 1


def _feed(agent, reference, steps) -> None:
    for s, a, r, s2, code in steps:
        agent.update(s, a, r, s2, *_ends(code))
        reference.update(s, a, r, s2, *_ends(code))
        np.testing.assert_array_equal(agent.q_table, reference.q)


# ---------------------------------------------------------------------- the Python path
@settings(max_examples=examples(40), deadline=None)
@given(q_init=st.sampled_from([0.0, 5.0]), steps=transitions)
def test_q_learning_is_the_reference(q_init, steps):
    agent = QLearning(GridWorldEnv(size=3), q_init=q_init, learning_rate=ALPHA, gamma=GAMMA)
    _feed(agent, ReferenceMMQ(N_STATES, N_ACTIONS, [0], q_init, ALPHA, GAMMA), steps)


@settings(max_examples=examples(40), deadline=None)
@given(k=st.integers(0, 6), steps=transitions)
def test_fixed_delay_q_learning_is_the_reference(k, steps):
    agent = FixedDelayQLearning(
        GridWorldEnv(size=3), delay_estimate=k, q_init=2.0, learning_rate=ALPHA, gamma=GAMMA
    )
    _feed(agent, ReferenceMMQ(N_STATES, N_ACTIONS, [k], 2.0, ALPHA, GAMMA), steps)


@settings(max_examples=examples(60), deadline=None)
@given(estimates=delay_sets, option=options, steps=transitions)
def test_mmq_is_the_reference(estimates, option, steps):
    agent = MultipleModelQLearning(
        GridWorldEnv(size=3), delay_estimates=estimates, q_init=5.0, learning_rate=ALPHA,
        gamma=GAMMA, **option,
    )  # fmt: skip
    reference = ReferenceMMQ(N_STATES, N_ACTIONS, estimates, 5.0, ALPHA, GAMMA, **option)
    _feed(agent, reference, steps)


@settings(max_examples=examples(40), deadline=None)
@given(delay=delays, max_delay_estimate=st.sampled_from([None, 3]), steps=transitions)
def test_expected_credit_is_the_reference(delay, max_delay_estimate, steps):
    agent = ExpectedCreditQLearning(
        GridWorldEnv(size=3),
        delay,
        max_delay_estimate,
        q_init=1.0,
        learning_rate=ALPHA,
        gamma=GAMMA,
    )
    weights = agent.credit_weights
    _feed(agent, ReferenceExpectedCredit(N_STATES, N_ACTIONS, weights, 1.0, ALPHA, GAMMA), steps)


@settings(max_examples=examples(40), deadline=None)
@given(steps=transitions, data=st.data())
def test_oracle_is_the_reference(steps, data):
    env = RewardDelay(GridWorldEnv(size=3), Constant(3), record_arrivals=True)
    agent = OracleQLearning(env, q_init=1.0, learning_rate=ALPHA, gamma=GAMMA)
    reference = ReferenceOracle(N_STATES, N_ACTIONS, agent.history_length, 1.0, ALPHA, GAMMA)
    step = 0
    for s, a, r, s2, code in steps:
        emitted = data.draw(st.lists(st.integers(-10, step), max_size=3))
        arrivals = [(e, r + e) for e in emitted]
        agent.update(s, a, r, s2, *_ends(code), info={"reward_arrivals": arrivals})
        reference.update(s, a, s2, *_ends(code), arrivals)
        np.testing.assert_array_equal(agent.q_table, reference.q)
        step = 0 if code in (0, 1) else step + 1


@settings(max_examples=examples(30), deadline=None)
@given(rewards=st.lists(st.floats(-5, 5), min_size=36, max_size=36), steps=transitions)
def test_deconvolution_is_q_learning_on_its_reward_model(rewards, steps):
    """Between solves, deconvolution Q-learning is Q-learning on ``R̂(s, a)``."""
    agent = DeconvolutionQLearning(
        GridWorldEnv(size=3), max_delay_estimate=4, solve_interval=10**6, q_init=0.5, learning_rate=ALPHA,
        gamma=GAMMA,
    )  # fmt: skip
    agent._reward_model[:] = rewards
    reference = ReferenceMMQ(N_STATES, N_ACTIONS, [0], 0.5, ALPHA, GAMMA)
    for s, a, r, s2, code in steps:
        agent.update(s, a, r, s2, *_ends(code))
        reference.update(s, a, rewards[s * N_ACTIONS + a], s2, *_ends(code))
        np.testing.assert_array_equal(agent.q_table, reference.q)


# ---------------------------------------------------------------------- the compiled path
def _replay_record(agent, reference) -> None:
    """Replay ``agent.training_log`` (episodes end only by termination) into ``reference``."""
    log = agent.training_log
    obs, action, reward, ended = log["obs"], log["action"], log["reward"], log["episode_end"]
    acting = log["acting_delay_index"]
    compiled = agent.last_learn_path == "compiled"  # where the run stopped: the next state
    stop = int(agent._compiled[1].state[0]) if compiled else agent._obs  # (env, run)
    after = [*obs[1:].tolist(), stop]
    for i in range(obs.size):
        s2 = int(obs[i]) if ended[i] else int(after[i])  # a terminal step does not bootstrap
        args = (int(obs[i]), int(action[i]), float(reward[i]), s2, bool(ended[i]), False)
        if isinstance(reference, ReferenceMMQ):
            reference.update(*args, acting=int(acting[i]))
        else:
            reference.update(*args)


LEARN_PATH_CASES = {
    "q": (QLearning, {}),
    "fixed": (FixedDelayQLearning, {"delay_estimate": 3}),
    "mmq": (MultipleModelQLearning, {"max_delay_estimate": 6}),
    "mmq-options": (
        MultipleModelQLearning,
        {"max_delay_estimate": 6, "reward_kernel": 1.0, "delay_trace": 0.8},
    ),  # fmt: skip
    "expected-credit": (ExpectedCreditQLearning, {"delay": Poisson(2.0), "max_delay_estimate": 8}),
}


REFERENCE_TESTS = {
    "QLearning": "test_q_learning_is_the_reference",
    "FixedDelayQLearning": "test_fixed_delay_q_learning_is_the_reference",
    "MultipleModelQLearning": "test_mmq_is_the_reference",
    "ExpectedCreditQLearning": "test_expected_credit_is_the_reference",
    "OracleQLearning": "test_oracle_is_the_reference",
    "DeconvolutionQLearning": "test_deconvolution_is_q_learning_on_its_reward_model",
}
"""Each agent class's test against its rule in :mod:`delayed_rl.agents.reference`."""


def test_every_registered_agent_has_a_reference_test_here():
    """A new agent's rule gets a reference and a test in this module, named here."""
    import inspect

    from delayed_rl.agents.registry import CLASS_NAMES

    assert set(CLASS_NAMES.values()) <= set(REFERENCE_TESTS)
    for class_name, test_name in REFERENCE_TESTS.items():
        source = inspect.getsource(globals()[test_name])
        assert class_name in source and "Reference" in source, test_name


COMPILED_PATH_TESTS = {
    "OracleQLearning": ("tests/agents/test_oracle.py", "test_without_delay_it_is_q_learning_update_for_update"),
    "DeconvolutionQLearning": (
        "tests/agents/test_deconvolution.py",
        "test_the_compiled_and_python_paths_learn_the_same_from_the_same_steps",
    ),
}  # fmt: skip
"""Agents with a compiled rule whose compiled path is checked by a test elsewhere: file, test."""


def test_every_compiled_rule_is_checked_on_both_paths():
    """A registered agent that returns ``compiled_tables`` has its compiled path tested.

    Here (:data:`LEARN_PATH_CASES`, replayed into its reference) or in a test named in
    :data:`COMPILED_PATH_TESTS`; an agent without a compiled rule trains on the Python path only.
    """
    from pathlib import Path

    from delayed_rl.agents import TabularAgent
    from delayed_rl.agents.registry import REGISTRY, agent_class

    here = {cls for cls, _ in LEARN_PATH_CASES.values()}
    for name in REGISTRY:
        cls = agent_class(name)
        if cls.compiled_tables is not TabularAgent.compiled_tables:
            assert cls in here or cls.__name__ in COMPILED_PATH_TESTS, cls.__name__
    root = Path(__file__).resolve().parents[2]
    for path, test in COMPILED_PATH_TESTS.values():  # the tests named are there
        assert f"def {test}(" in (root / path).read_text(encoding="utf-8"), (path, test)


def _reference_for(agent):
    if isinstance(agent, ExpectedCreditQLearning):
        return ReferenceExpectedCredit(
            agent.n_states, agent.n_actions, agent.credit_weights, agent.q_init, ALPHA, GAMMA
        )
    return ReferenceMMQ(
        agent.n_states, agent.n_actions, agent.delay_estimates, agent.q_init, ALPHA, GAMMA,
        getattr(agent, "reward_kernel", None), getattr(agent, "delay_trace", None),
    )  # fmt: skip


@pytest.mark.parametrize("compiled", [True, False])
@pytest.mark.parametrize("name", list(LEARN_PATH_CASES))
@pytest.mark.parametrize(("seed", "mode"), [(0, "flush"), (1, "carry"), (2, "drop")])
def test_both_learn_loops_are_the_reference(name, compiled, seed, mode):
    cls, kwargs = LEARN_PATH_CASES[name]
    env = RewardDelay(FrozenLakeEnv(is_slippery=True), Poisson(2.0), on_episode_end=mode)
    agent = cls(env, q_init=0.5, learning_rate=ALPHA, gamma=GAMMA, seed=seed, **kwargs)
    agent.learn(3_000, compiled=compiled, record=True)
    assert agent.last_learn_path == ("compiled" if compiled else "python")
    assert agent.training_log["episode_end"].sum() >= 20  # many episodes: the check has teeth
    reference = _reference_for(agent)
    _replay_record(agent, reference)
    np.testing.assert_array_equal(agent.q_table, reference.q)


@settings(max_examples=examples(40), deadline=None)
@given(estimates=delay_sets, option=options, steps=transitions, data=st.data())
def test_the_compiled_replay_is_the_reference(estimates, option, steps, data):
    """``kernel.replay`` (the compiled loop on scripted transitions) for any Λ and options."""
    rows = np.array([(s, a, s2) for s, a, _, s2, _ in steps], np.int64)
    terminated = np.array([code in (0, 1) for *_, code in steps])  # replay ends episodes so
    rewards = np.array([r for _, _, r, _, _ in steps])
    acting = np.array(data.draw(st.lists(st.integers(0, len(estimates) - 1),
                                         min_size=len(steps), max_size=len(steps))))  # fmt: skip
    q = np.full((N_STATES, len(estimates), N_ACTIONS), 4.0)
    replay(q, np.array(estimates), rows, terminated, rewards, ALPHA, GAMMA, acting=acting,
           **option)  # fmt: skip
    reference = ReferenceMMQ(N_STATES, N_ACTIONS, estimates, 4.0, ALPHA, GAMMA, **option)
    for (s, a, s2), done, r, m in zip(rows.tolist(), terminated, rewards, acting, strict=True):
        reference.update(s, a, float(r), s2, bool(done), False, acting=int(m))
    np.testing.assert_array_equal(q, reference.q)
