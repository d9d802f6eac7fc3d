"""The shell every tabular agent shares, as stable-baselines3's ``common`` package is for its own.

:mod:`~delayed_rl.agents.common.base` (:class:`~delayed_rl.agents.common.base.TabularAgent`),
:mod:`~delayed_rl.agents.common.q_table` and :mod:`~delayed_rl.agents.common.q_agent` (the
Q-table and the agent over it), :mod:`~delayed_rl.agents.common.transition_ring` (the last
transitions), :mod:`~delayed_rl.agents.common.python_loop` and
:mod:`~delayed_rl.agents.common.compiled_loop` (the two training loops),
:mod:`~delayed_rl.agents.common.persistence` and :mod:`~delayed_rl.agents.common.save_util`
(model files), and the env helpers, callbacks, logger, schedules, hyper-parameters, statistics
and random streams. The package imports nothing itself: import the module you need.
"""
