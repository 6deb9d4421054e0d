"""
detect() on images of an independent OpenCV renderer (simple_render, not robotenis_sim's).

Tolerances: an outline point is found to RESOLUTION_PX = 1/50 px on noise-free blurred discs
(test_edges), so a noise-free centre is good to that over the ball's apparent radius along the line
of sight, and over the focal length across it; with noise, the scatter is what the detection's
covariance predicts (chi-square) and the mean is within that resolution plus 3 standard errors.
"""
import numpy as np
import pytest
from robotenis_vision import camera as camera_model_vision
from robotenis_vision import detector, model_fit, search
from robotenis_vision.detection import Detection
from robotenis_vision.detector import DetectionError
from scipy.stats import chi2
import simple_render

R = 0.019                       # m: the paper's ball radius R_B
RESOLUTION_PX = 0.02
CAM = camera_model_vision.default()


def split(error, c):
    """Error components along the line of sight and across it (m)."""
    u = c / np.linalg.norm(c)
    along = error @ u
    perpendicular = error - np.outer(np.atleast_1d(along), u).reshape(np.shape(error))
    return along, np.linalg.norm(perpendicular, axis=-1)


def tolerances(c):
    """Resolution-limited error along the line of sight and across it (m)."""
    d = np.linalg.norm(c)
    r_px = CAM.fx * R / d
    return d * RESOLUTION_PX / r_px, d * RESOLUTION_PX / CAM.fx


POSITIONS = [np.array(c) for c in ([0.0, 0.0, 0.2], [0.05, 0.03, 0.2], [0.1, -0.06, 0.3],
                                   [-0.12, 0.09, 0.25], [0.15, 0.08, 0.45], [0.0, 0.0, 0.15])]


@pytest.mark.parametrize('c', POSITIONS)
def test_noise_free_independent_render_is_measured_to_the_resolution(c):
    det = detector.detect(simple_render.render(CAM, c, R), CAM, R)
    along, across = split(det.position - c, c)
    tol_along, tol_across = tolerances(c)
    assert abs(along) < tol_along and across < tol_across


@pytest.mark.parametrize('c', [POSITIONS[1], POSITIONS[3]])
def test_scatter_and_bias_with_noise_match_the_covariance(c):
    rng = np.random.default_rng(11)
    runs = 25
    dets = [detector.detect(simple_render.render(CAM, c, R, rng, noise_sigma=2.0), CAM, R)
            for _ in range(runs)]
    errors = np.array([d.position for d in dets]) - c
    P = np.mean([d.covariance for d in dets], axis=0)
    spread = errors - errors.mean(axis=0)
    total = np.einsum('ni,ij,nj->', spread, np.linalg.inv(P), spread)
    dof = 3 * (runs - 1)
    assert chi2.ppf(0.0005, dof) < total < chi2.ppf(0.9995, dof)
    along, across = split(errors.mean(axis=0), c)
    u = c / np.linalg.norm(c)
    sd_along = np.sqrt(u @ P @ u / runs)
    sd_across = np.sqrt(max(np.trace(P) - u @ P @ u, 0) / runs)
    tol_along, tol_across = tolerances(c)
    assert abs(along) < tol_along + 3 * sd_along
    assert across < tol_across + 3 * sd_across


@pytest.mark.parametrize('c', [POSITIONS[1], POSITIONS[4]])
def test_a_prior_from_the_last_frame_gives_the_same_centre(c):
    """
    Seed the detection with the previous frame's, as the node's stream does.

    The outline is looked for where the previous frame's sphere was (the ball moved half a pixel
    since) and the sphere refined from it, to the same resolution as from scratch; a prior 30 px
    off falls back to the search.
    """
    image = simple_render.render(CAM, c, R)
    moved = c + np.array([0.5, -0.3, 0.0]) * c[2] / CAM.fx
    prior = detector.detect(simple_render.render(CAM, moved, R), CAM, R)
    tol_along, tol_across = tolerances(c)
    far = detector.Detection(c + np.array([30.0, 0.0, 0.0]) * c[2] / CAM.fx, prior.covariance,
                             prior.edge_points, 0.0, 'conic', dict(prior.extra))
    for seed in (prior, far):
        along, across = split(detector.detect(image, CAM, R, prior=seed).position - c, c)
        assert abs(along) < tol_along and across < tol_across


def septic(u):
    """Return the 4-5-6-7 polynomial of a point-to-point move at u in [0, 1]."""
    return 35 * u ** 4 - 84 * u ** 5 + 70 * u ** 6 - 20 * u ** 7


