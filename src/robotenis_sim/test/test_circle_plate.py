"""The ISO 9283 plate rendered by the simulator, its circle measured by robotenis_vision.circle."""
import numpy as np
import pytest

from robotenis_sim import camera_model
from robotenis_vision import camera, circle

DIAMETER = 0.04


def plate(c):
    """Build a circle at c (optical frame), its plate neighbours 100 mm away, facing the camera."""
    centres = np.array([c, c + [0.1, 0, 0], c - [0.1, 0, 0], c + [0, 0.1, 0]])
    return centres, np.tile([0.0, 0.0, -1.0], (4, 1)), np.full(4, DIAMETER / 2)


@pytest.mark.parametrize('c', [[0.0, 0.0, 0.2], [0.0012, -0.0007, 0.25]])
def test_centre_is_measured_to_the_renderers_resolution(c):
    """
    Check that the centre is measured to the renderer's resolution.

    A circle centred to a few pixels, as the ISO servoing leaves it. Lateral error of the mean of
    10 frames: the noise's standard error (from the frames' spread) plus the renderer's resolution
    (rim pixels supersampled: a centroid good to 0.01 px). Off centre, the lateral position also
    carries x/z times the depth error.
    """
    cam, rng = camera.default(), np.random.default_rng(3)
    c = np.array(c)
    m = np.array([circle.measure_circle(camera_model.render_circles(cam, *plate(c), rng), cam,
                                        DIAMETER)
                  for _ in range(10)])
    pixel = c[2] / cam.K[0, 0]
    standard_error = m[:, :2].std(axis=0, ddof=1) / np.sqrt(len(m))
    assert np.all(np.abs(m[:, :2].mean(axis=0) - c[:2]) < 4 * standard_error + 0.01 * pixel)
    # depth from the apparent size: the coverage of the blurred rim is good to a few tenths of a
    # per cent
    assert abs(m[:, 2].mean() / c[2] - 1) < 5e-3


def test_an_image_without_a_whole_circle_is_refused():
    cam, rng = camera.default(), np.random.default_rng(0)
    far_off = camera_model.render_circles(cam, *plate(np.array([0.3, 0.0, 0.2])), rng)
    with pytest.raises(circle.CircleError):
        circle.measure_circle(np.full((480, 640), 200, np.uint8), cam, DIAMETER)
    with pytest.raises(circle.CircleError):
        circle.measure_circle(far_off[:, :100], cam, DIAMETER)
