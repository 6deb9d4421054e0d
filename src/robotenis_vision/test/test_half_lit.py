"""
A ball lit from the side whose shadowed half is as dark as its background.

Rendered by robotenis_sim's camera model (Lambertian shading, a defocused background, 2.2 grey
levels of noise): the detector's own test renderer (simple_render, shading drawn by hand) gave
no such frame in 40, as its terminator leaves the ball's lit half enough rays.
"""
import numpy as np
import pytest
from robotenis_sim import camera_model as cm
from robotenis_vision import camera, detector

R = 0.019
CAM = camera.default()


def frames(c, light, ambient, background, n, seed):
    """Yield n renders of a ball at c (m) lit along ``light``; its shadow near the background."""
    rng = np.random.default_rng(seed)
    d = np.asarray(light, dtype=float) / np.linalg.norm(light)
    kw = {'lighting': cm.Lighting(direction=tuple(d), ambient=ambient, diffuse=150.0,
                                  specular=0.0),
          'background': cm.Background(low=background, high=background, defocus_px=3.0),
          'blur_sigma': 0.0, 'defocus_px': 1.3, 'noise_sigma': 2.2}
    for _ in range(n):
        yield cm.render(CAM, c, R, rng, **kw)


@pytest.mark.parametrize('c, light, ambient, background', [
    ((0.0, 0.0, 0.17), (0.12, -0.99, -0.06), 36.0, 40.0),
    ((-0.02, 0.01, 0.2), (-0.97, 0.1, -0.1), 30.0, 33.0)])
def test_a_mark_on_a_half_lit_ball_is_not_measured_as_a_ball(c, light, ambient, background):
    """
    No frame's answer is a mark on the ball: a sphere seen within its disc, far behind it.

    Only the lit half of the outline answers the search's rays (0.47-0.49 of them, under the
    0.5 a sphere needs), while the corners where the terminator meets the limb do answer as
    small spheres: measured, they read 0.4-0.5 m behind the ball (2 of these 48 frames before
    detector.HALF_LIT_SCORE). The ball itself may be measured or refused, never its mark.
    """
    c = np.asarray(c)
    for image in frames(c, light, ambient, background, 24, 0):
        try:
            position = detector.detect(image, CAM, R).position
        except detector.DetectionError:
            continue
        assert not detector._on_ball(CAM, position, c, R), position
