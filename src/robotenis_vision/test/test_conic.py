"""The closed form from conic to sphere centre, the Taubin fit and the geometric refinement."""
import warnings

import numpy as np
import pytest
from robotenis_vision import conic
from robotenis_vision.conic import ConicError
from scipy.stats import chi2

R = 0.019                       # m: the paper's ball radius R_B
F = 500.0


def outline_xy(c, R, n=200):
    """Exact normalized outline points of sphere (c, R): touching rays from the cone's geometry."""
    d = np.linalg.norm(c)
    u = c / d
    a = np.cross(u, [1.0, 0.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(u, a)
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)[:, None]
    sin_b = R / d
    rays = np.sqrt(1 - sin_b ** 2) * u + sin_b * (np.cos(t) * a + np.sin(t) * b)
    return rays[:, :2] / rays[:, 2:]


CENTRES = [np.array(c) for c in ([0.0, 0.0, 0.2], [0.05, 0.03, 0.2], [-0.15, 0.1, 0.45],
                                 [0.2, -0.14, 0.6], [0.0, 0.0, 0.15])]


@pytest.mark.parametrize('c', CENTRES)
def test_closed_form_inverts_the_cone_at_any_scale(c):
    Q = conic.sphere_conic(c, R)
    for scale in (1.0, -3.7, 1e-6):
        np.testing.assert_allclose(conic.sphere_from_conic(scale * Q, R), c, rtol=1e-12,
                                   atol=1e-15)


@pytest.mark.parametrize('c', CENTRES)
def test_taubin_then_closed_form_recovers_the_centre_from_projected_points(c):
    """Noise-free projected outline points: the fitted conic is the cone, the centre exact."""
    xy = outline_xy(c, R)
    Q = conic.taubin(xy)
    p = np.column_stack([xy, np.ones(len(xy))])
    assert np.max(np.abs(np.einsum('ni,ij,nj->n', p, Q, p))) < 1e-12
    np.testing.assert_allclose(conic.sphere_from_conic(Q, R), c, rtol=1e-8, atol=1e-12)
    fit = conic.fit_sphere(xy, R, F)
    np.testing.assert_allclose(fit.c, c, rtol=1e-10, atol=1e-13)
    assert fit.rms_px < 1e-8


def test_sampson_distance_is_the_pixel_distance_near_the_outline():
    c = CENTRES[1]
    xy = outline_xy(c, R, 50)
    centre = c[:2] / c[2]
    # 0.5 px outward
    out = xy + 1e-3 * (xy - centre) / np.linalg.norm(xy - centre, axis=1, keepdims=True)
    d = F * conic.sampson(out, c, R)
    np.testing.assert_allclose(d, 0.5, rtol=0.05)


def test_refined_centre_errors_match_the_predicted_covariance():
    """Gaussian point noise: the normalized estimation error squared averages 3 (chi-square)."""
    rng = np.random.default_rng(4)
    sigma_px, runs = 0.1, 200
    nees = []
    for k in range(runs):
        c = CENTRES[k % len(CENTRES)]
        xy = outline_xy(c, R, 120) + rng.normal(scale=sigma_px / F, size=(120, 2))
        fit = conic.fit_sphere(xy, R, F)
        e = fit.c - c
        nees.append(e @ np.linalg.solve(fit.cov, e))
    total = np.sum(nees)
    assert chi2.ppf(0.0005, 3 * runs) < total < chi2.ppf(0.9995, 3 * runs)


@pytest.mark.parametrize('c', CENTRES)
def test_refinement_from_a_nearby_sphere_needs_no_conic(c):
    """
    Refine from a sphere whose outline is a pixel off, without the conic.

    Started from such a sphere (the one the detector's profiles were laid along), the refinement
    reaches the Taubin-started estimate to a thousandth of its own sigma.
    """
    rng = np.random.default_rng(2)
    xy = outline_xy(c, R, 150) + rng.normal(scale=0.1 / F, size=(150, 2))
    c0 = c * (1 + R / np.linalg.norm(c) * 0.5 / (F * R / c[2])) + [c[2] / F, -c[2] / F, 0.0]
    assert np.max(np.abs(F * conic.sampson(xy, c0, R))) > 0.5
    from_taubin, from_c0 = conic.fit_sphere(xy, R, F), conic.fit_sphere(xy, R, F, c0=c0)
    sigma = np.sqrt(np.diag(from_taubin.cov))
    np.testing.assert_array_less(np.abs(from_c0.c - from_taubin.c), 1e-3 * sigma)
    np.testing.assert_array_equal(from_c0.inliers, from_taubin.inliers)


def test_outliers_are_rejected():
    rng = np.random.default_rng(1)
    c = CENTRES[2]
    xy = outline_xy(c, R, 150) + rng.normal(scale=0.05 / F, size=(150, 2))
    xy[:8] *= 0.99                                   # a glint: 8 points far inside
    fit = conic.fit_sphere(xy, R, F)
    assert not np.any(fit.inliers[:8])
    e = fit.c - c
    assert e @ np.linalg.solve(fit.cov, e) < chi2.ppf(0.999, 3)


def test_bad_input_is_named():
    with pytest.raises(ConicError, match='at least 5 points'):
        conic.taubin(np.zeros((3, 2)))
    with pytest.raises(ConicError, match='coincide'):
        conic.taubin(np.ones((10, 2)))
    with pytest.raises(ConicError, match='not the outline of a sphere'):
        conic.sphere_from_conic(np.diag([1.0, 1.0, 1.0]), R)


@pytest.mark.parametrize('c', CENTRES)
def test_three_touching_rays_fix_the_sphere(c):
    xy = outline_xy(c, R, 30)
    np.testing.assert_allclose(conic.sphere_from_three_rays(xy[0], xy[11], xy[23], R), c,
                               rtol=1e-9)


def test_a_degenerate_triple_gives_nan_without_a_warning():
    xy = outline_xy(CENTRES[0], R, 30)
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        c = conic.sphere_from_three_rays(xy[[0, 3]], xy[[0, 11]], xy[[5, 23]], R)
    assert np.all(np.isnan(c[0])) and np.all(np.isfinite(c[1]))


def test_ransac_ignores_points_that_caught_the_highlight():
    rng = np.random.default_rng(3)
    c = CENTRES[1]
    xy = outline_xy(c, R, 60) + rng.normal(scale=0.2 / F, size=(60, 2))
    centre = c[:2] / c[2]
    xy[10:25] = centre + 0.8 * (xy[10:25] - centre)          # a quarter of the points well inside
    fit, inliers = conic.ransac_sphere(xy, R, F, threshold_px=1.0)
    assert not np.any(inliers[10:25]) and np.all(inliers[25:])
    # the refit uses the 45 good points: within 4 sigma of the true depth for 0.2 px point noise
    depth_sigma = 0.2 / F * c[2] ** 2 / R / np.sqrt(45 / 2)
    assert abs(fit[2] - c[2]) < 4 * depth_sigma


def test_sampson_jacobian_matches_finite_differences():
    rng = np.random.default_rng(5)
    c = CENTRES[2]
    xy = outline_xy(c, R, 40) + rng.normal(scale=0.5 / F, size=(40, 2))
    P = np.column_stack([xy, np.ones(40)])
    r, J = conic._residual_and_jacobian(P, np.sum(P * P, axis=1), c, R, F)
    np.testing.assert_allclose(r, F * conic.sampson(xy, c, R), rtol=1e-12)
    h = 1e-7
    numeric = np.stack([(F * conic.sampson(xy, c + h * e, R)
                         - F * conic.sampson(xy, c - h * e, R)) / (2 * h)
                        for e in np.eye(3)], axis=1)
    np.testing.assert_allclose(J, numeric, rtol=1e-5, atol=1e-6 * np.abs(J).max())
