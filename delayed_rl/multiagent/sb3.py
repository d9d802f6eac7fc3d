"""A PettingZoo ``ParallelEnv``'s agents as one stable-baselines3 vector env: :func:`sb3_vec_env`."""

from __future__ import annotations

from typing import Any

__all__ = ["sb3_vec_env"]


def sb3_vec_env(env: Any) -> Any:
    """``env``'s agents as the sub-envs of one stable-baselines3 ``VecEnv`` (parameter sharing).

    SuperSuit's ``pettingzoo_env_to_vec_env_v1`` makes every agent a sub-env, and
    ``concat_vec_envs_v1`` hands the result to stable-baselines3: one policy acts for every agent,
    on each agent's own observation, and learns from every agent's steps (SB3 counts each
    agent's step as a step). Every agent must have the same observation and action spaces, and
    every agent must stay until the episode ends (SuperSuit's rules).

    SuperSuit's SB3 adapter has no ``seed()``, which SB3's algorithms call with their ``seed``.
    This one's ``seed(s)`` seeds the next ``reset()``: the env's ``reset(seed=s)``, and so, for
    the library's wrappers, every agent's delays. Later resets (SuperSuit resets the env when
    every agent is done) continue the env's and the delays' generators unseeded, so a seed fixes
    the whole run, as with SB3's own vector envs.

    It needs SuperSuit (the ``multiagent`` extra) and stable-baselines3 (the ``sb3`` extra).

    Args:
        env: a ``pettingzoo.ParallelEnv``, e.g. behind
            :class:`~delayed_rl.multiagent.ParallelRewardDelay`.

    Returns:
        The ``VecEnv``, with ``num_envs`` the number of agents.

    Example:
        >>> import pettingzoo
        >>> from delayed_rl.multiagent import ParallelRewardDelay, sb3_vec_env
        >>> game = pettingzoo.make("parallel", "sisl/pursuit-v5", n_pursuers=4, max_cycles=50)
        >>> venv = sb3_vec_env(ParallelRewardDelay(game, 30))  # Poisson(30) per pursuer
        >>> venv.num_envs, venv.observation_space.shape
        (4, (7, 7, 3))

        ``PPO("MlpPolicy", venv, seed=0)`` then trains one policy for the four pursuers.
    """
    import supersuit
    from supersuit.vector.sb3_vector_wrapper import SB3VecEnvWrapper

    class SeededVecEnv(SB3VecEnvWrapper):
        """SuperSuit's SB3 adapter with a ``seed()``: the seed of the next ``reset()``."""

        next_seed: int | None = None

        def seed(self, seed: int | None = None) -> list[int | None]:
            self.next_seed = seed
            return [seed] * self.num_envs

        def reset(self, seed: int | None = None, options: dict | None = None) -> Any:
            seed, self.next_seed = (self.next_seed if seed is None else seed), None
            observations, self.reset_infos = self.venv.reset(seed=seed, options=options)
            return observations

    agents = supersuit.pettingzoo_env_to_vec_env_v1(env)
    return SeededVecEnv(supersuit.concat_vec_envs_v1(agents, 1, num_cpus=0))
