"""Fixed (non-learning) controllers: the thesis's proportional line follower."""

from __future__ import annotations

import numbers
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from numpy.typing import ArrayLike, NDArray

from delayed_rl._validation import check_real
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

    Actions: on ``action_mode="discrete"`` envs (the registered env's default, and the format
    used when ``env`` is None) the index of the nearest Table 5.2 pair (Euclidean distance in
    wheel-speed space); on ``action_mode="continuous"`` envs the normalised wheel-speed pair
    (v_left, v_right) / 300. Observations: centroids (``Discrete(41)``, the default) or, on
    ``observation_mode="pixels"`` envs, the 40 pixels, from which m is computed.

    Args:
        env: an :class:`~delayed_rl.envs.linefollow.env.EPuckLineFollowEnv` (possibly wrapped),
            its id, or ``None`` (the registered env's formats); only its spaces are used, to
            choose the action and observation format. The first argument, as for every agent.
        k_p: the proportional gain (thesis: 6), a number >= 0.
        base_speed: wheel speed (steps/s) with the line centred, in (0, 300].

    Example:
        >>> ctrl = ProportionalController()
        >>> ctrl.wheel_speeds(25)  # line 5 pixels right of centre: slow the right wheel
        array([300., 240.])
        >>> int(ctrl.predict(25)[0])  # the nearest Table 5.2 pair, (300, 200)
        4
    """

    def __init__(self, env: Any = None, k_p: float = 6.0, base_speed: float = MAX_WHEEL_SPEED):
        self.k_p = check_real("k_p", k_p, 0.0)
        self.base_speed = check_real(
            "base_speed", base_speed, 0.0, MAX_WHEEL_SPEED, low_open=True, note=" steps/s"
        )
        self.discrete_actions = True
        self.pixel_observations = False
        self.env = None
        if env is not None:
            self.set_env(env)

    def set_env(self, env: Any) -> None:
        """Adopt ``env``'s action and observation formats (an env, a wrapped env or an id).

        Raises:
            TypeError: ``env`` is not an env or an id.
            ValueError: its spaces are not the e-puck env's.
        """
        if isinstance(env, str):
            env = gym.make(env)
        if not isinstance(env, gym.Env):
            hint = (
                " (since 0.2 the env is the first argument: pass k_p=...)"
                if isinstance(env, numbers.Real)
                else ""
            )
            raise TypeError(
                f"env must be an EPuckLineFollow env, its id or None, got {env!r}{hint}"
            )
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
        deterministic: bool = False,
    ) -> tuple[NDArray, NDArray[np.float32]]:
        """The controller's action for one observation or a batch (stable-baselines3 style).

        Args:
            observation: a centroid (int) or a batch ``(n,)`` of them; with a pixels env, a
                ``(40,)`` pixel row or an ``(n, 40)`` batch.
            state: the state returned by the previous call (the last normalised wheel speeds,
                finite numbers of shape ``(2,)``, or ``(n, 2)`` for a batch of ``n``), or None.
            episode_start: booleans (scalar or ``(n,)``); True forgets the last command.
            deterministic: ignored (the controller is deterministic; the default, ``False``, is
                every agent's, as in stable-baselines3).

        Returns:
            ``(action, state)``: the action(s) in the env's format, and the new state to pass
            back next time.

        Raises:
            TypeError: ``observation`` (centroids) or ``state`` does not hold numbers.
            ValueError: ``observation`` is not centroids in 0..40 (or pixel rows), or ``state``
                has the wrong shape or a NaN or infinite entry.
        """
        obs = np.asarray(observation)
        if not self.pixel_observations and (
            obs.dtype.kind not in "iuf" or (obs.dtype.kind == "f" and not np.all(obs == obs // 1))
        ):
            error = TypeError if obs.dtype.kind not in "iuf" else ValueError
            raise error(
                f"observation must be line centroids in 0..{N_PIXELS} (scalar or 1-D batch), "
                f"got {observation!r} ({type(observation).__name__})"
            )
        batched = obs.ndim == (2 if self.pixel_observations else 1)
        m = np.atleast_1d(line_centroid(obs) if self.pixel_observations else obs).astype(np.int64)
        if m.ndim != 1 or np.any((m < 0) | (m > N_PIXELS)):
            raise ValueError(
                f"observation must be line centroids in 0..{N_PIXELS} (scalar or 1-D batch), "
                f"got {observation!r}"
            )
        last_command = None if state is None else self._check_state(state, len(m), batched)
        speeds = self.wheel_speeds(m) / MAX_WHEEL_SPEED
        unseen = m == 0
        if unseen.any():  # repeat the last command (see the class docstring)
            straight = self.base_speed / MAX_WHEEL_SPEED
            last = np.full((len(m), 2), straight)
            if last_command is not None:
                last[:] = last_command
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

    @staticmethod
    def _check_state(state: Any, n: int, batched: bool) -> NDArray[np.float64]:
        """``state`` as a float array after checking it: finite, ``(2,)`` or ``(n, 2)``."""
        allowed = f"the last normalised wheel speeds, finite numbers of shape (2,){' or (n, 2)' if batched else ''}"
        try:
            raw = np.asarray(state)
        except ValueError:  # a ragged nesting
            raw = np.asarray(state, dtype=object)
        if raw.dtype.kind not in "iuf":  # strings, None, bools, ragged lists...
            raise TypeError(
                f"state must be {allowed} (the state returned by predict), got {state!r} "
                f"({type(state).__name__})"
            )
        last = raw.astype(np.float64)
        shapes = [(2,), (n, 2)] if batched else [(2,)]
        if last.shape not in shapes:
            raise ValueError(
                f"state must have shape {' or '.join(map(str, shapes))} (the state returned by "
                f"predict), got shape {last.shape}"
            )
        if not np.all(np.isfinite(last)):
            raise ValueError(f"state must be {allowed}, got {state!r}")
        return last
