"""
The model fit from a search's sphere whose outline is a pixel or two too small.

Rendered by robotenis_sim's camera model: a glossy ball, defocused by a 1.4 px disc, on a
gradient, lit from the front. Its search's sphere reads 57-65 mm far at 0.55 m (its outline about
2 px small); a fit from there alone stopped 15-20 mm far in 2 of 6 such frames of
benchmarks/vision.py's list, its outline inside the ball's, the levels' ramps taking the edge's
shoulder. Tolerance: a frame's error along the line of sight lies within 5 standard
deviations of its own covariance from the frames' median (a chance of 6e-7 a frame for the
fit's Gaussian noise; what is common to the frames, the bias, is left out).
"""
import numpy as np
from robotenis_sim import camera_model as cm
from robotenis_vision import camera, detector

R = 0.019
CAM = camera.default()
C = np.array([0.09, -0.068, 0.534])
SCENE = {'lighting': cm.Lighting(direction=(-0.08, -0.44, -0.89), ambient=24.0, diffuse=184.0,
                                 specular=104.0, shininess=54.0),
         'background': cm.Background(low=9.4, high=168.5, angle=0.84, pattern='gradient',
                                     defocus_px=0.45),
         'blur_sigma': 0.0, 'defocus_px': 1.43, 'noise_sigma': 2.2, 'gamma': 2.2}


def along(det):
    """Return the detection's error along the line of sight and its standard deviation (m)."""
    u = C / np.linalg.norm(C)
    return (det.position - C) @ u, np.sqrt(u @ det.covariance @ u)


def test_a_fit_left_inside_the_outline_is_replaced_by_one_from_a_larger_start():
    rng = np.random.default_rng(7)
    frames = [cm.render(CAM, C, R, rng, **SCENE) for _ in range(12)]
    errors = np.array([along(detector.detect(f, CAM, R, gamma=SCENE['gamma']))
                       for f in frames])
    deviation = np.abs(errors[:, 0] - np.median(errors[:, 0])) / errors[:, 1]
    assert deviation.max() < 5, (
        f'frames {np.flatnonzero(deviation >= 5).tolist()} read '
        f'{1e3 * errors[deviation >= 5, 0]} mm along the line of sight; the median of all frames '
        f'{1e3 * np.median(errors[:, 0]):.1f} mm')
