"""
A ball alone on a plain image, measured without the search (detector.lone_ball).

Images of an independent OpenCV renderer (simple_render). The shortcut is sound only if noise
alone never makes an edge (search.steep's threshold, LONE_CHAIN) while the weakest step a ray of
search.confirm takes does; both are checked at the bounds of what the threshold assumes. Where
both paths measure, they fit the same pixels from two starts: they must agree well within the
detection's own covariance (chi-square, 3 dof, 99.9 %).
"""
import cv2
import numpy as np
import pytest
from robotenis_vision import camera, detector, search
from robotenis_vision.detector import DetectionError
from scipy.stats import chi2
import simple_render

R = 0.019
CAM = camera.default()
POSITIONS = [np.array(c) for c in ([0.0, 0.0, 0.2], [0.1, -0.06, 0.3], [-0.12, 0.09, 0.25],
                                   [0.15, 0.08, 0.45])]


def no_search(*args):
    raise AssertionError('the whole image was searched')


def longest_chain(steep):
    """Return the most connected pixels (8-neighbours) of one chain in a steep map."""
    _, labels = cv2.connectedComponents(steep.astype(np.uint8), connectivity=8)
    return int(np.bincount(labels[steep], minlength=2)[1:].max())


@pytest.mark.parametrize('method', ['conic', 'model'])
def test_a_ball_alone_is_measured_without_the_search_as_the_search_measures_it(monkeypatch,
                                                                               method):
    rng = np.random.default_rng(11)
    for c in POSITIONS:
        image = simple_render.render(CAM, c, R, rng, noise_sigma=2.0)
        with monkeypatch.context() as m:
            m.setattr(detector, 'find', no_search)
            lone = detector.detect(image, CAM, R, method)
        with monkeypatch.context() as m:
            m.setattr(detector, 'lone_ball', lambda *args: None)
            searched = detector.detect(image, CAM, R, method)
        d = lone.position - searched.position
        assert d @ np.linalg.solve(searched.covariance, d) < chi2.ppf(0.999, 3), c


def test_an_edge_elsewhere_sends_the_image_to_the_search():
    """A bar far from the ball, and a second ball: the search runs, and refuses two balls."""
    rng = np.random.default_rng(12)
    c = POSITIONS[1]
    image = simple_render.render(CAM, c, R, rng, noise_sigma=2.0).astype(np.float32)
    assert detector.lone_ball(image, CAM, R, 'conic', 1.0) is not None
    barred = image.copy()
    barred[40:44, 60:200] += 30.0
    assert detector.lone_ball(barred, CAM, R, 'conic', 1.0) is None
    second = simple_render.on_background(CAM, np.array([-0.1, 0.05, 0.3]), R, image, rng,
                                         ball=200.0)
    assert detector.lone_ball(second.astype(np.float32), CAM, R, 'conic', 1.0) is None
    with pytest.raises(DetectionError, match='two balls'):
        detector.detect(second, CAM, R, 'conic')


@pytest.mark.parametrize('sigma', [0.5, 2.0, 6.0])
def test_noise_alone_makes_no_edge_and_the_weakest_step_a_ray_takes_does(sigma):
    """
    Noise: a flat image and a bright ramp whose noise grows with the signal (sigma at its median).

    Step: max(MIN_STEP, 6 sigma) grey levels blurred by 1.6 px, the least steep that
    search.confirm takes (SHARPNESS), along a circle of 12 px radius.
    """
    rng = np.random.default_rng(int(10 * sigma))
    h, w = CAM.height, CAM.width
    ramp = np.linspace(20.0, 235.0, w)[None, :] * np.ones((h, 1))
    shot = sigma * np.sqrt(ramp / np.median(ramp))
    for flat in (np.full((h, w), 100.0) + sigma * rng.standard_normal((h, w)),
                 ramp + shot * rng.standard_normal((h, w))):
        steep = search.steep(np.clip(flat, 0, 255).astype(np.float32))
        assert longest_chain(steep) < detector.LONE_CHAIN
    step = max(search.MIN_STEP, 6 * sigma)
    v, u = np.mgrid[0:h, 0:w]
    disc = (np.hypot(u - 320, v - 240) < 12.0).astype(float)
    blurred = cv2.GaussianBlur(100.0 + step * disc, (0, 0), 1.6)
    image = np.clip(blurred + sigma * rng.standard_normal((h, w)), 0, 255).astype(np.float32)
    assert longest_chain(search.steep(image)) >= detector.LONE_CHAIN
