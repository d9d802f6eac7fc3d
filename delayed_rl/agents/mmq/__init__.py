"""Multiple Model Q-learning (Campbell 2015, section 3.2, Eq. 3.7 and Algorithm 1).

- :mod:`~delayed_rl.agents.mmq.mmq`: the agent,
  :class:`~delayed_rl.agents.mmq.mmq.MultipleModelQLearning`, with the exact rule;
- :mod:`~delayed_rl.agents.mmq.options`: its options beyond the thesis's rule (the reward
  kernel, the delay trace and the averaged greedy table);
- :mod:`~delayed_rl.agents.mmq.updates`: a step's updates of every model, compiled.
"""

from delayed_rl.agents.mmq.mmq import MultipleModelQLearning

__all__ = ["MultipleModelQLearning"]
