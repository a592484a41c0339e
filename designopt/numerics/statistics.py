"""Summary statistics and rank tests for comparing optimizer runs (numpy only).

Mann-Whitney U uses the normal approximation with tie correction and continuity
correction (what scipy.stats.mannwhitneyu does with ``method="asymptotic"``; the tests
check against it); Holm's step-down procedure corrects a family of p-values.
"""

from __future__ import annotations

import math

import numpy as np


def rankdata(x: np.ndarray) -> np.ndarray:
    """Average ranks (1-based), ties sharing the mean of their ranks."""
    _, inv, counts = np.unique(np.asarray(x), return_inverse=True, return_counts=True)
    ends = np.cumsum(counts)
    return (0.5 * (ends - counts + 1 + ends))[inv.ravel()].astype(np.float64)


def mann_whitney_u(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Two-sided Mann-Whitney U test: (U of x, p-value). Infinite values rank last."""
    x, y = np.asarray(x, np.float64).ravel(), np.asarray(y, np.float64).ravel()
    n1, n2 = len(x), len(y)
    if n1 == 0 or n2 == 0:
        raise ValueError("both samples must be non-empty")
    both = np.concatenate([x, y])
    both = np.where(np.isnan(both), np.inf, both)
    r = rankdata(both)
    u1 = r[:n1].sum() - n1 * (n1 + 1) / 2.0
    n = n1 + n2
    _, counts = np.unique(both, return_counts=True)
    tie = (counts**3 - counts).sum() / (n * (n - 1)) if n > 1 else 0.0
    sigma = math.sqrt(n1 * n2 / 12.0 * ((n + 1) - tie))
    if sigma == 0.0:
        return float(u1), 1.0
    mu = n1 * n2 / 2.0
    z = (abs(u1 - mu) - 0.5) / sigma
    p = math.erfc(max(z, 0.0) / math.sqrt(2.0))
    return float(u1), float(min(p, 1.0))


def holm(pvalues: np.ndarray) -> np.ndarray:
    """Holm-Bonferroni adjusted p-values (step-down, monotone, capped at 1)."""
    p = np.asarray(pvalues, np.float64)
    m = len(p)
    order = np.argsort(p)
    adj = np.empty(m)
    adj[order] = np.minimum(np.maximum.accumulate((m - np.arange(m)) * p[order]), 1.0)
    return adj


def summary(final: np.ndarray, conv: np.ndarray, threshold: float) -> dict[str, float]:
    """Mean, std (ddof=1), median, best of final values; convergence-iteration mean/std;
    success rate = fraction of runs with final value ≤ threshold."""
    f = np.asarray(final, np.float64)
    c = np.asarray(conv, np.float64)
    return {
        "mean": float(f.mean()),
        "std": float(f.std(ddof=1)) if f.size > 1 else 0.0,
        "median": float(np.median(f)),
        "best": float(f.min()),
        "conv_mean": float(c.mean()),
        "conv_std": float(c.std(ddof=1)) if c.size > 1 else 0.0,
        "success": float(np.mean(f <= threshold)),
    }
