"""Fixed (non-learning) controllers: the thesis's proportional line follower."""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces
from numpy.typing import ArrayLike, NDArray

from delayed_rl.envs.linefollow.camera import CENTRE_PIXEL, N_PIXELS, line_centroid
from delayed_rl.envs.linefollow.env import MAX_WHEEL_SPEED, WHEEL_SPEED_ACTIONS

__all__ = ["ProportionalController"]


class ProportionalController:
    """The proportional line follower of thesis Eqs. 5.8–5.9.

    With Δ = m − 20 (m the line centroid; Δ > 0 when the line is to the robot's right, since
    pixel 1 is on the left)::

        v_left  = base_speed − k_p·|Δ| + k_p·Δ        (Eq. 5.8, v_1)
        v_right = base_speed − k_p·|Δ| − k_p·Δ        (Eq. 5.9, v_2)

    so the wheel on the line's side slows down and the robot turns towards the line; a centred
    line gives both wheels ``base_speed``. With the thesis's k_p = 6 and base speed 300 the
    speeds stay in [60, 300].

    **Line not seen (m = 0):** the controller repeats its last command (the robot keeps turning
    the way it was, which usually brings a line lost on a bend back into view). The last command
    travels in the ``state`` returned by :meth:`predict`, as in stable-baselines3's recurrent
    policies: pass it back (``evaluate_policy`` does). Without a state (``state=None``), or where
    ``episode_start`` is True, there is no last command and the robot drives straight at
    ``base_speed``.

    Actions: on ``action_mode="continuous"`` envs (the default when ``env`` is None) the action is
    the normalised wheel-speed pair (v_left, v_right) / 300; on ``action_mode="discrete"`` envs,
    the index of the nearest Table 5.2 pair (Euclidean distance in wheel-speed space).
    Observations: centroids (``Discrete(41)``, the default) or, on ``observation_mode="pixels"``
    envs, the 40 pixels, from which m is computed.

    Args:
        k_p: the proportional gain (thesis: 6).
        base_speed: wheel speed (steps/s) with the line centred, in (0, 300].
        env: an :class:`~delayed_rl.envs.linefollow.env.EPuckLineFollowEnv` (possibly wrapped)
            or its id; only its spaces are used, to choose the action and observation format.

    Example:
        >>> ctrl = ProportionalController()
        >>> ctrl.predict(25)[0]  # line 5 pixels right of centre: slow the right wheel
        array([1. , 0.8], dtype=float32)
    """

    def __init__(self, k_p: float = 6.0, base_speed: float = MAX_WHEEL_SPEED, env: Any = None):
        if isinstance(k_p, bool) or not isinstance(k_p, int | float | np.integer | np.floating):
            raise TypeError(f"k_p must be a number, got {k_p!r} ({type(k_p).__name__})")
        if not (np.isfinite(k_p) and k_p >= 0):
            raise ValueError(f"k_p must be a finite number >= 0, got {k_p!r}")
        if isinstance(base_speed, bool) or not isinstance(
            base_speed, int | float | np.integer | np.floating
        ):
            raise TypeError(f"base_speed must be a number, got {base_speed!r}")
        if not (np.isfinite(base_speed) and 0 < base_speed <= MAX_WHEEL_SPEED):
            raise ValueError(
                f"base_speed must be in (0, {MAX_WHEEL_SPEED}] steps/s, got {base_speed!r}"
            )
        self.k_p = float(k_p)
        self.base_speed = float(base_speed)
        self.discrete_actions = False
        self.pixel_observations = False
        self.env = None
        if env is not None:
            self.set_env(env)

    def set_env(self, env: Any) -> None:
        """Adopt ``env``'s action and observation formats (an env, a wrapped env or an id)."""
        if isinstance(env, str):
            import gymnasium as gym

            env = gym.make(env)
        action_space, observation_space = env.action_space, env.observation_space
        if isinstance(action_space, spaces.Discrete) and action_space.n == len(WHEEL_SPEED_ACTIONS):
            discrete = True
        elif isinstance(action_space, spaces.Box) and action_space.shape == (2,):
            discrete = False
        else:
            raise ValueError(
                f"env's action space must be Discrete({len(WHEEL_SPEED_ACTIONS)}) or Box of "
                f"shape (2,) (EPuckLineFollow), got {action_space}"
            )
        if isinstance(observation_space, spaces.Discrete) and observation_space.n == N_PIXELS + 1:
            pixels = False
        elif isinstance(observation_space, spaces.Box) and observation_space.shape == (N_PIXELS,):
            pixels = True
        else:
            raise ValueError(
                f"env's observation space must be Discrete({N_PIXELS + 1}) (centroid) or Box of "
                f"shape ({N_PIXELS},) (pixels), got {observation_space}"
            )
        self.env, self.discrete_actions, self.pixel_observations = env, discrete, pixels

    def get_env(self) -> Any:
        """The env given to the constructor or :meth:`set_env`, if any."""
        return self.env

    def wheel_speeds(self, centroid: ArrayLike) -> NDArray[np.float64]:
        """Eqs. 5.8–5.9: ``(..., 2)`` (left, right) speeds (steps/s) for centroids m ∈ 1..40.

        m = 0 (line not seen) is not handled here; see :meth:`predict`.
        """
        delta = np.asarray(centroid, dtype=np.float64) - CENTRE_PIXEL
        slow = self.base_speed - self.k_p * np.abs(delta)
        speeds = np.empty(delta.shape + (2,))
        speeds[..., 0] = slow + self.k_p * delta
        speeds[..., 1] = slow - self.k_p * delta
        return speeds

    def predict(
        self,
        observation: ArrayLike,
        state: Any = None,
        episode_start: ArrayLike | None = None,
        deterministic: bool = True,
    ) -> tuple[NDArray, NDArray[np.float32]]:
        """The controller's action for one observation or a batch (stable-baselines3 style).

        Args:
            observation: a centroid (int) or a batch ``(n,)`` of them; with a pixels env, a
                ``(40,)`` pixel row or an ``(n, 40)`` batch.
            state: the state returned by the previous call (the last normalised wheel speeds,
                ``(2,)`` or ``(n, 2)``), or None.
            episode_start: booleans (scalar or ``(n,)``); True forgets the last command.
            deterministic: ignored (the controller is deterministic).

        Returns:
            ``(action, state)``: the action(s) in the env's format, and the new state to pass
            back next time.
        """
        obs = np.asarray(observation)
        batched = obs.ndim == (2 if self.pixel_observations else 1)
        m = np.atleast_1d(line_centroid(obs) if self.pixel_observations else obs).astype(np.int64)
        if m.ndim != 1 or np.any((m < 0) | (m > N_PIXELS)):
            raise ValueError(
                f"observation must be line centroids in 0..{N_PIXELS} (scalar or 1-D batch), "
                f"got {observation!r}"
            )
        speeds = self.wheel_speeds(m) / MAX_WHEEL_SPEED
        unseen = m == 0
        if unseen.any():  # repeat the last command (see the class docstring)
            straight = self.base_speed / MAX_WHEEL_SPEED
            last = np.full((len(m), 2), straight)
            if state is not None:
                last[:] = np.asarray(state, dtype=np.float64)
            if episode_start is not None:
                last[np.broadcast_to(np.asarray(episode_start, dtype=bool), (len(m),))] = straight
            speeds[unseen] = last[unseen]
        new_state = speeds.astype(np.float32)
        if self.discrete_actions:
            table = np.asarray(WHEEL_SPEED_ACTIONS, dtype=np.float64) / MAX_WHEEL_SPEED
            distance = ((speeds[:, None, :] - table[None, :, :]) ** 2).sum(axis=-1)
            action: NDArray = distance.argmin(axis=1)
        else:
            action = new_state
        if not batched:
            return action[0], new_state[0]
        return action, new_state
