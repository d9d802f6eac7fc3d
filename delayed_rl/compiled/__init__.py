"""The compiled (numba) training path for tabular envs and the e-puck; see :class:`CompiledRun`.

``agent.learn()`` runs on it by itself when it can (``learn(compiled=None)``, the default): the
agent's rule has a compiled twin (``agent.compiled_tables()`` is not ``None``: every agent of
:mod:`delayed_rl.agents` — MMQ, Q-learning, fixed-delay Q-learning, deconvolution Q-learning,
expected credit and the oracle), the env stack compiles (:mod:`delayed_rl.compiled.tabular` states the
protocol), the learning rate is constant and no callback is given (a progress bar is fine).
``learn(compiled=False)`` never does and ``learn(compiled=True)`` must (else
:class:`NotCompilable` says why).

- The update rule is the Python path's; the random streams differ, so seeded runs agree in
  distribution, not step by step. Each path is reproducible from the agent's seed.
- A tabular env object is not stepped: the compiled loop reads the env's tables. The e-puck
  line follower is (:mod:`delayed_rl.compiled.robot`): the compiled loop steps its robot, its own
  generator drawing its noise, and leaves the env where the run is. Either way the next
  Python-path ``learn()`` resets the env (the run's pending rewards are in the run, not in the
  env's delay wrapper).
- Compiling: numba compiles the loop the first time a machine trains a kind of agent (one
  version per combination of the rule's options: a reward model, the oracle's record, MMQ's
  credit options, a greedy window, the e-puck), which takes seconds, and caches it on disk
  beside the package: later runs, processes and workers load it from there
  (``benchmarks/SPEED.md``).
- Callbacks (with ``compiled=True``) still get one ``on_step()`` per step, with that step's
  ``locals`` (``info`` holds only ``undelayed_reward``), but they run after each compiled chunk
  of ``agent.compiled_chunk`` steps: the model they see (an ``EvalCallback``'s evaluation, a
  ``CheckpointCallback``'s file) is the one at the chunk's end, and a callback's ``False`` stops
  training at the end of its chunk.
"""

from typing import Any

from delayed_rl._numba import HAVE_NUMBA
from delayed_rl.compiled.tabular import NotCompilable, TabularModel, inspect_stack

__all__ = ["HAVE_NUMBA", "CompiledRun", "NotCompilable", "TabularModel", "inspect_stack"]


def __getattr__(name: str) -> Any:
    """:class:`CompiledRun`, imported on first use.

    The loop it runs can step the e-puck, whose physics (pymunk) an agent that trains on a
    grid need not load.
    """
    if name == "CompiledRun":
        from delayed_rl.compiled.run import CompiledRun

        return CompiledRun
    raise AttributeError(f"module 'delayed_rl.compiled' has no attribute {name!r}")
