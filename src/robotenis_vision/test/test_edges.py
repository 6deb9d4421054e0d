"""The limb profile model on straight edges with known position, blur and shading."""
import warnings

import cv2
import numpy as np
import pytest

from robotenis_vision import edges

FINE = 32           # straight edges are drawn 32x finer, blurred there and box-averaged to pixels


def edge_image(x0, sigma_px, inside, outside, size=(40, 40)):
    """
    Render a vertical edge at x = x0 (pixel centres at integers).

    x < x0 is the ball, inside(x) its shading, outside(x) the background; Gaussian blur sigma_px,
    then pixel integration (exact box filter).
    """
    w, h = size
    xf = (np.arange(w * FINE) + 0.5) / FINE - 0.5
    row = np.where(xf < x0, inside(xf), outside(xf))
    fine = np.tile(row, (4, 1)).astype(np.float64)
    fine = cv2.GaussianBlur(fine, (0, 0), sigmaX=sigma_px * FINE, sigmaY=0.1,
                            borderType=cv2.BORDER_REPLICATE)
    row = fine[0].reshape(w, FINE).mean(axis=1)
    return np.tile(row, (h, 1)).astype(np.float32)


CASES = [
    # bright ball darkening inward, background gradient
    (lambda x: 200 - 2.0 * x, lambda x: 90 + 0.8 * x),
    # dark side of the ball against a brighter background
    (lambda x: 30 + 0.0 * x, lambda x: 120 - 1.5 * x),
    # weak contrast, steep shading
    (lambda x: 140 + 3.0 * x, lambda x: 100 + 0.0 * x),
]


@pytest.mark.parametrize('inside, outside', CASES)
@pytest.mark.parametrize('x0', [19.5, 20.13, 20.71])
def test_straight_edge_found_to_a_fiftieth_of_a_pixel(inside, outside, x0):
    image = edge_image(x0, 0.9, inside, outside)
    points = np.column_stack([np.full(10, 20.0), np.arange(15.0, 25.0)])
    normals = np.tile([1.0, 0.0], (10, 1))       # outward: from the ball to the background
    fit, sigma = edges.profile_edges(image, points, normals, np.zeros(10), 4.5, 1.0,
                                     refit_blur=True)
    assert np.all(fit.ok)
    # Resolution: 1/50 px, the accuracy asked of an outline point (the renderers are exact to
    # 1/500).
    np.testing.assert_allclose(points[:, 0] + fit.e, x0, atol=0.02)


def test_blur_is_estimated():
    """Gaussian blur 1.2 px on pixels (box of variance 1/12), bilinear sampling: about 1.25 px."""
    image = edge_image(20.3, 1.2, CASES[0][0], CASES[0][1])
    points = np.column_stack([np.full(10, 20.3), np.arange(15.0, 25.0)])
    s = np.arange(-4.0, 4.25, edges.STEP)
    P, inside = edges.sample_profiles(image, points, np.tile([1.0, 0.0], (10, 1)), s)
    sigma = edges.estimate_blur(P[inside], s)
    expected = np.sqrt(1.2 ** 2 + 1 / 12)
    assert abs(sigma - expected) < 0.1 * expected


def test_profiles_outside_the_image_keep_the_blur_guess():
    """A predicted outline wholly off the image: nothing measured, no blur made up, no warning."""
    image = edge_image(20.0, 1.0, CASES[0][0], CASES[0][1])
    points = np.column_stack([np.full(4, -30.0), np.arange(18.0, 22.0)])
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        fit, sigma = edges.profile_edges(image, points, np.tile([1.0, 0.0], (4, 1)), np.zeros(4),
                                         4.0, 1.3, refit_blur=True)
    assert sigma == 1.3 and not np.any(fit.ok)
    with pytest.raises(ValueError, match='no profile'):
        edges.estimate_blur(np.empty((0, 33)), np.arange(33.0))


def test_curvature_correction_moves_the_edge_outward():
    image = edge_image(20.0, 1.0, CASES[0][0], CASES[0][1])
    points = np.column_stack([np.full(4, 20.0), np.arange(18.0, 22.0)])
    normals = np.tile([1.0, 0.0], (4, 1))
    straight, _ = edges.profile_edges(image, points, normals, np.zeros(4), 4.0, 1.0)
    curved, _ = edges.profile_edges(image, points, normals, np.full(4, 0.1), 4.0, 1.0)
    np.testing.assert_allclose(curved.e - straight.e, 0.5 * 1.0 ** 2 * 0.1)


def test_saturated_profiles_are_dropped():
    image = edge_image(20.0, 0.9, lambda x: 255.0 + 0 * x, lambda x: 90.0 + 0 * x)
    points = np.column_stack([np.full(4, 20.0), np.arange(18.0, 22.0)])
    fit, _ = edges.profile_edges(image, points, np.tile([1.0, 0.0], (4, 1)), np.zeros(4), 4.0, 1.0)
    assert not np.any(fit.ok)


def test_rough_circle_finds_a_disc_and_refuses_a_blank_image():
    image = np.full((480, 640), 100, np.float32)
    cv2.circle(image, (400, 150), 20, 220, -1)
    image = cv2.GaussianBlur(image, (0, 0), 1.0)
    centre, radius = edges.rough_circle(image, 5, 60)
    # a few pixels (4x shrunk image)
    assert np.linalg.norm(centre - [400, 150]) < 4 and abs(radius - 20) < 4
    with pytest.raises(edges.EdgeError, match='no strong edge'):
        edges.rough_circle(np.full((480, 640), 100, np.float32), 5, 60)
