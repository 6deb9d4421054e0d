"""The switch between the fast method while the ball moves and the accurate one at rest."""
import numpy as np
import pytest
from robotenis_vision import camera as vision_camera, detector
from robotenis_vision.rest import MeanCorrection, RestSwitch
from scipy.stats import f as f_dist
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


def test_the_mean_correction_fits_at_powers_of_two_and_adds_the_accurate_less_the_fast_mean():
    mean = MeanCorrection(motion_px=0.3)
    rng = np.random.default_rng(1)
    images = rng.integers(0, 256, (9, 4, 5)).astype(np.uint8)
    fast = np.array([0.01, 0.02, 0.3]) + 1e-5 * rng.standard_normal((9, 3))
    due = [mean.add(images[k], fast[k], (320.0 + 0.01 * k, 240.0)) for k in range(8)]
    assert due == [True, True, False, True, False, False, False, True]
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
    Average a rest of noisy frames two ways.

    Returns the mean of per-frame model fits, the mean of the conic corrected from mean images
    (as the node does) and the number of model fits the second took.
    """
    clean = simple_render.render(CAM, C, R).astype(np.float32)
    per_frame, corrected, fits = [], [], 0
    last, last_mean, prior, mean = None, None, None, MeanCorrection(0.3)
    for _ in range(frames):
        image = np.clip(np.rint(clean + NOISE * rng.standard_normal(clean.shape)), 0, 255)
        image = image.astype(np.uint8)
        fast = prior = detector.detect(image, CAM, R, 'conic', prior)
        last = detector.detect(image, CAM, R, 'model', last or fast)
        per_frame.append(last.position)
        if mean.add(image, fast.position, CAM.project(fast.position)):
            last_mean = detector.detect(mean.mean_image(), CAM, R, 'model', last_mean or fast)
            mean.fitted(last_mean.position)
            fits += 1
        corrected.append(mean.corrected(fast.position))
    return np.mean(per_frame, axis=0), np.mean(corrected, axis=0), fits


def test_a_rest_corrected_from_mean_images_agrees_with_per_frame_fits_at_a_fraction_of_the_fits():
    # rests on an independent renderer (simple_render); the two averages' difference over rests
    # must be zero within its own scatter: Hotelling's T^2 at the 1 % level
    rng = np.random.default_rng(7)
    C, frames, rests = np.array([0.04, -0.03, 0.32]), 16, 12
    D, fits = [], set()
    for _ in range(rests):
        a, b, n = rest_means(C, frames, rng)
        D.append(b - a)
        fits.add(n)
    assert fits == {5}                                      # frames 1, 2, 4, 8, 16 of 16
    D = np.array(D)
    m, S = D.mean(axis=0), np.cov(D.T)
    t2 = rests * m @ np.linalg.solve(S, m)
    p = 3
    limit = p * (rests - 1) / (rests - p) * f_dist.ppf(0.99, p, rests - p)
    assert t2 < limit, (t2, limit, m)
