"""PPO on CartPole and DQN on Taxi with Poisson-delayed rewards (stable-baselines3).

The delay wrapper goes around the env SB3 trains on; SB3 sees only the delayed reward. The
agents are evaluated on the undelayed env (what they learned, not what they were paid). Needs
the ``sb3`` extra (stable-baselines3; install ``torch==2.13.0`` first for the CPU build).

Run::

    python examples/sb3_delayed_rewards.py [--steps 50000] [--reward-delay 5]
"""

from __future__ import annotations

import argparse

import gymnasium as gym
from stable_baselines3 import DQN, PPO
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.monitor import Monitor

from delayed_rl.wrappers import PoissonRewardDelay


def train(algo, env_id: str, steps: int, lam: float, **kwargs) -> tuple[float, float]:
    """Train ``algo`` on ``env_id`` with Poisson(``lam``) reward delays; evaluate undelayed."""
    delayed = PoissonRewardDelay(gym.make(env_id), lam)  # under "flush": episode returns kept
    model = algo("MlpPolicy", delayed, seed=0, verbose=0, **kwargs).learn(steps)
    mean, std = evaluate_policy(model, Monitor(gym.make(env_id)), n_eval_episodes=10)
    return mean, std


def main() -> None:
    """Train both, print their undelayed returns."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=50_000)
    parser.add_argument(
        "--reward-delay", type=float, default=5.0, metavar="λ", help="Poisson mean delay (steps)"
    )
    args = parser.parse_args()
    mean, std = train(PPO, "CartPole-v1", args.steps, args.reward_delay, n_steps=256)
    print(
        f"PPO, CartPole-v1, Poisson({args.reward_delay}) reward delays: return {mean:.1f} ± {std:.1f}"
    )
    mean, std = train(DQN, "Taxi-v4", args.steps, args.reward_delay, learning_starts=500)
    print(
        f"DQN, Taxi-v4, Poisson({args.reward_delay}) reward delays: return {mean:.1f} ± {std:.1f}"
    )


if __name__ == "__main__":
    main()
