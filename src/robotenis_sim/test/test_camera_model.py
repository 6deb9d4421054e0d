"""The hand camera renderer: geometry against OpenCV's projection, noise, and the mounting."""
import cv2
import numpy as np
import pytest
from robotenis_sim import camera_model as cm, hand_camera_node, truth as sim_truth
from robotenis_vision import camera, detector, model_fit
from scipy.stats import chi2

R = 0.019                       # m: the paper's ball radius R_B
CAM = camera.default()
WHITE = cm.Lighting(ambient=255.0, diffuse=0.0, specular=0.0)
BLACK = cm.Background(low=0.0, high=0.0, texture=0.0)


def opencv_outline(C, n=4000):
    """Project the sphere's outline with OpenCV (its own plumb_bob): a polygon (n, 2), pixels."""
    uv, _ = cv2.projectPoints(cm.tangent_circle(C, R, n).reshape(-1, 1, 3), np.zeros(3),
                              np.zeros(3), CAM.K, CAM.D)
    return uv.reshape(-1, 2)


@pytest.mark.parametrize('C', [[0.0, 0.0, 0.2], [0.0, 0.0, 0.6], [0.15, 0.1, 0.3],
                               [-0.2, 0.1, 0.35], [0.02, -0.05, 0.15]])
def test_covered_area_and_centroid_match_the_projected_outline(C):
    """
    Check that the covered area and centroid match the projected outline.

    Supersampled coverage: the ball's area and centroid in the image to 1/200 px of radius and
    position (8 x 8 rays in each of a pixel's 2 x 2 sub-pixels: 1/256 of a pixel's area per edge
    pixel, averaging out along the edge; 8-bit rounding of the coverage adds 1/510 per edge pixel
    at most).
    """
    image = cm.render(CAM, C, R, np.random.default_rng(0), lighting=WHITE, background=BLACK,
                      blur_sigma=0.0, noise_sigma=0.0).astype(float) / 255
    x, y = opencv_outline(C).T
    area = 0.5 * abs(np.dot(x, np.roll(y, 1)) - np.dot(y, np.roll(x, 1)))
    cx = np.sum((x + np.roll(x, 1)) * (x * np.roll(y, 1) - np.roll(x, 1) * y)) / (6 * -area)
    cy = np.sum((y + np.roll(y, 1)) * (x * np.roll(y, 1) - np.roll(x, 1) * y)) / (6 * -area)
    r_eq = np.sqrt(area / np.pi)
    assert abs(image.sum() - area) / (2 * np.pi * r_eq) < 0.005
    v, u = np.mgrid[0:CAM.height, 0:CAM.width]
    centroid = np.array([(image * u).sum(), (image * v).sum()]) / image.sum()
    assert np.linalg.norm(centroid - [abs(cx), abs(cy)]) < 0.005