def test_a_moving_ball_is_followed_by_its_prior_moved_at_its_velocity():
    """
    Follow a ball on a 4-5-6-7 move at 120 frames/s, as the node's stream does.

    The move (60, 40, 40 mm in 0.4 s from 0.25 m, up to 6 px a frame) takes the outline out of the
    reach of a prior left where it was; moved at the velocity of the two last detections, each
    frame's prior finds it without a search (search=False raises otherwise), within the
    resolution.
    """
    c0, move = np.array([-0.03, -0.02, 0.25]), np.array([0.06, 0.04, 0.04])
    duration, dt = 0.4, 1 / 120
    times = np.arange(0.0, duration + dt / 2, dt)
    track, left_behind = [], 0
    for t in times:
        c = c0 + move * septic(t / duration)
        image = simple_render.render(CAM, c, R)
        if len(track) < 2:
            det = detector.detect(image, CAM, R, 'conic')
        else:
            try:
                detector.detect(image, CAM, R, 'conic', track[-1][1], search=False)
            except DetectionError:
                left_behind += 1
            det = detector.detect(image, CAM, R, 'conic',
                                  detector.moved_prior(CAM, track[-2:], t), search=False)
        along, across = split(det.position - c, c)
        tol_along, tol_across = tolerances(c)
        assert abs(along) < tol_along and across < tol_across, t
        track.append((t, det))
    assert left_behind > len(times) / 2


def test_a_ball_that_left_its_priors_outline_is_found_near_it_without_a_search(monkeypatch):
    """Prior 8 px off (a frame or more missed): found from there (_near), not by find()."""
    c = POSITIONS[2]
    prior = detector.detect(simple_render.render(CAM, c, R), CAM, R, 'conic')
    off = detector.Detection(c + np.array([6.4, 4.8, 0.0]) * c[2] / CAM.fx, prior.covariance,
                             prior.edge_points, 0.0, 'conic', dict(prior.extra))
    image = simple_render.render(CAM, c, R)
    with pytest.raises(DetectionError):
        detector.detect(image, CAM, R, 'conic', off, search=False)

    def no_search(*args):
        raise AssertionError('the whole image was searched')
    monkeypatch.setattr(detector, 'find', no_search)
    along, across = split(detector.detect(image, CAM, R, 'conic', off).position - c, c)
    tol_along, tol_across = tolerances(c)
    assert abs(along) < tol_along and across < tol_across


def test_a_prior_is_moved_only_by_a_recent_velocity_of_a_visible_move():
    c = POSITIONS[2]
    det = detector.detect(simple_render.render(CAM, c, R), CAM, R, 'conic')
    step = np.array([2.0, 0.0, 0.0]) * c[2] / CAM.fx     # 2 px a frame
    before = detector.Detection(det.position - step, det.covariance, det.edge_points, 0.0,
                                'conic', dict(det.extra))
    moved = detector.moved_prior(CAM, ((0.0, before), (0.01, det)), 0.02)
    np.testing.assert_allclose(moved.position, det.position + step, atol=1e-12)
    assert moved.extra == det.extra
    tiny = detector.Detection(det.position - step / 10, det.covariance, det.edge_points, 0.0,
                              'conic', {})
    for track, t in ((((0.0, before), (0.01, det)), 0.01 + 2 * detector.TRACK_GAP),
                     (((0.0, before), (2 * detector.TRACK_GAP, det)), 0.11),
                     (((0.0, tiny), (0.01, det)), 0.02),
                     (((0.01, det),), 0.02)):
        assert detector.moved_prior(CAM, track, t) is det


def test_a_previous_frames_noise_levels_settle_the_weights_to_the_same_centre():
    """
    At rest the model fit starts from the frame before's noise levels (the node's stream).

    With its weights settled from the first step it reaches the centre a fit from the same start
    finds on its own (weighted by this frame's own noise levels, which differ from the frame
    before's by their sampling error) to a quarter of that centre's standard deviation, which adds
    at most 6 % to a frame's variance; the free limb's fit (model_fit.fit) in no more iterations.
    """
    rng = np.random.default_rng(5)
    c = POSITIONS[2]
    before, image = (simple_render.render(CAM, c, R, rng, noise_sigma=2.0) for _ in range(2))
    prior = detector.detect(before, CAM, R)
    cold = detector.measure(image.astype(np.float32), CAM, R, 'model', prior.position,
                            prior.extra['psf_sigma'])
    warm = detector.detect(image, CAM, R, prior=prior)
    e = warm.position - cold.position
    assert e @ np.linalg.solve(cold.covariance, e) < 0.25 ** 2
    start = (image.astype(np.float32), CAM, R, prior.position, prior.extra['psf_sigma'])
    assert (model_fit.fit(*start, noise_levels=prior.extra['noise_levels']).iterations
            <= model_fit.fit(*start).iterations)


