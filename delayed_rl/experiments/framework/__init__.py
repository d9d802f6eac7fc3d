"""What the experiments are built on; no experiment module imports another, they import these.

- :mod:`.experiment`: configs, experiments, tasks, shared runs, claims, curves and summaries;
- :mod:`.report`: the files an experiment writes, and a reproduction's index;
- :mod:`.pool`: every experiment's runs, each distinct one run once, on one pool of workers
  (:mod:`delayed_rl.parallel`'s);
- :mod:`.results`: an experiment's results by any of its tasks' fields and by seed;
- :mod:`.claims`: the 95 % intervals and the rules that turn them into verdicts;
- :mod:`.plotting`: the figures;
- :mod:`.training`: the thesis's hyper-parameters and its grid-world training runs;
- :mod:`.normalised_runs`: grid-world runs normalised by undelayed Q-learning (Eq. 5.3);
- :mod:`.snapshot_runs`: grid-world training in pieces, with the greedy policy's snapshots;
- :mod:`.delay_settings`: the grid worlds under anonymous delays and their learners;
- :mod:`.setting_summaries`: those settings' tables, claims and figures;
- :mod:`.delay_estimates`: what an agent believes of the delay, and its claim;
- :mod:`.line_following`: the e-puck line follower's setting, learners and pooled training run;
- :mod:`.line_claims`: the thesis's line-following values (Figs. 5.22–5.23) as claims and lines;
- :mod:`.gain_settings`, :mod:`.deep_training`, :mod:`.late_training`,
  :mod:`.multiagent_training`: the SB3 experiments' settings, gains and training runs.
"""
