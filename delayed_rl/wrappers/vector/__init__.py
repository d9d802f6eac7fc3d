"""The ``gymnasium.vector`` twins of the wrappers: each applies its single-env namesake's rule to every sub-env.

As Gymnasium lays out ``gymnasium.wrappers.vector``, each family's twin is in the module of the
same name as its single-env family (``wrappers/reward_delay.py`` and
``wrappers/vector/reward_delay.py``). The stable-baselines3 twin of the reward delay,
:class:`~delayed_rl.wrappers.sb3.VecRewardDelay`, is in ``wrappers/sb3.py`` (it imports
stable-baselines3) and is imported from there; :mod:`delayed_rl.wrappers` exports the
``gymnasium.vector`` twins.
"""

from delayed_rl.wrappers.vector.action_delay import VectorActionDelay
from delayed_rl.wrappers.vector.delay_aware import VectorDelayAwareObservation
from delayed_rl.wrappers.vector.observation_delay import VectorObservationDelay
from delayed_rl.wrappers.vector.reward_delay import VectorRewardDelay

__all__ = [
    "VectorActionDelay",
    "VectorDelayAwareObservation",
    "VectorObservationDelay",
    "VectorRewardDelay",
]
