"""Tests of :mod:`delayed_rl.multiagent`."""
