"""
One function to measure the ball in an image: ``detect(image, camera, radius, method)``.

Methods (all return the sphere centre in the optical frame, m, with a covariance):

* ``'conic'`` (default): sub-pixel outline (robotenis_vision.edges), Taubin conic, closed-form
  centre and geometric refinement (robotenis_vision.conic);
* ``'paper'``: the same outline points, the paper's tangent lines and ellipse correction
  (robotenis_vision.paper_method, eqs. 9-22); ``'tangent'``: its tangent lines alone (eqs. 9-16);
* ``'baseline'``: threshold, OpenCV's fitEllipse, centre back-projected, depth from the apparent
  size (robotenis_vision.baseline).

The outline is measured in ideal (undistorted) pixels, K [x, y, 1] for the ray (x, y, 1): there the
sphere's outline is exactly an ellipse. Profiles are laid out in ideal pixels and sampled at their
distorted image positions (the forward plumb_bob model: no iterative undistortion per point).
Steps: a rough circle in the image, coarse outermost-gradient points on rays from it, a first
sphere from them (RANSAC on triples of rays, then Taubin + closed form), then the profile model
along the normals of that sphere's ellipse, with the blur estimated on the way
(robotenis_vision.edges). Frames that cannot be trusted raise DetectionError with the reason: no
sphere found, the ball touching the image border, too few outline points with contrast, too short
an arc of outline.
"""
import numpy as np

from robotenis_vision import baseline, conic, edges, paper_method
from robotenis_vision.detection import Detection, DetectionError, RANGE

METHODS = ('conic', 'paper', 'tangent', 'baseline')
RAY_SPACING = 1.5              # px between profiles along the outline
MIN_EDGE_POINTS = 16
MIN_FRACTION = 0.4             # of the outline's profiles must find the edge with contrast
MIN_ARC = np.deg2rad(200)      # the outline points must cover this much of the outline
BLUR_GUESS = 1.0               # px: the first profiles' blur, before the frame's is estimated
COARSE_TOLERANCE_PX = 1.0      # coarse (steepest-gradient) outline points agreeing with a sphere
PRIOR_MIN_FRACTION = 0.6       # profiles that must find the edge near a prior's outline


def check_image(image, camera):
    """Return the image as float32 (height, width); DetectionError naming the problem otherwise."""
    if not isinstance(image, np.ndarray) or image.ndim != 2:
        raise DetectionError('image: expected a 2-D mono array, '
                             f'got {getattr(image, "shape", type(image).__name__)}')
    if image.shape != (camera.height, camera.width):
        raise DetectionError(f'image: size {image.shape[1]}x{image.shape[0]} does not match '
                             f'the camera ({camera.width}x{camera.height})')
    if image.dtype.kind not in 'uif':
        raise DetectionError(f'image: expected numbers, got dtype {image.dtype}')
    if image.dtype.kind == 'f' and not np.all(np.isfinite(image)):
        raise DetectionError('image: has values that are not finite')
    return image.astype(np.float32)


def detect(image, camera, radius, method='conic', prior=None):
    """
    Measure the sphere of ``radius`` (m) in ``image`` (mono, as the camera gives it): a Detection.

    ``prior``: the Detection of a previous frame of the same scene (a ball at rest, a slow one).
    Its outline then stands in for the search (rough circle, coarse rays, RANSAC) and its blur for
    the blur estimate: about half the time. If the outline is not found where it says, the search
    is run after all.
    """
    if method not in METHODS:
        raise ValueError(f"method: expected one of {', '.join(METHODS)}, got {method!r}")
    if not radius > 0:
        raise ValueError(f'radius: must be positive, got {radius!r}')
    img = check_image(image, camera)
    if method == 'baseline':
        return baseline.detect(img, camera, radius)
    try:
        ideal, fit, sigma, c0 = outline(img, camera, radius, prior)
    except DetectionError:
        if prior is None:
            raise
        ideal, fit, sigma, c0 = outline(img, camera, radius)
    xy = camera.to_normalized(ideal)
    weights = 1.0 / np.maximum(fit.sigma_e, 0.02) ** 2      # floored: no point outweighs the rest
    if method in ('paper', 'tangent'):
        c = _conic(xy, ideal, camera, radius, weights, c0).position
        _check_arc(ideal, camera.to_pixels(c[:2] / c[2]))
        det = paper_method.detect_from_outline(img, camera, radius, xy, sigma,
                                               _window(camera, c, radius, sigma),
                                               0 if method == 'tangent' else None)
    else:
        det = _conic(xy, ideal, camera, radius, weights, c0)
        _check_arc(det.edge_points, camera.to_pixels(det.position[:2] / det.position[2]))
    det.extra['psf_sigma'] = sigma
    return det


