"""Tests of :mod:`delayed_rl.agents`."""
