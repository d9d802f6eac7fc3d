"""Tests of :mod:`delayed_rl.envs`."""
