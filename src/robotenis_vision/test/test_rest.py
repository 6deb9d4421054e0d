"""At rest: the switch to the accurate method, and the fast one corrected from mean images."""
from dataclasses import replace

import numpy as np
import pytest
from robotenis_sim import camera_model as cm
from robotenis_vision import camera as vision_camera, detector
from robotenis_vision.rest import MeanCorrection, outline_px, RestCorrection, RestSwitch
from scipy.stats import f as f_dist, norm
import simple_render

R = 0.019                       # m: the paper's ball radius R_B
NOISE = 2.0                     # grey levels per frame
CAM = vision_camera.default()


def test_rest_after_enough_still_frames_and_again_after_a_move_or_a_lost_frame():
    switch = RestSwitch(motion_px=0.3, frames=3)
    # the first frame has nothing to compare with; then three still frames make it rest
    assert [switch.update((100.0, 50.0 + 0.1 * k)) for k in range(4)] == [False] * 3 + [True]
    assert switch.update((100.0, 50.5))          # moved 0.2 px: still at rest
    assert not switch.update((100.0, 51.0))      # moved 0.5 px: moving again
    assert [switch.update((100.0, 51.0)) for _ in range(3)] == [False, False, True]
    switch.lost()
    assert not switch.update((100.0, 51.0))
    with pytest.raises(ValueError, match='motion_px'):
        RestSwitch(0.0, 3)


def test_a_ball_moving_along_the_line_of_sight_is_not_at_rest():
    """Its centre stands still in the image, its outline's radius does not."""
    switch = RestSwitch(motion_px=0.3, frames=3)
    # toward the camera at 0.6 m/s, a frame at 120 Hz: 5 mm a frame at 0.37 m
    C = np.array([0.0, 0.0, 0.37]) - np.outer(np.arange(6), [0.0, 0.0, 0.005])
    outlines = np.array([outline_px(CAM, c, R) for c in C])
    assert np.ptp(outlines[:, :2], axis=0).max() < 1e-9            # the centre never moves
    assert np.diff(outlines[:, 2]).min() > 0.3                     # the radius grows
    assert not any(switch.update(o) for o in outlines)
    assert [switch.update(outlines[-1]) for _ in range(3)] == [False, False, True]


def test_a_new_sum_at_rest_is_fitted_from_the_fast_detection_not_the_last_fit():
    """A ball creeping under motion_px a frame leaves its sum: the last fit is then elsewhere."""
    seeds = []

    def accurate(image, seed):
        seeds.append(seed)
        return replace(seed, position=seed.position + 1e-4, method='model')

    rest = RestCorrection(0.3, 1, accurate, 'model')
    image = np.zeros((4, 5), np.uint8)
    fast = [detector.Detection(np.array([0.0, 0.0, 0.3 + 1e-4 * k]), np.eye(3) * 1e-10,
                               np.zeros((0, 2)), 0.1, 'conic') for k in range(4)]
    for k, det in enumerate(fast):                 # 0.2 px a frame: still, frame by frame
        rest.update(image, det, (320.0 + 0.2 * k, 240.0, 30.0))
    # fits at the first frame at rest (1) and at the new sum of frame 3, 0.3 px from 1 and 2
    assert len(seeds) == 2 and seeds[0] is fast[1] and seeds[1] is fast[3]


def test_a_rests_first_fit_from_the_conics_ball_finds_the_model_outline_of_a_defocused_ball():
    """
    As scene 001 of benchmarks/vision.py's list: side-lit, 0.44 m away, a 1.8 px defocus disc.

    The conic's outline lies inside the ball's on its dark side (it reads 40 mm far); a model
    fit started there refused the frame, or stayed 17-33 mm far (half the frames of the
    benchmark's scene), and the rest's later fits, each seeded by the last, kept it. Seeded by
    the conic, the frames' fits must scatter about one depth as their noise does: each within
    the 99.9 % interval of its own depth (sd about 1 mm) about the frames' mean; a fit held in
    another minimum lies many times that away.
    """
    c = np.array([-0.069, -0.052, 0.441])
    u = c / np.linalg.norm(c)
    lighting = cm.Lighting(direction=(0.516, -0.075, -0.853), ambient=20.3, diffuse=162.7)
    background = cm.Background(pattern='gradient', low=75.3, high=75.3, defocus_px=3.0)
    depth, sd = [], []
    for seed in range(6):
        image = cm.render(CAM, c, R, np.random.default_rng(seed), lighting=lighting,
                          background=background, defocus_px=1.84, noise_sigma=2.07)
        conic = detector.detect(image, CAM, R, 'conic')
        assert (conic.position - c) @ u > 0.03          # the conic's ball, far behind
        det = detector.detect(image, CAM, R, 'model', conic, search=False)
        depth.append(det.position @ u)
        sd.append(np.sqrt(u @ det.covariance @ u))
    var, n = np.square(sd), len(sd)
    # each fit's deviation from the mean of all, its variance with the mean's share in it
    z = (np.array(depth) - np.mean(depth)) / np.sqrt(var * (1 - 2 / n) + var.sum() / n ** 2)
    assert np.all(np.abs(z) < norm.ppf(0.9995)), z


