"""ISO 9283 (1998) static performance criteria, exactly as in the calibration paper's appendix."""
import numpy as np


def repeatability(points):
    """
    Compute the position repeatability RP = l_bar + 3 S of one commanded position.

    points : the n reached positions (n, 3) of that commanded position.

    l_j is the distance of visit j from the barycentre, l_bar their mean and
    S = sqrt(sum (l_j - l_bar)^2 / (n - 1)).
    """
    points = np.asarray(points, dtype=float)
    if points.ndim != 2 or points.shape[1] != 3 or len(points) < 2:
        raise ValueError('repeatability needs at least two 3D positions, '
                         f'got shape {points.shape}')
    l_j = np.linalg.norm(points - points.mean(axis=0), axis=1)
    return float(l_j.mean() + 3 * np.std(l_j, ddof=1))


def distance_accuracy(reached_1, reached_2, commanded_1, commanded_2):
    """
    Compute the positioning distance accuracy AD = |D_bar - D_c|.

    reached_1, reached_2 : (n, 3) positions reached at the j-th repetition for the two commanded
    positions; D_j = |P_1j - P_2j|, D_bar their mean, D_c = |P_c1 - P_c2|.
    """
    reached_1, reached_2 = np.asarray(reached_1, dtype=float), np.asarray(reached_2, dtype=float)
    if reached_1.shape != reached_2.shape or reached_1.ndim != 2 or reached_1.shape[1] != 3:
        raise ValueError('reached positions must both be (n, 3), '
                         f'got {reached_1.shape} and {reached_2.shape}')
    D_bar = np.linalg.norm(reached_1 - reached_2, axis=1).mean()
    P_c1, P_c2 = np.asarray(commanded_1, dtype=float), np.asarray(commanded_2, dtype=float)
    D_c = np.linalg.norm(P_c1 - P_c2)
    return float(abs(D_bar - D_c))
