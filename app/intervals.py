"""The 95 % confidence interval of a time mean from batch means, the one rule of the scenes' statistics and the
benches: a chaotic or wandering run's consecutive samples are correlated, the means of windows long against
that correlation are not, so the mean's interval is Student's t over the batch means."""

from __future__ import annotations

import numpy as np


def half_width_95(batch_means) -> float:
    """Half-width of the 95 % t-interval of the mean of ``batch_means`` (B >= 2 of them): t_{0.975, B-1} s / sqrt(B),
    s their sample standard deviation."""
    from scipy import stats as sps

    n = len(batch_means)
    return float(sps.t.ppf(0.975, n - 1)) * float(np.std(batch_means, ddof=1)) / np.sqrt(n)
