"""
The specular highlight measured on the ball's disc and taken out of the model fit (highlight.py).

Two renderers this module did not write: the simulator's (robotenis_sim.camera_model: a
Blinn-Phong highlight over a Lambertian ball, the model's own family) and the committed Mitsuba 3
set (rough plastic, GGX; test/data/mitsuba). Tolerances: the fits' own covariances (their noise
read from the images), chi2 at 99 %; a lobe's direction within a fraction of its own width.
"""
from dataclasses import replace

import numpy as np
import pytest
from robotenis_sim import camera_model as cm
from robotenis_vision import camera, detector, highlight
from scipy.stats import chi2
import test_mitsuba_set as mitsuba

R = 0.019
# off-centre balls at 0.3-0.4 m, where the default light's highlight reaches the limb's annulus
CENTRES = ((-0.08, 0.06, 0.35), (0.05, -0.07, 0.4), (-0.06, -0.05, 0.3), (0.07, 0.05, 0.38))


def render(cam, C, lighting):
    return cm.render(cam, C, R, np.random.default_rng(0), lighting=lighting, noise_sigma=0.0)


def test_the_simulators_highlight_is_measured_where_it_is():
    """
    On noisy renders the lobe points at the renderer's light and has its width.

    The direction within a tenth of the lobe's angular width, the width within 10 % (the disc's
    lobe is fitted unblurred: a blur of 0.8 px widens a lobe a few pixels wide by a few %).
    """
    cam = camera.default()
    lighting = cm.Lighting()
    true_light = np.asarray(lighting.direction) / np.linalg.norm(lighting.direction)
    for C in CENTRES:
        image = cm.render(cam, C, R, np.random.default_rng(1), lighting=lighting, noise_sigma=2.0)
        det = detector.detect(image, cam, R, 'model')
        lobe = highlight.fit(image, cam, det.position, R, det.extra['psf_sigma'])
        assert lobe is not None
        width = 1 / np.sqrt(lighting.shininess)
        assert np.arccos(lobe.light @ true_light) < width / 10
        assert lobe.width == pytest.approx(width, rel=0.1)


def test_no_highlight_is_found_on_a_lambertian_ball():
    cam = camera.default()
    lighting = replace(cm.Lighting(), specular=0.0)
    for C in CENTRES:
        image = cm.render(cam, C, R, np.random.default_rng(1), lighting=lighting, noise_sigma=2.0)
        det = detector.detect(image, cam, R, 'model')
        assert highlight.fit(image, cam, det.position, R, det.extra['psf_sigma']) is None


def test_a_mean_image_at_rest_is_fitted_with_its_own_lobe():
    """
    A rest's fit on its mean image does not keep what the first frame's noise put in the lobe.

    As the node measures a rest: the first frame by the conic, then fitted from there, then the
    mean of 16 more frames seeded by that fit. It must land where the same mean image's fit
    seeded at the true ball lands: their difference within the fit's 99 % ellipsoid (chi2(3)).
    With the first frame's lobe carried to the mean image, this ball 0.415 m away read 0.21-0.27 mm
    nearer than with the mean's own lobe in 3 of these 6 rests (chi2 235-262), for a standard
    deviation of 0.04 mm along the line of sight.
    """
    cam = camera.default()
    C = np.array([-0.131, -0.0705, 0.387])
    for seed in range(6):
        rng = np.random.default_rng(seed)
        frames = [cm.render(cam, C, R, rng) for _ in range(17)]
        mean = np.mean(np.array(frames[1:], dtype=np.float32), axis=0)
        conic = detector.detect(frames[0], cam, R, 'conic')
        first = detector.detect(frames[0], cam, R, 'model', prior=conic, search=False)
        rest = detector.detect(mean, cam, R, 'model', prior=first, search=False)
        at_truth = replace(first, position=C, extra={'psf_sigma': first.extra['psf_sigma']})
        reference = detector.detect(mean, cam, R, 'model', prior=at_truth, search=False)
        d = rest.position - reference.position
        assert d @ np.linalg.solve(rest.covariance, d) < chi2.ppf(0.99, 3)


def test_a_ball_with_a_highlight_is_measured_where_the_same_ball_without_one_is():
    """
    With its highlight taken out, the fit agrees with the fit of the ball rendered without one.

    Noise-free renders of one scene with and without the Blinn-Phong highlight: the difference of
    the two depths over its standard deviation (both fits' covariances, their noise the images'
    8-bit rounding), squared and summed over the scenes, within chi2's 99 % quantile. Without the
    highlight's model the highlight's tail near the limb reads the ball 0.1-0.2 mm too near.
    """
    cam = camera.default()
    lighting = cm.Lighting()
    total = 0.0
    for C in CENTRES:
        u = np.asarray(C) / np.linalg.norm(C)
        a = detector.detect(render(cam, C, lighting), cam, R, 'model')
        b = detector.detect(render(cam, C, replace(lighting, specular=0.0)), cam, R, 'model')
        d = (a.position - b.position) @ u
        total += d * d / (u @ (a.covariance + b.covariance) @ u)
    assert total < chi2.ppf(0.99, len(CENTRES))


def test_on_mitsuba_the_highlight_is_found_on_glossy_balls_lit_from_the_front_only():
    """
    A point-lit glossy ball's lobe points at the light within its width; a diffuse ball has none.

    Mitsuba's rough plastic is a GGX lobe with Fresnel over a diffuse base: not the model's
    Blinn-Phong. Back-lit balls' highlights lie on the limb, outside the disc the lobe is measured
    on, and are left to the fit's robust weights.
    """
    found = {'glossy': 0, 'diffuse': 0}
    for entry in mitsuba.index():
        truth, cam, frames = mitsuba.load(entry)
        scene = truth['scene']
        try:
            det = detector.detect(frames[0], cam, R, 'model', gamma=scene['exposure']['gamma'])
        except detector.DetectionError:
            continue
        lobe = highlight.fit(frames[0], cam, det.position, R, det.extra['psf_sigma'],
                             scene['exposure']['gamma'])
        kind, light = scene['material']['type'], scene['light']
        found[kind] += lobe is not None
        if kind == 'glossy' and light['type'] == 'point' and light['direction'] == 'frontal':
            assert lobe is not None, entry['id']
            to_light = np.asarray(light['position_m']) - np.asarray(truth['ball']['center_m'])
            angle = np.arccos(lobe.light @ to_light / np.linalg.norm(to_light))
            assert angle < lobe.width, entry['id']
    assert found['diffuse'] == 0
    assert found['glossy'] >= 2
