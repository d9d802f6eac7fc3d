"""Hypothesis profiles for the whole suite: ``dev`` (few examples) unless ``HYPOTHESIS_PROFILE``.

``dev``, the default, is hypothesis's ``default`` profile with 10 examples a test in place of
100: it keeps ``python -m pytest -q`` fast. ``ci`` (``HYPOTHESIS_PROFILE=ci``, as ``.ci/run``
sets it) is hypothesis's own built-in ``ci`` profile: its 100 examples a test, the counts the
tests had before these profiles, derandomized, without a deadline or an example database (what
hypothesis already chose by itself on a CI machine, where ``CI`` is set). A test that sets its
own ``max_examples`` overrides the profile, so it states its ``ci`` count through
:func:`support.examples`, which scales it to the active profile.

Which tests run by default is ``addopts`` in ``pyproject.toml``: all but the ones marked
``experiment``, ``distributed``, ``sb3``, ``cold_cache``, ``statistical`` or ``large``
(CONTRIBUTING.md says what each holds).
"""

from __future__ import annotations

import os

from hypothesis import settings

settings.register_profile("dev", settings.get_profile("default"), max_examples=10)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "dev"))