def test_the_limb_is_shaded_by_the_pixels_area():
    """
    Check that the pixels just inside the limb carry their area's mean shading, not their centre's.

    A frontally lit ball brightens as the square root of the depth inside its outline, so a pixel's
    centre value exceeds its mean (f'' / 24 across the outline: 0.4 grey levels 1.5 px in). The
    reference is the mean over 16 x 16 rays of each pixel; the renderer's 4 x 4 grid is 16 times
    closer to it than the centre, and 8-bit rounding adds sd 0.29 / sqrt(n) to a mean over n
    pixels.
    """
    C = np.array([0.0, 0.0, 0.2])
    D = 250.0
    light = cm.Lighting(direction=(0.0, 0.0, -1.0), ambient=0.0, diffuse=D, specular=0.0)
    image = cm.render(CAM, C, R, np.random.default_rng(0), lighting=light, background=BLACK,
                      blur_sigma=0.0, noise_sigma=0.0).astype(float)
    tan_beta = R / np.sqrt(C @ C - R * R)
    v, u = np.mgrid[180:300, 260:380].reshape(2, -1).astype(float)
    depth = (tan_beta - np.hypot(*CAM.pixel_rays(np.stack([u, v], -1)).T)) * CAM.fx
    band = (depth > 1.0) & (depth < 3.5)
    u, v = u[band], v[band]
    g = (np.arange(16) + 0.5) / 16 - 0.5
    du, dv = (a.ravel() for a in np.meshgrid(g, g))
    xy = CAM.pixel_rays(np.stack([u[:, None] + du, v[:, None] + dv], -1))

    def lambert(xy):
        """Return D cos(i) for the rays (x, y, 1) on the ball at C (on the axis, light frontal)."""
        d = np.concatenate([xy, np.ones(xy.shape[:-1] + (1,))], -1)
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        b = d @ C
        t = b - np.sqrt(b * b - (C @ C - R * R))
        return D * (C[2] - t * d[..., 2]) / R

    area = lambert(xy).mean(axis=1)
    centre = lambert(CAM.pixel_rays(np.stack([u, v], -1)))
    rendered = image[v.astype(int), u.astype(int)]
    assert np.mean(centre - area) > 0.1      # what is to be resolved
    assert abs(np.mean(rendered - area)) < np.mean(centre - area) / 8 + 4 * 0.29 / np.sqrt(len(u))


def test_the_blurred_outline_does_not_move_with_its_phase_on_the_pixel_grid():
    """
    Check that a still ball's outline carries no error beyond the noise that depends on its pose.

    A pixel integrates the lens's blurred image over its area. A flat disc (ambient light only)
    on a flat background is what the model fit's edge without its limb term describes, blur
    included: 24 balls at 0.2-0.4 m across the view, each the mean of 16 noisy frames, fitted
    from the truth. Their errors along the line of sight, less their mean (a bias common to all),
    scaled by the fits' variances (the mean's share taken out) must sum as chi2(23). A Gaussian
    of 0.8 px sampled once a pixel and applied to pixels that integrate a sharp outline (the
    renderer before) moved the outline with its phase on the grid: sums of 50-89 on four seeds
    (the bound 49.7), 19-40 drawn on sub-pixels.
    """
    light = cm.Lighting(direction=(0.0, 0.0, -1.0), ambient=160.0, diffuse=0.0, specular=0.0)
    flat = cm.Background(low=60.0, high=60.0, texture=0.0)
    rng = np.random.default_rng(0)
    errors, variances = [], []
    for _ in range(24):
        C = np.linalg.solve(CAM.K, [rng.uniform(120, 520), rng.uniform(100, 380), 1.0])
        C *= rng.uniform(0.2, 0.4)
        mean = np.mean([cm.render(CAM, C, R, rng, lighting=light, background=flat)
                        for _ in range(16)], axis=0)
        fit = model_fit.fit(mean, CAM, R, C, blur0=0.8, limb=False)
        d = C / np.linalg.norm(C)
        errors.append((fit.c - C) @ d)
        variances.append(d @ fit.cov @ d)
    errors, variances = np.array(errors), np.array(variances)
    deviations = errors - errors.mean()
    exact = variances * (1 - 2 / len(errors)) + variances.sum() / len(errors) ** 2
    assert np.sum(deviations ** 2 / exact) < chi2.ppf(0.999, len(errors) - 1)


def test_sphere_outline_is_the_projected_tangent_circle():
    C = np.array([0.05, -0.03, 0.25])
    np.testing.assert_allclose(cm.sphere_outline(CAM, C, R, 50), opencv_outline(C, 50), atol=1e-9)


def test_noise_has_the_requested_variance():
    """Check a flat, ball-free background: the variance is noise^2 plus 1/12 (8-bit rounding)."""
    rng = np.random.default_rng(3)
    flat = cm.Background(low=100.0, high=100.0, texture=0.0)
    image = cm.render(CAM, [0.0, 0.0, -1.0], R, rng, background=flat,
                      noise_sigma=2.0).astype(float)
    block = image[100:200, 100:300]
    n = block.size
    s2 = block.var(ddof=1)
    expected = 4.0 + 1 / 12
    assert chi2.ppf(0.0005, n - 1) / (n - 1) < s2 / expected < chi2.ppf(0.9995, n - 1) / (n - 1)


