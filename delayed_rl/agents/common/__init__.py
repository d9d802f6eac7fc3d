"""The shell every tabular agent shares, as stable-baselines3's ``common`` package is for its own.

- :mod:`~delayed_rl.agents.common.base`: :class:`~delayed_rl.agents.common.base.TabularAgent`,
  the base class (``learn``, ``predict``, ``update``, ``save``/``load``, ``get_env``/``set_env``);
- :mod:`~delayed_rl.agents.common.q_table`: the Q-table and its exact cache of each state's max,
  which every algorithm learns in, and :mod:`~delayed_rl.agents.common.q_agent`:
  :class:`~delayed_rl.agents.common.q_agent.QAgent`, the agent over it that every algorithm
  subclasses;
- :mod:`~delayed_rl.agents.common.transition_ring`: the last transitions, for the rules that
  credit a reward to a step ``k`` steps back;
- :mod:`~delayed_rl.agents.common.python_loop` and :mod:`~delayed_rl.agents.common.compiled_loop`:
  the two training loops of ``learn()``;
- :mod:`~delayed_rl.agents.common.persistence` and :mod:`~delayed_rl.agents.common.save_util`:
  saving and loading, and the model-file format;
- :mod:`~delayed_rl.agents.common.env_util`, :mod:`~delayed_rl.agents.common.callbacks`,
  :mod:`~delayed_rl.agents.common.logger`, :mod:`~delayed_rl.agents.common.schedules`,
  :mod:`~delayed_rl.agents.common.hyperparameters`, :mod:`~delayed_rl.agents.common.statistics`
  and :mod:`~delayed_rl.agents.common.streams`: env helpers, SB3 callbacks, the logger, the
  learning-rate schedules, the shared hyper-parameters and their checks, the training
  statistics and the random streams.

The package imports nothing itself: import the module you need.
"""
