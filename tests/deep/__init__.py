"""Tests of :mod:`delayed_rl.deep`."""
