"""Tests of :mod:`delayed_rl.parallel`."""