def test_shading_background_and_repeatability():
    a = cm.render(CAM, [0.0, 0.0, 0.2], R, np.random.default_rng(9))
    b = cm.render(CAM, [0.0, 0.0, 0.2], R, np.random.default_rng(9))
    np.testing.assert_array_equal(a, b)
    assert a.dtype == np.uint8 and a.shape == (480, 640)
    ball = a[225:255, 305:335]
    assert ball.max() - ball.min() > 100                 # shaded: a lit side and a dark side
    assert abs(int(a[20, 600]) - int(a[460, 20])) > 30   # the background has a gradient
    empty = cm.render(CAM, [0.0, 0.0, -0.2], R, np.random.default_rng(9))
    assert np.abs(empty[225:255, 305:335].astype(int)
                  - int(np.median(empty[225:255, 305:335]))).max() < 40


def test_checker_noise_defocus_and_response_backgrounds():
    """
    Check the background patterns, the defocus disc and the response curve, without noise.

    A checkerboard's squares alternate low and high with edges at phase + k square_px (its
    pixels straddling an edge are the fraction on each side); the random texture stays within
    low..high; a defocus keeps the mean level and spreads an edge over its disc's diameter; a
    disc smaller than a pixel's samples is no blur (and no NaN); the response maps a linear grey
    I to 255 (I / 255)^(1 / gamma), within the 8-bit rounding.
    """
    far = [0.0, 0.0, -1.0]
    checker = cm.Background(pattern='checker', low=40.0, high=200.0, texture=0.0,
                            square_px=20.0, phase_px=(10.0, 0.0))
    image = cm.render(CAM, far, R, np.random.default_rng(0), background=checker,
                      blur_sigma=0.0, noise_sigma=0.0).astype(float)
    row = image[5]
    assert row[15] == row[25] and row[35] == row[45] and {row[25], row[35]} == {40.0, 200.0}
    # pixel 10 (9.5..10.5) straddles the edge at u = 10: half of its 4x4 samples on each side
    assert image[5, 10] == 120.0 and abs(image[5, 11] - image[5, 9]) == 160.0
    noise = cm.Background(pattern='noise', low=60.0, high=180.0, texture=0.0, scale_px=4.0)
    textured = cm.render(CAM, far, R, np.random.default_rng(0), background=noise,
                         blur_sigma=0.0, noise_sigma=0.0)
    assert textured.min() >= 60 and textured.max() <= 180 and textured.std() > 10
    flat = cm.Background(pattern='checker', low=40.0, high=200.0, texture=0.0, square_px=40.0)
    sharp = cm.render(CAM, far, R, np.random.default_rng(0), background=flat, blur_sigma=0.0,
                      noise_sigma=0.0).astype(float)
    blurred = cm.render(CAM, far, R, np.random.default_rng(0), background=flat, blur_sigma=0.0,
                        noise_sigma=0.0, defocus_px=3.0).astype(float)
    assert abs(blurred[40:440, 40:600].mean() - sharp[40:440, 40:600].mean()) < 0.5
    across = blurred[20, 30:50]                 # the edge at u = 39.5, spread over +- 3 px
    assert np.all(np.diff(across) >= 0) or np.all(np.diff(across) <= 0)
    assert np.sum((across > 41) & (across < 199)) in (6, 7)
    tiny = cm.render(CAM, far, R, np.random.default_rng(0), background=flat, blur_sigma=0.0,
                     noise_sigma=0.0, defocus_px=0.01)
    np.testing.assert_array_equal(tiny, sharp.astype(np.uint8))
    grey = cm.Background(low=100.0, high=100.0, texture=0.0)
    bright = cm.render(CAM, far, R, np.random.default_rng(0), background=grey, noise_sigma=0.0,
                       gamma=2.2)
    assert abs(float(bright.mean()) - 255 * (100 / 255) ** (1 / 2.2)) <= 0.5
    with pytest.raises(ValueError, match='pattern'):
        cm.Background(pattern='stripes')
    with pytest.raises(ValueError, match='gamma'):
        cm.render(CAM, far, R, np.random.default_rng(0), gamma=0.0)


