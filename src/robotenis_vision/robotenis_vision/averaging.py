"""
Averaging N detections of one pose (the paper used 500 frames), with outlier rejection.

Frames are rejected by their Mahalanobis distance to the robust centre under the robust scatter of
the frames themselves: d^2 > chi^2_3(0.999) = 16.27 (a frame with a glint on the outline, a
vibration). The average's covariance is the scatter of the kept frames divided by their number;
when fewer than ``MIN_FOR_SCATTER`` frames are kept, the mean of their own (predicted) covariances
divided by the number is used instead, since a scatter from a handful of frames is unreliable.
"""
from dataclasses import dataclass

import numpy as np
from scipy.special import chdtri

GATE = float(chdtri(3, 0.001))     # chi2(3) quantile 0.999 (scipy.stats: 1 s to import)
MIN_FOR_SCATTER = 10


@dataclass
class Averaged:
    position: np.ndarray      # (3,), optical frame, m
    covariance: np.ndarray    # (3, 3) of the average, m^2
    frames: int               # frames kept
    rejected: np.ndarray      # (N,) bool: frames left out
    scatter: np.ndarray       # (3, 3) per-frame covariance of the kept frames, m^2


def _robust_scatter(P, centre):
    """Per-axis MAD scale with the frames' correlation: a covariance outliers do not inflate."""
    mad = 1.4826 * np.median(np.abs(P - centre), axis=0)
    corr = np.corrcoef(P.T) if len(P) > 3 else np.eye(3)
    corr = np.nan_to_num(corr, nan=0.0) + 1e-9 * np.eye(3)
    return corr * np.outer(mad, mad) + 1e-30 * np.eye(3)


def average(positions, covariances=None, gate=GATE):
    """
    Average positions (N, 3).

    ``covariances`` (N, 3, 3) are each frame's predicted covariance (optional).
    """
    P = np.asarray(positions, dtype=float)
    if P.ndim != 2 or P.shape[1] != 3 or len(P) == 0:
        raise ValueError(f'positions: expected an (N, 3) array with N >= 1, got shape {P.shape}')
    if not np.all(np.isfinite(P)):
        raise ValueError('positions: not all finite')
    keep = np.ones(len(P), dtype=bool)
    if len(P) >= 4:
        centre = np.median(P, axis=0)
        S = _robust_scatter(P, centre)
        for _ in range(3):
            d = P - centre
            m2 = np.einsum('ni,ij,nj->n', d, np.linalg.inv(S), d)
            keep = m2 <= gate
            centre = P[keep].mean(axis=0)
            S = np.cov(P[keep].T) if keep.sum() > 3 else S
    kept = P[keep]
    n = len(kept)
    mean = kept.mean(axis=0)
    scatter = np.cov(kept.T) if n > 1 else np.zeros((3, 3))
    if n >= MIN_FOR_SCATTER or covariances is None:
        cov = scatter / n
    else:
        cov = np.mean(np.asarray(covariances, dtype=float)[keep], axis=0) / n
    return Averaged(mean, cov, n, ~keep, scatter)
