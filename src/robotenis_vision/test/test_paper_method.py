"""The paper's tangent planes (eqs. 12, 16) and ellipse correction (17-22) on exact outlines."""
import numpy as np
import pytest

from robotenis_vision import paper_method
from robotenis_vision.paper_method import PaperMethodError
from test_conic import outline_xy

R = 0.019                       # m: the paper's ball radius R_B


def error(c, iterations):
    xy = outline_xy(c, R, 720)
    centre, cross = paper_method.chords(xy)
    return np.linalg.norm(paper_method.centre_from_chords(centre, cross, R, iterations) - c)


def test_on_the_axis_the_tangent_planes_are_exact():
    c = np.array([0.0, 0.0, 0.2])
    assert error(c, 0) < 1e-9 and error(c, 2) < 1e-9


@pytest.mark.parametrize('c', [[0.05, 0.03, 0.2], [0.1, -0.06, 0.3], [-0.12, 0.09, 0.25],
                               [0.15, 0.08, 0.45]])
def test_the_ellipse_correction_removes_most_of_the_chord_error(c):
    """
    Off both axes the chords through the centre are not the tangent points: eqs. 17-22 fix that.

    The correction is first order: what it leaves grows as (R/d)^2, 9 % of the chord error for the
    paper's ball at 200 mm and 60 mm off the axis (R/d = 0.09), 0.1-2 % farther away. (The paper:
    a second iteration brings no appreciable improvement.)
    """
    c = np.array(c)
    raw, once, twice = error(c, 0), error(c, 1), error(c, 2)
    assert once < 0.1 * raw
    assert abs(twice - once) < 0.1 * once + 1e-9


def test_covariance_propagates_the_crossing_noise():
    c = np.array([0.05, 0.03, 0.2])
    _, cross = paper_method.chords(outline_xy(c, R, 720))
    _, cov = paper_method.paper_centre(cross, R, np.full(4, 0.1 / 500))
    assert np.all(np.linalg.eigvalsh(cov) > 0)
    _, cov2 = paper_method.paper_centre(cross, R, np.full(4, 0.2 / 500))
    np.testing.assert_allclose(cov2, 4 * cov, rtol=1e-6)


def test_points_that_do_not_surround_their_centre_are_refused():
    flat = np.column_stack([np.linspace(0.0, 0.1, 50), np.zeros(50)])     # a line, not an outline
    with pytest.raises(PaperMethodError, match='twice'):
        paper_method.chords(flat)


def test_a_gap_at_a_crossing_is_refused():
    """Profiles dropped where the horizontal line meets the outline: no crossing to measure."""
    c = np.array([0.05, 0.03, 0.2])
    xy = outline_xy(c, R, 720)
    centre = c[:2] / c[2]
    angle = np.arctan2(xy[:, 1] - centre[1], xy[:, 0] - centre[0])
    with pytest.raises(PaperMethodError, match='gap'):
        paper_method.chords(xy[np.abs(angle) > 0.2])  # 23 degrees missing around the right end
