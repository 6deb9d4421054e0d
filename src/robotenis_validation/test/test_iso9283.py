import numpy as np
import pytest

from robotenis_validation import iso9283


def test_repeatability_by_hand():
    # Barycentre (0, 0, 0); distances l = 1, 1, 2, 2 -> l_bar = 1.5,
    # S = sqrt((0.25 * 4) / 3) = sqrt(1/3); RP = 1.5 + 3 sqrt(1/3) = 1.5 + sqrt(3).
    points = [[1, 0, 0], [-1, 0, 0], [0, 2, 0], [0, -2, 0]]
    assert iso9283.repeatability(points) == pytest.approx(1.5 + np.sqrt(3), abs=1e-12)


def test_repeatability_of_identical_visits_is_zero():
    assert iso9283.repeatability(np.ones((5, 3))) == 0.0


def test_distance_accuracy_by_hand():
    # Commanded 100 apart along x; reached distances 100.2 and 99.6 -> D_bar = 99.9, AD = 0.1.
    reached_1 = [[0, 0, 0], [0, 0, 0]]
    reached_2 = [[100.2, 0, 0], [0, 99.6, 0]]
    AD = iso9283.distance_accuracy(reached_1, reached_2, [0, 0, 0], [100, 0, 0])
    assert AD == pytest.approx(0.1, abs=1e-12)


def test_bad_shapes_are_refused():
    with pytest.raises(ValueError, match='at least two'):
        iso9283.repeatability([[0, 0, 0]])
    with pytest.raises(ValueError, match=r'\(n, 3\)'):
        iso9283.distance_accuracy(np.zeros((2, 3)), np.zeros((3, 3)), [0, 0, 0], [1, 0, 0])
