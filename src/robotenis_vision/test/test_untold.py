"""
A ball whose outline shows no edge: kept in a plain image, refused in a textured one.

detector._told decides from the image alone whether a found ball that round_arc cannot tell
(no profile finds an edge along its outline) could be one of the background's blobs: it can when
the image has edges of its own beyond the ball (search.steep at detector.TEXTURED). Images of an
independent OpenCV renderer (simple_render) and hand-made backgrounds: a checkerboard and a
random texture have such edges, a flat one does not; and the committed Mitsuba 3 set
(test_mitsuba_set): its checkered and random-texture backgrounds have them.
"""
import cv2
import numpy as np
import pytest
from robotenis_vision import camera, detector
from robotenis_vision.detection import Detection
from robotenis_vision.detector import DetectionError
import simple_render
import test_mitsuba_set as mitsuba_set

R = 0.019
CAM = camera.default()
C = np.array([0.04, -0.03, 0.3])


def texture(rng):
    """Return a random texture of 5 px blobs, 60 to 180 grey levels (float)."""
    smooth = cv2.GaussianBlur(rng.standard_normal((CAM.height, CAM.width)), (0, 0), 5.0)
    return np.clip(120.0 + 30.0 * smooth / smooth.std(), 0, 255)


def test_a_ball_without_an_edge_on_a_plain_background_is_kept():
    rng = np.random.default_rng(5)
    image = simple_render.render(CAM, C, R, rng, noise_sigma=2.0)
    det = detector.detect(image, CAM, R, 'conic')
    balls, shares = detector._told(detector.check_image(image, CAM), CAM, R, [(det, C)], [None])
    assert len(balls) == 1 and shares == [None]


def test_a_ball_without_an_edge_on_the_mitsuba_sets_textured_backgrounds_is_refused():
    """
    Each of the six textured images (checkered, random texture) has edges of its own.

    The plain ones need not be plain to this rule: a ball's shadow on its background is an edge
    (2 of them), and so is a path tracer's noise in a bright patch of light (1): a ball there that
    the profiles cannot tell is refused. test_mitsuba_set measures every ball of the set.
    """
    textured = [e for e in mitsuba_set.index() if e['background'] in ('checker', 'noise')]
    assert len(textured) == 6
    for entry in textured:
        truth, cam, frames = mitsuba_set.load(entry)
        c = np.array(truth['ball']['center_m'])
        ball = Detection(c, np.eye(3) * 1e-8, np.zeros((0, 2)), 0.0, 'model', {})
        with pytest.raises(DetectionError, match='not told from a ball'):
            detector._told(detector.check_image(frames[0], cam), cam, R, [(ball, c)], [None])


@pytest.mark.parametrize('background', ['checkerboard', 'texture'])
def test_a_ball_without_an_edge_on_a_textured_background_is_refused(background):
    rng = np.random.default_rng(6)
    board = (simple_render.checkerboard(CAM, 23) if background == 'checkerboard'
             else texture(rng))
    image = simple_render.on_background(CAM, C, R, board, rng, ball=230.0)
    img = detector.check_image(image, CAM)
    det = detector.detect(image, CAM, R, 'conic')
    assert np.linalg.norm(det.position - C) < 0.1 * R          # the ball is there, and found
    with pytest.raises(DetectionError, match='not told from a ball'):
        detector._told(img, CAM, R, [(det, C)], [None])
    balls, _ = detector._told(img, CAM, R, [(det, C)], [0.5])   # an edge seen: kept
    assert len(balls) == 1
