"""Tests of :mod:`delayed_rl.wrappers.vector`."""
