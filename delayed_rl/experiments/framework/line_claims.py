"""The thesis's line-following values (Figs. 5.22–5.23) as claims and as figure lines.

``linefollow`` tests them, ``linefollow-deconv`` tests them again beside DeconvQ on the same
runs, and ``real-robot`` uses their tolerance: MMQ's and Q's average rewards during learning
against the thesis's 5-run values ± :data:`REWARD_TOLERANCE` (:func:`reward_claims`), and MMQ's
accumulated error over Q's against ≈ 0.4 ± :data:`RATIO_TOLERANCE` (:func:`error_ratio_claim`).
The figures draw the same values dashed (:func:`thesis_reward_lines`,
:func:`thesis_error_ratio_lines`).
"""

from __future__ import annotations

from delayed_rl.experiments.framework.claims import band_claim
from delayed_rl.experiments.framework.experiment import Claim

#: The band of the average-reward claims (and of MMQ − Q): the thesis's value ± this.
REWARD_TOLERANCE = 0.2
#: The band of the accumulated-error ratio: 0.4 ± this.
RATIO_TOLERANCE = 0.15
#: The thesis's 5-run average rewards during learning (Fig. 5.22).
THESIS_REWARD = {"MMQ": 0.55, "Q": 0.12}
#: The thesis's MMQ accumulated error over Q's (Fig. 5.23: "only about 40 %").
THESIS_ERROR_RATIO = 0.4


def reward_claims(stat: dict[str, tuple[float, float, int]]) -> list[Claim]:
    """MMQ's and Q's average reward during learning against Fig. 5.22's, ± ``REWARD_TOLERANCE``.

    Args:
        stat: ``{"MMQ": (mean, ci, n), "Q": (mean, ci, n)}`` of the runs' average rewards.
    """
    return [
        band_claim(
            f"{agent} average reward during learning",
            f"≈ {value} (Fig. 5.22)",
            stat[agent],
            value,
            REWARD_TOLERANCE,
        )
        for agent, value in THESIS_REWARD.items()
    ]


def error_ratio_claim(ratio: tuple[float, float, int], note: str) -> Claim:
    """MMQ's accumulated error over Q's (paired by seed) against Fig. 5.23's ≈ 0.4."""
    return band_claim(
        "MMQ accumulated error / Q accumulated error",
        "≈ 0.4 (Fig. 5.23)",
        ratio,
        THESIS_ERROR_RATIO,
        RATIO_TOLERANCE,
        note=note,
    )


def thesis_reward_lines() -> list[tuple[float, str, str]]:
    """The thesis's average rewards (Fig. 5.22) as :func:`.plotting.learning_curves` lines."""
    return [
        (value, f"thesis {agent} ≈ {value} (Fig. 5.22, 5-run mean)", agent)
        for agent, value in THESIS_REWARD.items()
    ]


def thesis_error_ratio_lines() -> list[tuple[str, float, str, str]]:
    """The thesis's error ratio (Fig. 5.23) as a :func:`.plotting.learning_curves` ratio curve."""
    label = f"thesis MMQ = {THESIS_ERROR_RATIO} × Q's error (Fig. 5.23)"
    return [("Q", THESIS_ERROR_RATIO, label, "MMQ")]