def test_the_mean_correction_fits_at_1_8_16_and_adds_the_accurate_less_the_fast_mean():
    mean = MeanCorrection(motion_px=0.3)
    rng = np.random.default_rng(1)
    images = rng.integers(0, 256, (9, 4, 5)).astype(np.uint8)
    fast = np.array([0.01, 0.02, 0.3]) + 1e-5 * rng.standard_normal((9, 3))
    due = [mean.add(images[k], fast[k], (320.0 + 0.01 * k, 240.0)) for k in range(8)]
    assert due == [True, False, False, False, False, False, False, True]
    assert mean.corrected(fast[0]) is None                   # no fit yet
    np.testing.assert_allclose(mean.mean_image(), images[:8].mean(axis=0), rtol=1e-6)
    accurate = np.array([0.0101, 0.0199, 0.3004])
    mean.fitted(accurate)
    np.testing.assert_allclose(mean.corrected(fast[8]),
                               fast[8] + accurate - fast[:8].mean(axis=0), rtol=1e-12)
    # the ball leaves the summed frames' mean by more than motion_px: a new sum, due at once,
    # the last correction kept meanwhile; a lost ball forgets both
    assert mean.add(images[8], fast[8], (320.5, 240.0)) and mean.n == 1
    assert mean.corrected(fast[8]) is not None
    mean.reset()
    assert mean.corrected(fast[8]) is None and mean.n == 0
    with pytest.raises(ValueError, match='motion_px'):
        MeanCorrection(0.0)


def rest_means(C, frames, rng):
    """
    Average the frames at rest of a stream of noisy frames of a still ball, two ways.

    Returns the mean of per-frame model fits, the mean of the node's detections (RestCorrection:
    the conic corrected from mean images) and the number of model fits the second took.
    """
    clean = simple_render.render(CAM, C, R).astype(np.float32)
    fits = []

    def accurate(image, seed):
        fits.append(image)
        return detector.detect(image, CAM, R, 'model', seed, search=False)

    rest = RestCorrection(0.3, 3, accurate, 'model')
    per_frame, corrected, last, prior = [], [], None, None
    for _ in range(frames):
        image = np.clip(np.rint(clean + NOISE * rng.standard_normal(clean.shape)), 0, 255)
        image = image.astype(np.uint8)
        fast = prior = detector.detect(image, CAM, R, 'conic', prior)
        det, failure = rest.update(image, fast, CAM.project(fast.position))
        assert failure is None
        if det.method == 'conic+model mean':
            last = detector.detect(image, CAM, R, 'model', last or fast)
            per_frame.append(last.position)
            corrected.append(det.position)
    return np.mean(per_frame, axis=0), np.mean(corrected, axis=0), len(fits)


def test_a_rest_corrected_from_mean_images_agrees_with_per_frame_fits_at_a_fraction_of_the_fits():
    # rests on an independent renderer (simple_render); the two averages' difference over rests
    # must be zero within its own scatter: Hotelling's T^2 at the 1 % level
    rng = np.random.default_rng(7)
    C, frames, rests = np.array([0.04, -0.03, 0.32]), 19, 12
    D, fits = [], set()
    for _ in range(rests):
        a, b, n = rest_means(C, frames, rng)
        D.append(b - a)
        fits.add(n)
    # at rest from the fourth frame (3 still ones): fitted at 1, 8, 16 of 16 frames
    assert fits == {3}
    D = np.array(D)
    m, S = D.mean(axis=0), np.cov(D.T)
    t2 = rests * m @ np.linalg.solve(S, m)
    p = 3
    limit = p * (rests - 1) / (rests - p) * f_dist.ppf(0.99, p, rests - p)
    assert t2 < limit, (t2, limit, m)


