"""What an agent believes of the delay, and the claim on its mean.

DeconvQ learns a delay pmf (``delay_pmf``, ``mean_delay``); MMQ's acting-delay share says how
often each delay estimate λ̂ acted. :func:`delay_estimate` reads either off a trained agent (as
``anonymous-delay``, ``future-work``, ``linefollow`` and ``linefollow-deconv`` report it), and
:func:`mean_delay_claim` tests the estimated mean delay against the true one, ± 10 %.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from delayed_rl.experiments.framework.claims import band_claim
from delayed_rl.experiments.framework.experiment import Claim

#: The band of the mean-delay claims: the true mean ± this share of it.
DELAY_TOLERANCE = 0.10
#: The figures' names of the agents' estimates.
ESTIMATE_LABELS = {"MMQ": "MMQ acting share", "DeconvQ learned": "DeconvQ learned pmf"}


def delay_estimate(agent: Any) -> dict[str, Any]:
    """What ``agent`` believes of the delay: DeconvQ's pmf, MMQ's acting share (else nothing).

    Returns:
        ``estimate_support`` (the delays the estimate is over), ``estimate`` (a distribution
        over them: DeconvQ's ``delay_pmf``, MMQ's ``acting_delay_share``) and ``mean_delay``
        (its mean), or ``{}`` for agents that hold no estimate.
    """
    if hasattr(agent, "delay_pmf"):
        pmf = np.asarray(agent.delay_pmf)
        support = np.arange(pmf.size)
        return {"estimate_support": support, "estimate": pmf, "mean_delay": float(agent.mean_delay)}
    if hasattr(agent, "acting_delay_share") and len(agent.delay_estimates) > 1:
        share = np.asarray(agent.acting_delay_share)
        support = np.asarray(agent.delay_estimates, dtype=np.int64)
        return {
            "estimate_support": support,
            "estimate": share,
            "mean_delay": float(np.sum(share * support)),
        }
    return {}


def mean_delay_claim(quantity: str, stats: tuple[float, float, int], true: float) -> Claim:
    """The estimated mean delay ``stats`` against the ``true`` mean ± ``DELAY_TOLERANCE`` of it."""
    return band_claim(
        quantity, f"extension: the true mean {true:g}", stats, true, DELAY_TOLERANCE * true
    )