def test_sphere_in_optical_frame_from_the_mounting():
    truth = sim_truth.load()
    P = np.array([0.01, 0.02, 0.8])
    ball = truth.sphere_position
    C = cm.sphere_in_optical(P, ball, truth.camera_rotation, truth.camera_translation)
    np.testing.assert_allclose(truth.camera_rotation @ C + P + truth.camera_translation, ball,
                               atol=1e-15)
    # the nominal mounting looks along base +x: depth is the base x distance
    assert abs(C[2] - (ball[0] - P[0] - truth.camera_translation[0])) < 1e-15


def test_bad_input_is_named():
    with pytest.raises(ValueError, match='sphere_centre_optical'):
        cm.render(CAM, [0.0, 0.2], R, np.random.default_rng(0))
    with pytest.raises(ValueError, match='radius'):
        cm.render(CAM, [0.0, 0.0, 0.2], -R, np.random.default_rng(0))
    with pytest.raises(ValueError, match='noise_sigma'):
        cm.render(CAM, [0.0, 0.0, 0.2], R, np.random.default_rng(0), noise_sigma=-1.0)


def test_hand_camera_messages():
    """The node's messages: mono8 image bytes row by row, camera_info fields from the camera."""
    from std_msgs.msg import Header
    from robotenis_ros.convert import camera_info_message, image_message
    image = np.arange(12, dtype=np.uint8).reshape(3, 4)
    msg = image_message(image, Header(frame_id='camera_optical'))
    assert (msg.height, msg.width, msg.step, msg.encoding) == (3, 4, 4, 'mono8')
    assert bytes(msg.data) == image.tobytes()
    info = camera_info_message(CAM.camera_info_fields(), Header(frame_id='camera_optical'))
    assert (info.width, info.height, info.distortion_model) == (640, 480, 'plumb_bob')
    np.testing.assert_array_equal(np.reshape(info.k, (3, 3)), CAM.K)
    np.testing.assert_array_equal(info.d, CAM.D)
    assert camera.from_camera_info(info).width == 640


def test_circles_cover_their_projected_area():
    """A 40 mm disc at 200 mm, tilted: the ink covers the area of its projected rim (OpenCV)."""
    n = np.array([0.0, np.sin(0.3), -np.cos(0.3)])
    c = np.array([0.01, -0.02, 0.2])
    image = cm.render_circles(CAM, [c], [n], [0.02], np.random.default_rng(0), plate=255.0,
                              ink=0.0, blur_sigma=0.0, noise_sigma=0.0).astype(float)
    ink = (255.0 - image) / 255.0
    rim = cm._disc_rim(c, n, 0.02, 4000)
    uv, _ = cv2.projectPoints(rim.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), CAM.K, CAM.D)
    x, y = uv.reshape(-1, 2).T
    area = 0.5 * abs(np.dot(x, np.roll(y, 1)) - np.dot(y, np.roll(x, 1)))
    # 1/200 px of "radius", as above
    assert abs(ink.sum() - area) / (2 * np.sqrt(np.pi * area)) < 0.005
    with pytest.raises(ValueError, match='must agree'):
        cm.render_circles(CAM, [c], [n, n], [0.02], np.random.default_rng(0))