def test_a_failed_fit_at_rest_keeps_the_last_correction_and_says_why():
    calls = []

    def accurate(image, seed):
        calls.append(seed)
        if len(calls) == 2:
            raise detector.DetectionError('misfit')
        return replace(seed, position=np.array([0.0, 0.0, 0.301]))

    rest = RestCorrection(0.3, 1, accurate, 'model')
    fast = detector.Detection(np.array([0.0, 0.0, 0.3]), np.eye(3) * 1e-10, np.zeros((0, 2)),
                              0.1, 'conic')
    image = np.zeros((4, 5), np.uint8)
    out = [rest.update(image, fast, (320.0, 240.0)) for _ in range(9)]
    assert out[0] == (fast, None)                             # not yet still
    assert out[1][0].method == 'conic+model mean' and out[1][1] is None
    np.testing.assert_allclose(out[1][0].position, [0.0, 0.0, 0.301])
    assert len(calls) == 2                                    # fitted at 1 and 8 frames only
    # the second fit (8 frames) fails: the first correction stays, the reason is given; the next
    # fit starts from the fast detection again, not from the failed one's seed
    assert out[8][1] == 'on the mean of 8 frames at rest: misfit'
    np.testing.assert_allclose(out[8][0].position, [0.0, 0.0, 0.301])
    assert calls[0] is fast and calls[1].position[2] == 0.301
    for _ in range(8):                                        # 9 to 16 frames: fitted at 16
        rest.update(image, fast, (320.0, 240.0))
    assert len(calls) == 3 and calls[2] is fast


def test_every_frame_at_rest_publishes_the_accurate_method_on_the_frame_itself():
    seen = []

    def accurate(image, seed):
        seen.append((int(image[0, 0]), seed))
        return replace(seed, position=seed.position + 1e-4, method='model')

    rest = RestCorrection(0.3, 1, accurate, 'model', every_frame=True)
    fast = detector.Detection(np.array([0.0, 0.0, 0.3]), np.eye(3) * 1e-10, np.zeros((0, 2)),
                              0.1, 'conic')
    out = [rest.update(np.full((4, 5), k, np.uint8), fast, (320.0, 240.0))[0] for k in range(4)]
    assert out[0] is fast and [m.method for m in out[1:]] == ['model'] * 3
    # each frame's own image, seeded by the frame before's fit (the first by the fast one)
    assert [v for v, _ in seen] == [1, 2, 3] and seen[0][1] is fast and seen[1][1] is out[1]


def test_a_ball_the_accurate_method_refuses_at_rest_is_not_published():
    """While moving the fast detection is published; at rest, none without a correction."""
    def accurate(image, seed):
        raise detector.DetectionError('misfit')

    fast = detector.Detection(np.array([0.0, 0.0, 0.3]), np.eye(3) * 1e-10, np.zeros((0, 2)),
                              0.1, 'conic')
    image = np.zeros((4, 5), np.uint8)
    for every_frame in (False, True):
        rest = RestCorrection(0.3, 1, accurate, 'model', every_frame=every_frame)
        out = [rest.update(image, fast, (320.0, 240.0)) for _ in range(3)]
        assert out[0] == (fast, None)                         # not yet still
        assert all(det is None for det, _ in out[1:])
        if every_frame:
            assert [why for _, why in out[1:]] == ['at rest: misfit'] * 2
        else:
            assert out[1][1] == 'on the mean of 1 frames at rest: misfit'
            assert out[2][1] == 'at rest: no model correction yet (no fit of this rest has ' \
                                'succeeded)'


def test_a_rest_that_ends_shows_its_mean_image_and_its_noise_to_seen():
    """The node's background plate gets each rest's mean image once the ball moves or is lost."""
    shown = []

    def accurate(image, seed):
        return replace(seed, position=np.array([0.0, 0.0, 0.301]), extra={'noise': 0.8})

    rest = RestCorrection(0.3, 1, accurate, 'model',
                          seen=lambda image, det, noise: shown.append((image, det, noise)))
    fast = detector.Detection(np.array([0.0, 0.0, 0.3]), np.eye(3) * 1e-10, np.zeros((0, 2)),
                              0.1, 'conic')
    frames = np.random.default_rng(2).integers(0, 256, (13, 4, 5)).astype(np.uint8)
    for image in frames[:12]:                                 # 11 frames at rest: fits at 1, 8
        rest.update(image, fast, (320.0, 240.0))
    assert shown == []
    rest.update(frames[12], fast, (330.0, 240.0))             # moved: the rest ends
    (image, det, noise), = shown
    np.testing.assert_allclose(image, frames[1:12].mean(axis=0), rtol=1e-6)
    # the last fit's noise was of a mean of 8 frames; the image is a mean of 11
    assert det.position[2] == 0.301 and noise == pytest.approx(0.8 * np.sqrt(8 / 11))
    for image in frames[:3]:                                  # 3 frames at rest: a fit at 1
        rest.update(image, fast, (330.0, 240.0))
    rest.lost()                                               # lost: that rest ends too
    assert len(shown) == 2 and shown[1][2] == pytest.approx(0.8 * np.sqrt(1 / 3))
