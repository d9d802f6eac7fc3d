"""What the experiments are built on; no experiment module imports another, they import these.

:mod:`.experiment` (what an experiment is), :mod:`.pool` (running them), :mod:`.report` (their
files), :mod:`.results` (results by task field and seed), :mod:`.claims` (intervals and
verdicts) and :mod:`.plotting` (figures); the pieces several experiments share:
:mod:`.training`, :mod:`.normalised_runs`, :mod:`.snapshot_runs`, :mod:`.delay_settings`,
:mod:`.setting_summaries` and :mod:`.delay_estimates` (grid worlds), :mod:`.line_following` and
:mod:`.line_claims` (the e-puck), :mod:`.gain_settings`, :mod:`.deep_training`,
:mod:`.late_training` and :mod:`.multiagent_training` (the SB3 experiments).
"""
