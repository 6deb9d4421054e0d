"""
The search's candidate sources (robotenis_vision.search) on images of the independent renderer.

simple_render's uniform ball (no shading) over backgrounds drawn here: a checkerboard, a disc and
a square of the same contrast, soft and sharp edges. Each test states the property a source is
built on; the benchmark (benchmarks/vision.py) measures what they give on rendered scenes.
"""
import cv2
import numpy as np
import pytest
from robotenis_vision import camera, detector, model_fit, search
from robotenis_vision.detection import DetectionError
import simple_render

R = 0.019
CAM = camera.default()
C = np.array([0.08, -0.03, 0.3])          # the ball: about 32 px of radius


def blob(shape, centre, radius, square=False, level=200.0, ground=60.0, blur=0.8):
    """Return a float image of a disc (or a square of half-side ``radius``), blurred."""
    v, u = np.mgrid[0:shape[0], 0:shape[1]].astype(float)
    du, dv = u - centre[0], v - centre[1]
    inside = np.maximum(abs(du), abs(dv)) < radius if square else np.hypot(du, dv) < radius
    return cv2.GaussianBlur(np.where(inside, level, ground), (0, 0), blur)


def test_thinned_edges_are_one_pixel_across():
    image = cv2.GaussianBlur(np.where(np.arange(64) < 30, 50.0, 200.0)[None, :].repeat(40, 0)
                             .astype(np.float32), (0, 0), 2.0)
    gx = cv2.Sobel(image, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(image, cv2.CV_32F, 0, 1, ksize=3)
    mag = cv2.magnitude(gx, gy)
    thin = search._thin(gx, gy, mag) & (mag > 0.1 * mag.max())
    assert np.all(thin[5:-5].sum(axis=1) == 1)          # rows away from the image's own border
    assert np.all(np.abs(np.flatnonzero(thin[20]) - 29.5) <= 0.5)


def test_the_open_disc_of_a_ball_among_fine_squares_comes_first():
    """A ball over 12 px squares (its edge changing sign at each) is the largest open disc."""
    rng = np.random.default_rng(1)
    image = simple_render.on_background(CAM, C, R, simple_render.checkerboard(CAM, 12), rng)
    first = search.open_discs(image.astype(np.float32), 8.0, 150.0)[0]
    r = CAM.apparent_radius(C, R)
    assert np.linalg.norm(first.centre - CAM.project(C)) < 3.0
    assert 0.8 * r < first.radius < 1.05 * r


def test_the_outline_score_prefers_a_sharp_round_outline():
    """A sharp disc outscores the same disc blurred like a texture, and a square of its size."""
    shape, centre, radius = (200, 200), np.array([100.0, 100.0]), 40.0
    sharp, soft, square = (search.outline_score(*search.gradients(image.astype(np.float32)),
                                                centre, radius)
                           for image in (blob(shape, centre, radius),
                                         blob(shape, centre, radius, blur=4.0),
                                         blob(shape, centre, radius, square=True)))
    assert sharp > 2 * soft and sharp > 1.5 * square


def fit_at(image, c):
    """Return the model fit from sphere c, as detector.measure makes it from a search's start."""
    first = model_fit.fit(image, CAM, R, c, 1.5, iterations=4, limb=False)
    return model_fit.fit(image, CAM, R, first.c, first.blur)


def test_a_ball_whose_edge_flips_on_a_checkerboard_keeps_a_smooth_limb():
    """
    Tell a ball from a pattern by its limb, fitted from where each is.

    The ball (grey 130 between squares of 40 and 210) changes polarity at every square, but its
    limb varies little: not refused as a pattern. Its fit drops the squares' edges, over 40 % of
    the pixels' weight here, below MIN_KEPT; its limb is smooth (under SMOOTH_LIMB), so it is
    measured, and the search finds it rather than a square (it reads about 0.3 % of the range
    too near: the squares under its edge bias it). Circles about a corner of the squares, the
    pattern inside as outside, are refused as patterns.
    """
    rng = np.random.default_rng(2)
    image = simple_render.on_background(CAM, C, R, simple_render.checkerboard(CAM, 20), rng)
    ball = fit_at(image.astype(np.float32), C)
    assert ball.polarity_flips() > detector.MAX_FLIPS
    assert ball.limb_variation() < detector.SMOOTH_LIMB
    assert ball.kept < detector.MIN_KEPT
    measured = detector.measure(image.astype(np.float32), CAM, R, 'model', C, None)
    found = detector.detect(image, CAM, R)
    for det in (measured, found):
        ray = det.position / np.linalg.norm(det.position)
        assert np.linalg.norm(np.cross(ray, C)) < R / 10
    pattern = np.clip(np.rint(simple_render.checkerboard(CAM, 20)
                              + 2.0 * rng.standard_normal(image.shape)), 0, 255)
    for radius in (20.0, 40.0):
        # a circle about a corner of the squares, the pattern inside as outside
        ray = np.linalg.solve(CAM.K, [400.0, 200.0, 1.0])
        c = CAM.fx * R / radius * ray / np.linalg.norm(ray)
        false = fit_at(pattern.astype(np.float32), c)
        assert false.polarity_flips() > detector.MAX_FLIPS
        assert false.limb_variation() > detector.MAX_LIMB_VARIATION
        with pytest.raises(DetectionError, match='a pattern of the background'):
            detector.measure(pattern.astype(np.float32), CAM, R, 'model', c, None)


def test_a_candidate_within_a_bigger_ones_disc_is_left_out():
    """A spot on the ball (a highlight) is inside the ball's candidate; a neighbour is not."""
    ball = search.Candidate(np.array([100.0, 100.0]), 40.0, 1.0)
    spot = search.Candidate(np.array([120.0, 90.0]), 8.0, 1.0)
    beside = search.Candidate(np.array([150.0, 100.0]), 8.0, 1.0)
    assert detector._inside(spot, ball) and not detector._inside(ball, spot)
    assert not detector._inside(beside, ball)
    assert not detector._inside(search.Candidate(np.array([100.0, 100.0]), 30.0, 1.0), ball)


def test_a_square_meets_its_inscribed_circle_on_a_short_arc_and_a_ball_all_round():
    """
    round_arc: how much of a sphere's outline shows an edge on one ellipse.

    The sides of a 40 px square lie within a pixel of its inscribed circle (radius 20 px) where
    1 / cos(phi) - 1 < 1 / 20 about the four points they touch it: 8 acos(20 / 21) of its 2 pi
    (40 %), whatever the tolerance under a pixel. The ball shows its edge all round on a flat
    background (each profile within 3 of its standard errors: all but a few in a thousand), and
    over the checkerboard longer than any square's.
    """
    rng = np.random.default_rng(4)
    board = simple_render.checkerboard(CAM, 40)
    flat = simple_render.on_background(CAM, C, R, np.full(board.shape, 60.0), rng)
    ball = simple_render.on_background(CAM, C, R, board, rng)
    pattern = np.clip(np.rint(board + 2.0 * rng.standard_normal(board.shape)), 0, 255)
    ray = np.linalg.solve(CAM.K, [419.5, 219.5, 1.0])           # a square's centre
    square = CAM.fx * R / 20.0 * ray / np.linalg.norm(ray)
    circumference = 2 * np.pi * CAM.apparent_radius(C, R)
    assert detector.round_arc(flat.astype(np.float32), CAM, R, C) > 0.95 * circumference
    inscribed = detector.round_arc(pattern.astype(np.float32), CAM, R, square)
    assert inscribed < 8 * np.arccos(20 / 21) * 20.0
    assert detector.round_arc(ball.astype(np.float32), CAM, R, C) > 2 * inscribed


def test_a_squares_sides_do_not_turn_with_its_inscribed_circle():
    """
    Tell a ball's edge from a square's sides by how they turn along the outline (_turning).

    The ball drawn by the tests' own renderer turns with its outline all round; a square whose
    sides touch the same outline (its inscribed circle) does not, however sharp its edges.
    """
    rng = np.random.default_rng(5)
    c = np.array([0.0, 0.0, 0.3])
    disc = simple_render.render(CAM, c, R, rng, ball=170.0, background=60.0, noise_sigma=2.0)
    square = blob(disc.shape, CAM.project(c), CAM.apparent_radius(c, R), square=True,
                  level=170.0) + 2.0 * rng.standard_normal(disc.shape)
    assert detector._turning(disc.astype(np.float32), CAM, R, c) > 0.9
    assert detector._turning(square.astype(np.float32), CAM, R, c) < detector.MIN_TURNING


def test_a_weak_sphere_is_confirmed_again_from_where_it_lies():
    """
    A candidate a fifth of the radius off: its rays meet the outline aslant, under MIN_SCORE.

    A dark ball over 8 px squares. Confirmed again from the sphere they found, the rays agree on
    the ball over MIN_SCORE, and its outline lies within a pixel and a half of the truth's.
    """
    c = np.array([0.03, -0.02, 0.3])
    rng = np.random.default_rng(3)
    image = simple_render.on_background(CAM, c, R, simple_render.checkerboard(CAM, 8), rng,
                                        ball=60.0).astype(np.float32)
    r = CAM.apparent_radius(c, R)
    candidate = search.Candidate(CAM.project(c) + [0.2 * r, 0.0], 0.85 * r, 1.0)
    assert search.confirm(image, CAM, R, candidate).score < detector.MIN_SCORE
    sphere = detector._confirmed(image, CAM, R, candidate, detector.MIN_SCORE)
    assert sphere is not None
    assert max(model_fit.outline_offset(CAM, R, sphere.c, c)) < 1.5