def test_paper_method_on_axis_is_exact_and_baseline_runs():
    """
    On the axis the chords are diameters and eqs. 12/16 are exact.

    Each of the four crossings is good to the resolution plus the sag of the outline polygon
    between points (spacing^2 / 8 r).
    """
    c = POSITIONS[0]
    image = simple_render.render(CAM, c, R)
    paper = detector.detect(image, CAM, R, 'paper')
    along, across = split(paper.position - c, c)
    r_px = CAM.fx * R / np.linalg.norm(c)
    sag = detector.RAY_SPACING ** 2 / (8 * r_px)
    tol_along, tol_across = ((RESOLUTION_PX + sag) / RESOLUTION_PX * t for t in tolerances(c))
    assert abs(along) < tol_along and across < tol_across and paper.method == 'paper'
    base = detector.detect(image, CAM, R, 'baseline')
    assert base.method == 'baseline' and abs(base.position[2] - c[2]) < 0.1 * c[2]
    # a search candidate whose centre lies off the image is refused, not a crash of OpenCV
    with pytest.raises(DetectionError, match='not in the image'):
        detector.measure(image.astype(np.float32), CAM, R, 'baseline',
                         np.array([0.15, 0.075, 0.17]), None)


def test_what_cannot_be_measured_is_refused_with_a_reason():
    blank = np.full((480, 640), 90, np.uint8)
    with pytest.raises(DetectionError, match='no sphere'):
        detector.detect(blank, CAM, R)
    c = np.array([0.13, 0.0, 0.2])
    # the ball reaches past x = 640
    assert CAM.project(c)[0] + CAM.fx * R / 0.2 > CAM.width
    cut = simple_render.render(CAM, c, R)
    with pytest.raises(DetectionError, match='border'):
        detector.detect(cut, CAM, R)
    with pytest.raises(DetectionError, match='does not match'):
        detector.detect(np.zeros((240, 320), np.uint8), CAM, R)
    with pytest.raises(DetectionError, match='2-D'):
        detector.detect(np.zeros((480, 640, 3), np.uint8), CAM, R)
    with pytest.raises(ValueError, match='method'):
        detector.detect(blank, CAM, R, 'hough')


def test_one_blob_found_at_two_sizes_is_one_ball():
    """
    The search's spheres of one blob at two sizes are one ball, not two (never 'ambiguous').

    Shading (a highlight's ring, a terminator) gives the search a second sphere at the ball's place
    whose size, hence depth, is wrong; it must be merged with the ball, while two balls side by
    side stay two.
    """
    c = np.array([0.05, -0.02, 0.35])
    assert detector._same_ball(CAM, c, 1.3 * c, R)
    assert detector._same_ball(CAM, c, c + [0.004, 0.003, -0.05], R)
    beside = c + [2.5 * R, 0.0, 0.0]
    assert not detector._same_ball(CAM, c, beside, R)
    assert not detector._same_ball(CAM, c, 1.3 * beside, R)


def test_a_mark_on_a_ball_is_not_a_ball_of_its_own():
    """
    A bright round mark on a nearer ball (a highlight, a pattern) is not measured as the ball.

    Measured as a ball of the known radius, the mark reads 2-4 times too far; a ball hides what
    lies behind its disc, so a sphere two thirds the size or less seen on a bigger one's disc is
    dropped (detector._on_ball). 12 placements of the ball and of a mark at half its radius from
    its centre, a quarter of its size on the image.
    """
    rng = np.random.default_rng(3)
    c = np.array([0.02, -0.01, 0.25])
    assert detector._on_ball(CAM, 3 * c, c, R) and not detector._on_ball(CAM, c, 3 * c, R)
    beside = 3 * (c + [2.5 * R, 0.0, 0.0])
    assert not detector._on_ball(CAM, beside, c, R)
    for _ in range(12):
        ball = np.array([rng.uniform(-0.05, 0.05), rng.uniform(-0.03, 0.03),
                         rng.uniform(0.2, 0.3)])
        image = simple_render.render(CAM, ball, R, ball=150.0).astype(np.float32)
        direction = rng.normal(size=2)
        spot = ball + np.append(0.5 * R * direction / np.linalg.norm(direction), -0.8 * R)
        mark = 3.0 * np.linalg.norm(ball) * spot / np.linalg.norm(spot)
        image = simple_render.on_background(CAM, mark, R, image, rng, ball=230.0)
        error = detector.detect(image, CAM, R).position - ball
        assert np.linalg.norm(error) < 0.01 * np.linalg.norm(ball)


