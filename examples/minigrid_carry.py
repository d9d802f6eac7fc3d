"""Minigrid with delayed rewards: why a terminal-reward task needs ``on_episode_end="carry"``.

Minigrid pays its only reward when the agent reaches the goal, the episode's last step. Under
the default ``"flush"`` the pending reward is delivered at that very step — the delay has no
effect at all (the wrapper warns). Under ``"carry"`` it arrives its delay's number of steps
later, in the next episode, as a delayed reward should. Needs the ``examples`` extra (minigrid).

Run::

    python examples/minigrid_carry.py [--episodes 30] [--reward-delay 10]
"""

from __future__ import annotations

import argparse
import warnings

import gymnasium as gym
import minigrid  # noqa: F401  (registers the MiniGrid ids)
from minigrid.wrappers import ImgObsWrapper

from delayed_rl.wrappers import PoissonRewardDelay


def walk_to_goal(env: gym.Env, episodes: int, seed: int) -> tuple[int, int]:
    """Walk the 5×5 empty room's shortest path ``episodes`` times.

    Returns:
        How many nonzero rewards arrived at an episode's final step, and how many at any step.
    """
    path = [2, 2, 1, 2, 2, 1]  # forward, forward, turn right, forward, forward (then the goal)
    at_end = total = 0
    env.reset(seed=seed)
    for _ in range(episodes):
        for action in path:
            _, reward, terminated, truncated, _ = env.step(action)
            total += reward != 0
            if terminated or truncated:
                at_end += reward != 0
                env.reset()
                break
    return at_end, total


def main() -> None:
    """Count where the rewards arrive under each mode."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=30)
    parser.add_argument(
        "--reward-delay", type=float, default=10.0, metavar="λ", help="Poisson mean delay (steps)"
    )
    args = parser.parse_args()
    for mode in ("flush", "carry"):
        env = PoissonRewardDelay(
            ImgObsWrapper(gym.make("MiniGrid-Empty-5x5-v0")), args.reward_delay, on_episode_end=mode
        )
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            at_end, total = walk_to_goal(env, args.episodes, seed=0)
        warned = any("the delay had no effect" in str(w.message) for w in caught)
        print(f'on_episode_end="{mode}": {at_end} of {total} rewards arrived at an episode\'s '
              f"final step; warned: {warned}")  # fmt: skip


if __name__ == "__main__":
    main()
