"""Averaging one rest: the outlier gate rejects good samples at its level, and rejects outliers."""
import numpy as np
from robotenis_calibration import rests
from scipy import stats


def test_the_gate_rejects_good_samples_with_its_probability_whatever_their_number():
    rng = np.random.default_rng(4)
    alpha, rests_per_size = 1e-3, 2000
    for n in (12, 25, 60):
        cov = np.array([[4.0, 1.0, 0.0], [1.0, 2.0, 0.5], [0.0, 0.5, 1.0]])
        rejected = sum(int((~rests.robust_mean(rng.multivariate_normal(np.zeros(3), cov, n),
                                               np.full(3, 1e-12), alpha)[2]).sum())
                       for _ in range(rests_per_size))
        total = n * rests_per_size
        low, high = stats.binom.ppf([0.0005, 0.9995], total, alpha)
        assert low <= rejected <= high, (n, rejected, total * alpha)


def test_false_detections_are_rejected_and_the_mean_is_the_good_samples():
    rng = np.random.default_rng(5)
    x = rng.normal(size=(40, 3))
    x[[3, 17, 30]] += [8.0, -6.0, 5.0]
    mean, cov, keep = rests.robust_mean(x, np.full(3, 1e-12), 1e-3)
    assert not keep[[3, 17, 30]].any() and keep.sum() >= 36
    np.testing.assert_allclose(mean, x[keep].mean(axis=0))
