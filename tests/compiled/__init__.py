"""Tests of :mod:`delayed_rl.compiled`."""
