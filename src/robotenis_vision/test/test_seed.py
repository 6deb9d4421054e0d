"""The next frame's seed: the ball moved on at the velocity of its last two detections."""
import numpy as np
from robotenis_vision import camera as vision_camera, detector
from robotenis_vision.seed import Seed
import simple_render

R = 0.019                       # m: the paper's ball radius R_B
CAM = vision_camera.default()


def detection(position):
    return detector.Detection(np.asarray(position, dtype=float), np.eye(3) * 1e-10,
                              np.zeros((0, 2)), 0.1, 'conic', {'psf_sigma': 0.9})


def test_the_seed_moves_on_at_constant_velocity_and_is_forgotten_when_the_ball_is_lost():
    seed = Seed()
    assert seed.at(0.0) is None
    seed.update(detection([0.0, 0.0, 0.3]), 1.0)
    np.testing.assert_array_equal(seed.at(1.1).position, [0.0, 0.0, 0.3])   # one: where it was
    seed.update(detection([0.01, 0.0, 0.3]), 1.1)
    moved = seed.at(1.15)
    np.testing.assert_allclose(moved.position, [0.015, 0.0, 0.3], atol=1e-15)
    assert moved.extra == {'psf_sigma': 0.9}                  # the blur and noise levels kept
    np.testing.assert_allclose(seed.at(1.1).position, [0.01, 0.0, 0.3])     # no time: no move
    seed.lost()
    assert seed.at(1.2) is None


def test_a_ball_crossing_the_image_is_followed_without_a_search_where_the_last_position_fails():
    # a ball moving 12 px a frame (about 1.1 m/s at 0.3 m and 120 Hz), on an independent
    # renderer: seeded where it was, its outline is not where it is measured and the detector
    # searches the whole image (a call to detector.find); seeded where it is going, only for the
    # first frame (no seed) and the second (one detection: no velocity yet)
    v = np.array([1.1, 0.4, 0.0]) / 120.0
    C = [np.array([-0.08, -0.03, 0.3]) + k * v for k in range(12)]
    images = [simple_render.render(CAM, c, R) for c in C]
    searches = {}
    find = detector.find
    for name, moving in (('last', False), ('moving', True)):
        count = [0]

        def counting(*args, count=count):
            count[0] += 1
            return find(*args)

        detector.find = counting
        try:
            seed = Seed()
            for k, image in enumerate(images):
                last = seed.track[-1][1] if seed.track else None
                prior = seed.at(k / 120.0) if moving else last
                det = detector.detect(image, CAM, R, 'conic', prior)
                np.testing.assert_allclose(det.position, C[k], atol=2e-4)
                seed.update(det, k / 120.0)
        finally:
            detector.find = find
        searches[name] = count[0]
    assert searches == {'last': 12, 'moving': 2}
