"""Averaging frames of one pose: outliers out, the mean's covariance honest (chi-square)."""
import numpy as np
import pytest
from robotenis_vision import averaging
from scipy.stats import chi2

TRUE = np.array([0.01, -0.02, 0.2])
COV = np.array([[4e-10, 1e-10, 0.0], [1e-10, 9e-10, 0.0], [0.0, 0.0, 8e-9]])


def test_outliers_are_rejected_and_the_mean_is_consistent():
    rng = np.random.default_rng(2)
    runs, frames = 200, 100
    total = 0.0
    for _ in range(runs):
        P = rng.multivariate_normal(TRUE, COV, size=frames)
        P[:4] += [0.0, 0.0, 0.002]                  # glints: 2 mm off in depth, 20 sigma
        avg = averaging.average(P)
        assert np.all(avg.rejected[:4])
        e = avg.position - TRUE
        total += e @ np.linalg.solve(avg.covariance, e)
    # the covariance is estimated from ~96 frames: allow for that with a slightly wider band
    assert chi2.ppf(0.0005, 3 * runs) * 0.95 < total < chi2.ppf(0.9995, 3 * runs) * 1.05


def test_few_frames_use_their_predicted_covariance():
    P = np.array([TRUE, TRUE + 1e-5, TRUE - 1e-5])
    avg = averaging.average(P, [COV] * 3)
    np.testing.assert_allclose(avg.covariance, COV / 3)
    assert avg.frames == 3


def test_bad_input():
    with pytest.raises(ValueError, match=r'\(N, 3\)'):
        averaging.average(np.zeros((5, 2)))
    with pytest.raises(ValueError, match='finite'):
        averaging.average(np.array([[0.0, 0.0, np.nan]]))