def test_a_model_fit_started_a_few_pixels_off_follows_the_outline_to_the_ball():
    """
    From a search's sphere 4 px off and a third too small, the fit follows the outline to the ball.

    It is made again around its own outline until that stops moving (REFITS): the annulus it is
    fitted on is cut around its start.
    """
    rng = np.random.default_rng(5)
    c = np.array([0.03, 0.02, 0.3])
    image = simple_render.render(CAM, c, R, rng, noise_sigma=2.0)
    start = 1.4 * c + [0.0025 * 1.4, 0.0, 0.0]
    assert np.linalg.norm(CAM.project(start) - CAM.project(c)) > 3.5
    det = detector.measure(detector.check_image(image, CAM), CAM, R, 'model', start, None)
    along, across = split(det.position - c, c)
    sd = np.sqrt(np.linalg.eigvalsh(det.covariance).max())
    assert abs(along) < 5 * sd and across < 5 * sd


def test_without_search_a_ball_not_where_the_prior_says_is_an_error_not_another_ball():
    c = np.array([0.0, 0.0, 0.3])
    image = simple_render.render(CAM, c, R)
    prior = detector.detect(simple_render.render(CAM, c + [0.05, 0.0, 0.0], R), CAM, R, 'conic')
    assert np.allclose(detector.detect(image, CAM, R, 'model', prior).position, c, atol=1e-3)
    with pytest.raises(DetectionError):
        detector.detect(image, CAM, R, 'model', prior, search=False)
    with pytest.raises(ValueError, match='search=False needs a prior'):
        detector.detect(image, CAM, R, 'model', search=False)


def shadowed(c, rng, cut=0.25):
    """
    Return an image of the ball at c with its side beyond ``cut`` radii left of its centre dark.

    That side is lost in the background (a dark side on a dark background): 209 deg of the
    outline show an edge.
    """
    lit = simple_render.render(CAM, c, R, rng, noise_sigma=2.0)
    dark = simple_render.render(CAM, c, R, rng, ball=80.0, noise_sigma=2.0)
    u, r = CAM.project(c)[0], CAM.apparent_radius(c, R)
    return np.where(np.arange(CAM.width)[None, :] < u - cut * r, dark, lit)


def test_a_ball_with_its_edge_on_less_of_its_outline_is_followed_from_the_frame_before():
    """
    Seed each frame of a half-shadowed ball with the frame before's conic, as the node does.

    Its edge shows on about 58 % of the outline in every frame, below PRIOR_MIN_FRACTION: the
    prior's own fraction sets what is needed, so the seeded frame is measured there (no search),
    within the chi-square bound of its covariance.
    """
    rng = np.random.default_rng(3)
    c = POSITIONS[2]
    first = detector.detect(shadowed(c, rng), CAM, R, 'conic')
    assert first.extra['edge_fraction'] < detector.PRIOR_MIN_FRACTION
    moved = c + np.array([0.5, -0.3, 0.0]) * c[2] / CAM.fx
    det = detector.detect(shadowed(moved, rng), CAM, R, 'conic', first, search=False)
    e = det.position - moved
    assert e @ np.linalg.solve(det.covariance, e) < chi2.ppf(0.999, 3)


def test_two_balls_found_when_the_model_fit_cannot_view_the_first_return_the_first(monkeypatch):
    """
    By the conic method, two balls found, the model fit failing on the first: no ambiguity check.

    The check needs the model fit's view of the first (its clarity); without one, the ball
    ranked first is returned as the conic measured it, however clear the second is to the model
    fit (on this empty image neither shows a round arc: both rank at 0, in the search's order).
    """
    near, far = np.array([0.05, -0.02, 0.35]), np.array([-0.08, 0.03, 0.4])
    spheres = [search.Sphere(c, 0.9, np.zeros((0, 2)), search.Candidate(CAM.project(c), 20.0,
                                                                        1.0))
               for c in (near, far)]
    monkeypatch.setattr(detector, 'find', lambda img, camera, radius: spheres)

    def measure(img, camera, radius, method, c0, blur, gamma=1.0):
        if method == 'model' and c0 is near:
            raise DetectionError('the ball model misfits the image')
        clear = {'coverage': 2 * np.pi, 'kept': 1.0, 'step': 50.0, 'psf_sigma': 1.0}
        return Detection(np.asarray(c0), 1e-8 * np.eye(3), np.zeros((0, 2)), 0.1, method, clear)

    monkeypatch.setattr(detector, 'measure', measure)
    image = np.zeros((CAM.height, CAM.width), np.uint8)
    det = detector.detect(image, CAM, R, 'conic')
    np.testing.assert_array_equal(det.position, near)