def _conic(xy, ideal, camera, radius, weights, c0):
    """
    Apply the exact method to outline points (normalized xy, ideal pixels).

    The centre is refined from the sphere c0 whose outline they were found along; the covariance
    is inflated for the correlation of neighbouring points' errors (conic.correlation_inflation).
    """
    try:
        sphere = conic.fit_sphere(xy, radius, camera.fx, weights, c0)
    except conic.ConicError as e:
        raise DetectionError(str(e)) from None
    inflation = conic.correlation_inflation(sphere.residuals_px[sphere.inliers])
    return Detection(sphere.c, inflation * sphere.cov, ideal[sphere.inliers], sphere.rms_px,
                     'conic', {'correlation_inflation': inflation})


def search(img, camera, radius):
    """Where the sphere is, without a prior: rough circle, coarse rays, RANSAC sphere (m)."""
    r_min, r_max = camera.fx * radius / RANGE[1], camera.fx * radius / RANGE[0]
    try:
        centre, r = edges.rough_circle(img, r_min, r_max)
    except edges.EdgeError as e:
        raise DetectionError(str(e)) from None
    coarse, _ = edges.radial_edges(img, camera.undistort_pixels(centre), r,
                                   warp=camera.distort_pixels)
    return coarse_sphere(camera.to_normalized(coarse), camera, radius)


def outline(img, camera, radius, prior=None):
    """
    Measure the sphere's outline points in ideal pixels.

    Returns the points (n, 2), their edges.ProfileFit, the frame's blur sigma (px) and the sphere
    (m) whose outline the profiles were laid along.

    The profiles look for the edge within edges.REACH of the predicted outline; when the outline
    found lies near that limit on average, the prediction was off and the profiles are laid again
    along the outline found (at most twice).
    """
    if prior is None:
        c, blur = search(img, camera, radius), BLUR_GUESS
    else:
        c, blur = np.asarray(prior.position, dtype=float), prior.extra.get('psf_sigma', BLUR_GUESS)
    # the blur is the lens's: with a prior of the same scene it is kept
    refit = prior is None
    for attempt in range(3):
        pts, normals, kappa, fit, blur = _profiles(img, camera, c, radius, blur, refit)
        refit = False
        moved = np.mean(np.abs(fit.e[fit.ok]))
        if moved < 0.5 * edges.REACH or attempt == 2:
            break
        xy = camera.to_normalized(pts[fit.ok] + fit.e[fit.ok, None] * normals[fit.ok])
        try:
            c = conic.sphere_from_conic(conic.taubin(xy), radius)
        except conic.ConicError as e:
            raise DetectionError(str(e)) from None
    if moved >= 0.5 * edges.REACH:
        raise DetectionError(f'the outline keeps moving ({moved:.1f} px on average): '
                             'no stable edge')
    if prior is not None and fit.ok.mean() < PRIOR_MIN_FRACTION:
        raise DetectionError('the outline is not where the prior puts it')
    keep = fit.ok
    points = pts[keep] + fit.e[keep, None] * normals[keep]
    fields = ('e', 'sigma_e', 'contrast', 'rms', 'ok', 'inside')
    return points, edges.ProfileFit(*(getattr(fit, k)[keep] for k in fields)), blur, c


def _profiles(img, camera, c, radius, blur, refit_blur):
    """
    Run one profile pass along the outline predicted by sphere c.

    DetectionError if it cannot be trusted.
    """
    pts, normals, kappa = ellipse_points(camera, c, radius)
    window = _window(camera, c, radius, blur)
    fit, blur = edges.profile_edges(img, pts, normals, kappa, window, blur, camera.distort_pixels,
                                    refit_blur=refit_blur)
    if not np.all(fit.inside):
        raise DetectionError('the sphere touches the image border')
    needed = max(MIN_EDGE_POINTS, int(np.ceil(MIN_FRACTION * len(fit.ok))))
    if fit.ok.sum() < needed:
        raise DetectionError(f'only {int(fit.ok.sum())} of {len(fit.ok)} outline points '
                             f'with enough contrast (need {needed})')
    return pts, normals, kappa, fit, blur


