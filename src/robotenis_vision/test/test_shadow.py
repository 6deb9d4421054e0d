"""
A ball beside its own shadow: a dark disc of its size on a close background, partly behind it.

Mitsuba 3 casts that shadow (the project's renderer does not): in a scene of a list kept out of
the benchmark (seed 37, scene 081: a point light beside the camera, the background 6 cm behind
the ball) the shadow's outline, continued by the ball's edge where the two meet, showed more of
its edge than the ball's faint side did, and the detector measured the shadow: 5.8 % of the
range too near. Here the shadow is drawn into the background of the tests' own renderer
(simple_render), which shares nothing with the detector.
"""
import numpy as np
from robotenis_vision import camera, detector
import simple_render

R = 0.019
CAM = camera.default()


def ball_and_shadow(c, shift, rng, slope=0.7):
    """
    Return a frame of a uniform ball at c (m) over its shadow, a disc moved by ``shift`` (m).

    The ball is 120 grey levels, the shadow 45, the background 100 behind the ball's centre and
    ``slope`` grey levels brighter per px to the right: the ball's right side fades into it.
    """
    cover = simple_render.render(CAM, np.asarray(c) + shift, R, ball=1.0, background=0.0,
                                 blur_sigma=1.0).astype(float)
    u = np.arange(CAM.width)[None, :] - CAM.project(c)[0]
    background = np.full((CAM.height, CAM.width), 100.0) + slope * u
    behind = background + (45.0 - background) * cover
    return simple_render.on_background(CAM, c, R, behind, rng, ball=120.0, blur_sigma=1.0,
                                       noise_sigma=2.0)


C, SHIFT = np.array([0.03, -0.02, 0.3]), np.array([-0.015, 0.02, 0.02])


def test_the_ball_is_measured_not_its_shadow():
    """
    Every frame's answer is the ball: its centre's ray meets the ball, not the shadow's disc.

    The shadow's edge is strong all round, continued by the ball's where it runs behind it; the
    ball's fades on its right. Without detector._in_front, 4 of these 6 frames measured the
    shadow; with it, none.
    """
    rng = np.random.default_rng(5)
    for _ in range(6):
        det = detector.detect(ball_and_shadow(C, SHIFT, rng), CAM, R)
        u = det.position / np.linalg.norm(det.position)
        assert np.linalg.norm(np.cross(u, C)) < R, det.position


def test_hidden_outline():
    """The disc behind shows no edge where the other crosses it; the one in front does."""
    img = detector.check_image(ball_and_shadow(C, SHIFT, np.random.default_rng(1)), CAM)
    seen = {k: detector._edge_seen(img, CAM, R, c)
            for k, c in (('ball', C), ('shadow', C + SHIFT))}
    assert detector._hidden(CAM, R, C + SHIFT, seen['shadow'], C, seen['ball'])
    assert not detector._hidden(CAM, R, C, seen['ball'], C + SHIFT, seen['shadow'])
