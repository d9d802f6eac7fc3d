"""Many independent runs at once, for the experiments and the sweeps alike.

- :mod:`.pools`: worker pools (joblib's ``loky`` processes, Ray, Dask), results as tasks finish;
- :mod:`.progress`: the runs' progress on the terminal;
- :mod:`.intervals`: 95 % intervals of means and of shares.
"""

from delayed_rl.parallel.intervals import mean_ci95, t975, wilson_interval
from delayed_rl.parallel.pools import (
    BACKENDS,
    MAX_SEED_COUNT,
    MAX_WORKERS,
    check_workers,
    iter_tasks,
    run_tasks,
)
from delayed_rl.parallel.progress import RunProgress, tqdm_installed

__all__ = [
    "BACKENDS",
    "MAX_SEED_COUNT",
    "MAX_WORKERS",
    "RunProgress",
    "check_workers",
    "iter_tasks",
    "mean_ci95",
    "run_tasks",
    "t975",
    "tqdm_installed",
    "wilson_interval",
]
