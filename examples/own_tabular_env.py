"""Your own tabular env on the compiled path: give it ``P`` and ``initial_state_distrib``.

A two-state chain: in state 0, action 1 moves to state 1 with probability 0.9; in state 1,
action 1 pays 1 and goes back to 0; action 0 always goes back to 0 and pays nothing. Its rewards
arrive Poisson(3) steps late. Because the env exposes its dynamics as Gymnasium's toy-text envs
do (``P[s][a]``: a list of ``(probability, next_state, reward, terminated)``, and
``initial_state_distrib``), ``learn()`` runs compiled by itself; ``reset``/``step`` are still
what the Python path (``compiled=False``), evaluation and your own loops use, so the two must agree.

Run::

    python examples/own_tabular_env.py [--steps 200000]
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np

from delayed_rl.agents import DeconvolutionQLearning, QLearning
from delayed_rl.wrappers import PoissonRewardDelay


class Chain(gym.Env):
    """The two-state chain above; continuing (it never ends an episode itself)."""

    observation_space = gym.spaces.Discrete(2)
    action_space = gym.spaces.Discrete(2)
    P = {
        0: {0: [(1.0, 0, 0.0, False)], 1: [(0.9, 1, 0.0, False), (0.1, 0, 0.0, False)]},
        1: {0: [(1.0, 0, 0.0, False)], 1: [(1.0, 0, 1.0, False)]},
    }
    initial_state_distrib = np.array([1.0, 0.0])

    def reset(self, *, seed=None, options=None):
        """Start in state 0."""
        super().reset(seed=seed)
        self.state = 0
        return self.state, {}

    def step(self, action):
        """Draw the outcome of ``P[state][action]``."""
        outcomes = self.P[self.state][int(action)]
        i = self.np_random.choice(len(outcomes), p=[p for p, *_ in outcomes])
        _, self.state, reward, terminated = outcomes[i]
        return self.state, reward, terminated, False, {}


def main() -> None:
    """Train Q-learning and DeconvQ on the delayed chain, compiled, and print their policies."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=200_000)
    args = parser.parse_args()
    env = PoissonRewardDelay(Chain(), 3.0)
    for agent in (
        QLearning(env, seed=0),
        DeconvolutionQLearning(env, max_delay_estimate=10, seed=0),
    ):
        agent.learn(args.steps)
        policy = agent.predict(np.arange(2), deterministic=True)[0]
        print(f"{type(agent).__name__}: trained on the {agent.last_learn_path} path, "
              f"greedy actions {policy.tolist()} (the optimum is [1, 1])")  # fmt: skip


if __name__ == "__main__":
    main()
