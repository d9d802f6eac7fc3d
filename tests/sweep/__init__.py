"""Tests of :mod:`delayed_rl.sweep`."""