def test_frame_clock_exposes_the_first_sample_after_each_deadline():
    """
    Check that the frame clock exposes the first sample after each deadline.

    4 ms samples (stamps rounded to ns as on the wire), 120 Hz: one frame per deadline k / 120, on
    the first sample at or after it, so 120 frames per simulated second; a clock started late (a
    camera joining after the simulator) picks the same samples from its first deadline on.
    """
    samples = np.round(np.arange(0, 2000) * 0.004 * 1e9) * 1e-9
    clock = cm.FrameClock(120.0)
    frames = np.array([t for t in samples if clock.due(t)])
    deadlines = np.arange(len(frames)) / 120.0
    assert np.all(frames >= deadlines - 1e-9) and np.all(frames - deadlines < 0.004 - 1e-9)
    assert len(frames) == int(np.floor(samples[-1] * 120)) + 1
    late = cm.FrameClock(120.0)
    late_frames = np.array([t for t in samples[501:] if late.due(t)])
    np.testing.assert_array_equal(late_frames[1:], frames[frames > late_frames[0]])
    with pytest.raises(ValueError, match='rate'):
        cm.FrameClock(0.0)


def test_a_ball_just_past_the_border_renders():
    """
    Check that a ball just past the border renders.

    Its box is clipped to a pixel or two at the image's edge (a hand camera at the end of a session
    looked there): every position of the ball's rim from 20 px outside (in ideal pixels: the lens
    moves the image's edge by several) to 3 px inside renders.
    """
    rng = np.random.default_rng(0)
    z = 0.3
    r_px = CAM.fx * R / z
    for rim in np.arange(-20.0, 3.0, 0.25):   # u of the rim's rightmost point, and v of its lowest
        u = rim - r_px
        for C in ([(u - CAM.cx) * z / CAM.fx, 0.0, z], [0.0, (u - CAM.cy) * z / CAM.fy, z]):
            assert cm.render(CAM, C, R, rng, noise_sigma=0.0).shape == (CAM.height, CAM.width)


def test_the_detector_measures_a_render_at_200_mm_on_axis_to_its_resolution():
    """
    Check that the detector measures a render at 200 mm on axis to its resolution.

    Shading, highlight, gradient and textured background, blur and noise: the outline is found
    to 1/50 px (robotenis_vision's test_edges), so the centre is good to that resolution over the
    ball's apparent radius along the line of sight and over f across it, plus 3 standard errors.
    """
    c, resolution = np.array([0.0, 0.0, 0.2]), 0.02
    rng = np.random.default_rng(5)
    dets = [detector.detect(cm.render(CAM, c, R, rng), CAM, R) for _ in range(10)]
    errors = np.array([d.position for d in dets]) - c
    P = np.mean([d.covariance for d in dets], axis=0)
    mean = errors.mean(axis=0)
    tol_along = c[2] * resolution / (CAM.fx * R / c[2])
    tol_across = c[2] * resolution / CAM.fx
    assert abs(mean[2]) < tol_along + 3 * np.sqrt(P[2, 2] / 10)
    assert np.hypot(*mean[:2]) < tol_across + 3 * np.sqrt((P[0, 0] + P[1, 1]) / 10)


def test_the_hand_camera_draws_the_ball_where_the_truths_camera_reads_it():
    """A depth scale and a lens residue in the truth reach the images, as camera_reading says."""
    truth = sim_truth.with_effects(sim_truth.load(), camera_depth_scale=0.004, lens_residue=0.002)
    B = truth.sphere_position
    for C in ([0.0, 0.0, 0.3], [0.1, 0.06, 0.32]):
        P = B - truth.camera_translation - truth.camera_rotation @ np.array(C)
        drawn = hand_camera_node.rendered_centre(truth, P, B)
        np.testing.assert_allclose(drawn, truth.camera_reading(np.array(C)), atol=1e-12)
    # on the axis the detector reads the range 0.4 % long: 1.2 mm at 0.3 m, its bias the same
    # within what it changes over 1.2 mm of range (well under 2 % of the step)
    C = np.array([0.0, 0.0, 0.3])
    seen = [detector.detect(cm.render(CAM, c, R, np.random.default_rng(0), noise_sigma=0.0),
                            CAM, R).position for c in (C, truth.camera_reading(C))]
    assert seen[1][2] - seen[0][2] == pytest.approx(0.004 * 0.3, rel=0.02)
