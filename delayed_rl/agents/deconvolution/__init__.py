"""Deconvolution Q-learning: Q-learning on mean rewards estimated from the delayed stream.

- :mod:`~delayed_rl.agents.deconvolution.agent`: the agent,
  :class:`~delayed_rl.agents.deconvolution.agent.DeconvolutionQLearning`;
- :mod:`~delayed_rl.agents.deconvolution.regression`: the regression that estimates the mean
  rewards (and, with the delay unknown, its pmf) from the delivered rewards.

The statistics the regression reads are gathered by
:mod:`delayed_rl.compiled.deconvolution_statistics`, which both training paths feed.
"""

from delayed_rl.agents.deconvolution.agent import DeconvolutionQLearning

__all__ = ["DeconvolutionQLearning"]