def coarse_sphere(xy, camera, radius):
    """
    Find a first sphere from coarse outline points (normalized).

    Robust to the points that caught the highlight or the terminator instead of the limb: RANSAC on
    triples (conic.ransac_sphere).
    """
    if len(xy) < MIN_EDGE_POINTS:
        raise DetectionError(f'no sphere: only {len(xy)} coarse outline points')
    try:
        return conic.ransac_sphere(xy, radius, camera.fx, COARSE_TOLERANCE_PX)[0]
    except conic.ConicError as e:
        raise DetectionError(f'no sphere: {e}') from None


def _window(camera, c, R, sigma):
    """
    Return the profile half-length on each side of the outline, px.

    Three blur sigmas and 2 px, but at most 0.3 of the ball's apparent radius, where the shading is
    still the limb's (not the highlight's).

    The same on both sides: with a short inside and a long outside part the noise pulls the edge
    toward the longer side (0.09 px for 2.5 / 5 px at a contrast of 45 noise sigmas, measured).
    Rounded to the sample step, so that the profile designs repeat (and are cached).
    """
    half = float(np.clip(3 * sigma + 2.0, 3.5, 6.0))
    r_px = camera.fx * R / np.sqrt(c @ c - R * R)
    half = min(half, max(2.5, 0.3 * r_px))
    return float(np.round(half / edges.STEP) * edges.STEP)


def ellipse_points(camera, c, R, spacing=RAY_SPACING):
    """
    Return the outline of sphere (c, R) in ideal pixels.

    Points (n, 2), outward unit normals, curvature (1/px).

    The cone (conic.sphere_conic) meets the image plane in an ellipse; with Q_px = K^-T Q K^-1
    its centre is x0 = -A^-1 b (A, b the quadratic and linear blocks) and
    (x - x0)^T M (x - x0) = 1 with M = A / -(F + b.x0). Points at even parameter t:
    x0 + V (a cos t, b sin t), curvature a b / (a^2 sin^2 t + b^2 cos^2 t)^(3/2).
    """
    if c[2] <= R or c @ c <= R * R:
        raise DetectionError(f'no sphere in front of the camera at {np.round(c, 4).tolist()} m')
    Kinv = np.linalg.inv(camera.K)
    Q = Kinv.T @ conic.sphere_conic(c, R) @ Kinv
    A, b, F = Q[:2, :2], Q[:2, 2], Q[2, 2]
    x0 = -np.linalg.solve(A, b)
    M = A / -(F + b @ x0)
    values, V = np.linalg.eigh(M)
    if np.any(values <= 0):
        raise DetectionError('the sphere is too far off the optical axis to be measured '
                             '(outline not an ellipse)')
    a, bb = 1 / np.sqrt(values)
    perimeter = np.pi * (3 * (a + bb) - np.sqrt((3 * a + bb) * (a + 3 * bb)))     # Ramanujan
    n = int(np.clip(perimeter / spacing, 24, 720))
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    ct, st = np.cos(t), np.sin(t)
    pts = x0 + np.stack([a * ct, bb * st], axis=1) @ V.T
    normals = np.stack([ct / a, st / bb], axis=1) @ V.T
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    kappa = a * bb / (a * a * st * st + bb * bb * ct * ct) ** 1.5
    return pts, normals, kappa


def _check_arc(points, centre):
    """Raise DetectionError unless the points go around enough of the outline (arcs fit weakly)."""
    angles = np.sort(np.arctan2(points[:, 1] - centre[1], points[:, 0] - centre[0]))
    gaps = np.diff(np.concatenate([angles, angles[:1] + 2 * np.pi]))
    covered = 2 * np.pi - gaps.max()
    if covered < MIN_ARC:
        raise DetectionError(f'outline seen over only {np.degrees(covered):.0f} deg '
                             '(low contrast against the background)')
