"""Statistics of small evaluations: the interval of a rate and the exact test of two detectors'
paired outcomes. Pure functions on counts; :mod:`asnn.evaluation.scoring` applies them to clip
scores (a dozen clips give rates whose uncertainty must be shown beside them)."""

from __future__ import annotations

import math

__all__ = ["mcnemar_exact", "wilson_interval"]


def wilson_interval(successes: int, trials: int, z: float = 1.96) -> list[float] | None:
    """The Wilson score interval of a proportion ``successes / trials`` [1]_.

    Unlike the normal approximation ``p +- z sqrt(p (1 - p) / n)``, it stays within [0, 1] and
    does not collapse to a point at 0 or ``n`` successes, which a dozen clips often give.

    Parameters
    ----------
    successes, trials : int
    z : float
        The normal quantile: 1.96 for a 95 % interval.

    Returns
    -------
    [low, high] or None
        None when ``trials`` is 0.

    References
    ----------
    .. [1] E. B. Wilson, "Probable inference, the law of succession, and statistical
       inference", Journal of the American Statistical Association 22, 1927, pp. 209-212.
    """
    if trials <= 0:
        return None
    if not 0 <= successes <= trials:
        raise ValueError(f"successes must lie in 0..trials, got {successes} of {trials}")
    p = successes / trials
    z2 = z * z
    scale = 1.0 + z2 / trials
    centre = (p + z2 / (2 * trials)) / scale
    half = z * math.sqrt(p * (1.0 - p) / trials + z2 / (4 * trials * trials)) / scale
    # at 0 or n successes the interval ends at 0 or 1 exactly (rounding left 1 - 1e-16)
    low = 0.0 if successes == 0 else max(0.0, centre - half)
    high = 1.0 if successes == trials else min(1.0, centre + half)
    return [low, high]


def mcnemar_exact(only_first: int, only_second: int) -> float:
    """Two-sided p-value of McNemar's exact test [1]_ on paired outcomes.

    ``only_first`` pairs have the outcome with the first detector alone, ``only_second`` with
    the second alone (the pairs where both agree carry no information on which is better).
    Without a difference between them each discordant pair goes either way with probability
    1/2, so the count is binomial: the p-value is twice the smaller tail, at most 1.

    References
    ----------
    .. [1] Q. McNemar, "Note on the sampling error of the difference between correlated
       proportions or percentages", Psychometrika 12, 1947, pp. 153-157.
    """
    if only_first < 0 or only_second < 0:
        raise ValueError(f"counts of pairs cannot be negative, got {only_first}, {only_second}")
    n = only_first + only_second
    if n == 0:
        return 1.0
    tail = sum(math.comb(n, k) for k in range(min(only_first, only_second) + 1))
    return min(1.0, 2.0 * tail / 2 ** n)
