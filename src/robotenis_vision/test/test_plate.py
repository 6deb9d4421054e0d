"""The background plate: what the ball hides, from views where it was elsewhere, and the fit."""
import cv2
import numpy as np
import pytest
from robotenis_vision import camera as vision_camera, detector, model_fit, plate
from scipy.stats import chi2
import simple_render

R = 0.019                       # m: the paper's ball radius R_B
CAM = vision_camera.default()
SHAPE = (CAM.height, CAM.width)


def texture(rng, level=80.0, sd=10.0, scale_px=2.5):
    """Return a smooth random background (float grey levels), finer than the fit's bins."""
    t = cv2.GaussianBlur(rng.standard_normal(SHAPE), (0, 0), scale_px)
    return level + sd * t / t.std()


def ball_at(u, v, z):
    """Return the sphere centre (m, optical) at range z whose image centre is pixel (u, v)."""
    return z * np.linalg.solve(CAM.K, [u, v, 1.0])


def view(background, centre, radius, noise, rng):
    """Return the background with a bright disc plus noise: the ball seen at ``centre`` (px)."""
    v, u = np.mgrid[:SHAPE[0], :SHAPE[1]]
    disc = np.hypot(u - centre[0], v - centre[1]) < radius
    return np.where(disc, 200.0, background) + noise * rng.standard_normal(SHAPE)


def test_the_plate_is_the_background_where_views_showed_it_to_within_their_noise():
    rng = np.random.default_rng(1)
    background, noise = texture(rng), 2.0
    centres = [(160.0, 120.0), (320.0, 120.0), (160.0, 240.0), (320.0, 240.0)]
    p = plate.BackgroundPlate(SHAPE)
    for c in centres:
        p.add(view(background, c, 40.0, noise, rng), c, 40.0, noise)
    v, u = np.mgrid[100:260, 140:340]
    pixels = np.column_stack([u.ravel(), v.ravel()])
    levels, scatter, dof = p.at(pixels)
    seen = np.isfinite(levels)
    # a pixel hidden in all but one view (the centres' discs overlap nowhere, so each pixel is
    # seen at least 3 times) would be NaN; seen ones agree with the background: chi-square
    assert seen.all() and dof.min() >= 2
    n_views = dof + 1
    z2 = (levels - background[v.ravel(), u.ravel()]) ** 2 * n_views / noise ** 2
    assert z2.sum() < chi2.ppf(0.999, len(z2))
    # the views' scatter about their mean is the noise's: the group is trusted
    assert plate.trusted(levels, scatter, dof)
    # a pixel inside the ball's disc in every view is not known
    q = plate.BackgroundPlate(SHAPE)
    for _ in range(3):
        q.add(view(background, (320.0, 240.0), 40.0, noise, rng), (320.0, 240.0), 40.0, noise)
    hidden = q.at(np.array([[320, 240], [330, 250]]))
    assert np.isnan(hidden[0]).all() and not plate.trusted(*hidden)


def test_a_background_that_moves_between_views_is_not_trusted():
    """Near enough for the camera's translation to shift it: the views disagree."""
    rng = np.random.default_rng(2)
    background, noise = texture(rng), 2.0
    pixels = np.column_stack([np.arange(200, 260), np.full(60, 300)])
    for shift_px, trusted in ((0, True), (1, False)):
        p = plate.BackgroundPlate(SHAPE)
        for k, c in enumerate([(100.0, 100.0), (500.0, 100.0), (100.0, 400.0), (500.0, 400.0)]):
            moved = np.roll(background, k * shift_px, axis=1)
            p.add(view(moved, c, 40.0, noise, rng), c, 40.0, noise)
        assert plate.trusted(*p.at(pixels)) is trusted


def test_a_view_the_plate_cannot_take_is_refused_with_the_reason():
    p = plate.BackgroundPlate(SHAPE)
    with pytest.raises(ValueError, match=r'a view of \(10, 10\), the plate is \(480, 640\)'):
        p.add(np.zeros((10, 10)), (5.0, 5.0), 3.0, 2.0)
    with pytest.raises(ValueError, match='radius nan px'):
        p.add(np.zeros(SHAPE), (5.0, 5.0), float('nan'), 2.0)


def test_the_fit_with_a_plate_has_the_flat_backgrounds_error_on_a_textured_one():
    """
    A uniform ball over a smooth texture (an independent renderer, simple_render), noise-free.

    Without a plate the texture moves the fit far beyond a rest's noise; with a plate from nine
    views of the ball elsewhere (each a mean of 16 frames), the error left is within it, as on a
    flat background: each ball's error is scored against the covariance of the (free limb's) fit
    of a rest's mean image (16 noisy frames), the sum over six balls against chi2(18).
    """
    rng = np.random.default_rng(3)
    background = texture(rng)
    flat = np.full(SHAPE, 80.0)

    def image(c, back, frames=0):
        if not frames:
            return simple_render.on_background(CAM, c, R, back, rng, noise_sigma=0.0)
        return np.mean([simple_render.on_background(CAM, c, R, back, rng).astype(float)
                        for _ in range(frames)], axis=0)

    p = plate.BackgroundPlate(SHAPE)
    for u in (120, 320, 520):
        for v in (100, 240, 380):
            c = ball_at(u, v, 0.3)
            p.add(image(c, background, 16), CAM.project(c), CAM.apparent_radius(c, R), 0.5)
    nees = np.zeros(3)
    for c in (ball_at(220, 170, 0.28), ball_at(420, 170, 0.32), ball_at(220, 310, 0.3),
              ball_at(420, 310, 0.26), ball_at(320, 240, 0.34), ball_at(170, 240, 0.3)):
        start = detector.detect(image(c, flat), CAM, R, 'model')
        # the free limb's covariance: the noise-free fits below keep it (shading.agrees)
        rest = model_fit.fit(image(c, background, 16), CAM, R, start.position,
                             start.extra['psf_sigma'], background=p)
        for k, (back, behind) in enumerate(((background, None), (background, p), (flat, None))):
            e = detector.detect(image(c, back), CAM, R, 'model', start, search=False,
                                background=behind).position - c
            nees[k] += e @ np.linalg.solve(rest.cov, e)
    bound = chi2.ppf(0.99, 18)
    assert nees[0] > bound                      # the texture's error, without the plate
    assert nees[1] < bound and nees[2] < bound
