"""Mann-Whitney U and Holm against scipy; summary statistics; Fig. 9 p_c values."""

import numpy as np
import pytest
from scipy import stats as sst

from designopt.numerics import statistics


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_mann_whitney_matches_scipy_asymptotic(seed):
    rng = np.random.default_rng(seed)
    x = rng.normal(0, 1, 60)
    y = rng.normal(0.4, 1.3, 45)
    if seed == 2:  # heavy ties and an infinite value
        x, y = np.round(x, 1), np.round(y, 1)
        x[0] = np.inf
    u, p = statistics.mann_whitney_u(x, y)
    ref = sst.mannwhitneyu(x, y, method="asymptotic", use_continuity=True)
    assert u == pytest.approx(ref.statistic, abs=1e-9)
    assert p == pytest.approx(ref.pvalue, rel=1e-9)


def test_mann_whitney_identical_samples():
    assert statistics.mann_whitney_u(np.ones(5), np.ones(7))[1] == 1.0


def test_holm_matches_hand_computation():
    p = np.array([0.01, 0.04, 0.03, 0.005])
    # sorted 0.005, 0.01, 0.03, 0.04 → ×4, ×3, ×2, ×1 → 0.02, 0.03, 0.06, 0.06 (monotone)
    np.testing.assert_allclose(statistics.holm(p), [0.03, 0.06, 0.06, 0.02])
    assert statistics.holm(np.array([0.6, 0.9]))[1] == 1.0


def test_summary():
    s = statistics.summary(np.array([1.0, 2.0, 3.0, 10.0]), np.array([5, 7, 9, 11]), threshold=2.5)
    assert s["mean"] == 4.0 and s["median"] == 2.5 and s["best"] == 1.0
    assert s["std"] == pytest.approx(np.std([1, 2, 3, 10], ddof=1))
    assert s["conv_mean"] == 8.0 and s["success"] == 0.5
