"""Tests of :mod:`delayed_rl.experiments`."""
