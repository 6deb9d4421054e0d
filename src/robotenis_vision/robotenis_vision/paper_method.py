"""
The calibration paper's method (section 5.2-5.3).

Tangent planes, least squares, ellipse correction.

Coordinates are undistorted normalized ones (x_u / f, y_u / f in the paper's "central image
coordinates"), so alpha = x_u / f and beta = y_u / f directly (eqs. 10, 14).

1. The ellipse centre (x_uc, y_uc) and the outline's crossings with the horizontal and vertical
   lines through it: x_u1 < x_u2 and y_u1 < y_u2. As in the paper they are measured along those
   lines in the image (``image_crossings``: the sub-pixel profile model of robotenis_vision.edges),
   the sub-pixel outline only placing the lines (``chords``).
2. Each crossing is taken as a tangent: the plane x = alpha z (resp. y = beta z) touches the
   sphere, so its distance to the centre is R_B (eqs. 11, 15). With the centre between the two
   planes:

       X_B - alpha_1 Z_B = R_B sqrt(1 + alpha_1^2),
       alpha_2 Z_B - X_B = R_B sqrt(1 + alpha_2^2)                                          (12)
       Y_B - beta_1 Z_B  = R_B sqrt(1 + beta_1^2),
       beta_2 Z_B - Y_B  = R_B sqrt(1 + beta_2^2)                                           (16)

   (the paper numbers alpha_1 on the other side; the pairs are the same): four linear equations in
   (X_B, Y_B, Z_B), solved by least squares.
3. The crossings are not where those planes touch: correct with the ellipse model (eqs. 17-22). The
   angle theta_z of the centre off the optical axis (17) gives the axis ratio b_e = a_e cos theta_z
   (18); theta_r turns the ellipse (19) so that its major axis a_e points away from the principal
   point (Figure 7; with x right, y down that is tan theta_r = -x_uc / y_uc, the paper's eq. 20
   written for its axes); the horizontal half-chord (x_u2 - x_u1) / 2 then gives theta_e and a_e
   (21, 22). The tangent points are the extremes of the ellipse (19) along x and y, which are the
   theta_e = 0, pi/2, pi, 3 pi/2 points when theta_r = 0. Back to step 2 with them; twice, as the
   paper does.
"""
import numpy as np

from robotenis_vision import edges
from robotenis_vision.detection import Detection, DetectionError

ITERATIONS = 2
# normalized (0.1 px at f = 500): how far a polygon side may cut inside the outline
MAX_SAG = 2e-4


class PaperMethodError(ValueError):
    """The outline does not give the crossings the method needs."""


def ordered(xy):
    """Outline points sorted by angle around their mean: a closed polygon."""
    m = xy.mean(axis=0)
    return xy[np.argsort(np.arctan2(xy[:, 1] - m[1], xy[:, 0] - m[0]))]


def crossings(poly, axis, level, max_sag=MAX_SAG):
    """
    Find where the closed polygon crosses the line {axis coordinate = level}.

    Returns the lowest and highest value of the other coordinate (linear between vertices).

    A polygon side of length L cuts inside an outline of radius r by L^2 / 8r; where profiles were
    dropped the side is long, and a crossing on a side cutting in by more than ``max_sag`` would be
    a guess: PaperMethodError.
    """
    a = poly[:, axis] - level
    b = np.roll(poly, -1, axis=0)
    ab = b[:, axis] - level
    hit = (a * ab <= 0) & (a != ab)
    if hit.sum() < 2:
        raise PaperMethodError('the outline does not cross the line through its centre twice')
    t = a[hit] / (a[hit] - ab[hit])
    other = 1 - axis
    values = poly[hit, other] + t * (b[hit, other] - poly[hit, other])
    ends = np.flatnonzero(hit)[[np.argmin(values), np.argmax(values)]]
    radius = np.median(np.linalg.norm(poly - poly.mean(axis=0), axis=1))
    sag = np.sum((b[ends] - poly[ends]) ** 2, axis=1) / (8 * radius)
    if np.any(sag > max_sag):
        raise PaperMethodError('the outline has a gap where the line through its centre '
                               'crosses it')
    return values.min(), values.max()


def chords(xy, max_sag=MAX_SAG):
    """
    Find the centre (x_uc, y_uc) and crossings x_u1, x_u2, y_u1, y_u2 (normalized).

    The centre is moved to the midpoints of the horizontal and vertical chords through it until it
    stays (three passes).
    """
    poly = ordered(xy)
    xc, yc = poly.mean(axis=0)
    for _ in range(3):
        x1, x2 = crossings(poly, 1, yc, max_sag)
        y1, y2 = crossings(poly, 0, xc, max_sag)
        xc, yc = 0.5 * (x1 + x2), 0.5 * (y1 + y2)
    return np.array([xc, yc]), np.array([x1, x2, y1, y2])


def tangent_planes(alpha, beta, R_B):
    """Eqs. 12 and 16 by least squares: (X_B, Y_B, Z_B) from alpha_1 < alpha_2, beta_1 < beta_2."""
    a1, a2 = alpha
    b1, b2 = beta
    A = np.array([[1.0, 0.0, -a1], [-1.0, 0.0, a2], [0.0, 1.0, -b1], [0.0, -1.0, b2]])
    rhs = R_B * np.sqrt(1 + np.array([a1, a2, b1, b2]) ** 2)
    return np.linalg.lstsq(A, rhs, rcond=None)[0]


def corrected_extremes(centre_B, centre_uv, half_chord):
    """Eqs. 17-22: the ellipse's extreme x and y offsets from its centre (normalized units)."""
    X, Y, Z = centre_B
    theta_z = np.arccos(Z / np.sqrt(X * X + Y * Y + Z * Z))                  # (17)
    xc, yc = centre_uv
    # (20), see the module docstring
    theta_r = np.arctan2(-xc, yc) if np.hypot(xc, yc) > 1e-12 else 0.0
    theta_e = np.arctan(-np.tan(theta_r) * np.cos(theta_z))                   # (22)
    a_e = abs(half_chord / (np.cos(theta_z) * np.cos(theta_e) * np.cos(theta_r)
                            - np.sin(theta_e) * np.sin(theta_r)))             # (22)
    b_e = a_e * np.cos(theta_z)                                               # (18)
    # extremes of (19) over theta_e
    half_x = np.sqrt((b_e * np.cos(theta_r)) ** 2 + (a_e * np.sin(theta_r)) ** 2)
    half_y = np.sqrt((b_e * np.sin(theta_r)) ** 2 + (a_e * np.cos(theta_r)) ** 2)
    return half_x, half_y


def centre_from_chords(centre_uv, cross, R_B, iterations=ITERATIONS):
    """
    Compute the paper's sphere centre from the chord crossings.

    Eqs. 12/16, then eqs. 17-22 ``iterations`` times.
    """
    x1, x2, y1, y2 = cross
    B = tangent_planes((x1, x2), (y1, y2), R_B)
    for _ in range(iterations):
        half_x, half_y = corrected_extremes(B, centre_uv, 0.5 * (x2 - x1))
        xc, yc = centre_uv
        B = tangent_planes((xc - half_x, xc + half_x), (yc - half_y, yc + half_y), R_B)
    return B


def paper_centre(cross, R_B, sigma_cross, iterations=ITERATIONS):
    """
    Sphere centre (3,) and its covariance from the crossings x_u1, x_u2, y_u1, y_u2 (normalized).

    The ellipse centre is their midpoints; sigma_cross (4,): their standard deviations
    (normalized), independent, propagated through the method by finite differences.
    """
    cross = np.asarray(cross, dtype=float)

    def estimate(v):
        return centre_from_chords(np.array([0.5 * (v[0] + v[1]), 0.5 * (v[2] + v[3])]), v, R_B,
                                  iterations)

    B = estimate(cross)
    h = 1e-7
    J = np.stack([(estimate(cross + h * e) - estimate(cross - h * e)) / (2 * h)
                  for e in np.eye(4)], axis=1)
    return B, (J * np.asarray(sigma_cross) ** 2) @ J.T


def image_crossings(img, camera, xy, sigma, half_width, passes=2):
    """
    Measure the crossings in the image, as the paper does.

    Along the horizontal and vertical lines through the ellipse centre, by the same sub-pixel
    profile model as the outline (edges.profile_edges).

    xy: outline points (normalized), which place the lines and the first guess (``chords``); each
    pass moves the centre to the new chords' midpoints. Returns the centre, the crossings
    (normalized) and their standard deviations (normalized).
    """
    centre, cross = chords(xy, max_sag=np.inf)
    ideal = camera.to_pixels(xy)
    r_px = np.median(np.linalg.norm(ideal - ideal.mean(axis=0), axis=1))
    normals = np.array([[-1.0, 0.0], [1.0, 0.0], [0.0, -1.0], [0.0, 1.0]])
    for _ in range(passes):
        x1, x2, y1, y2 = cross
        xc, yc = centre
        points = camera.to_pixels(np.array([[x1, yc], [x2, yc], [xc, y1], [xc, y2]]))
        # relative_contrast=0.0: four profiles have no 'typical' step
        fit, _ = edges.profile_edges(img, points, normals, np.full(4, 1 / r_px), half_width, sigma,
                                     camera.distort_pixels, relative_contrast=0.0)
        if not np.all(fit.ok):
            raise PaperMethodError('no edge with contrast where a line through the centre '
                                   'crosses the outline')
        found = camera.to_normalized(points + fit.e[:, None] * normals)
        cross = np.array([found[0, 0], found[1, 0], found[2, 1], found[3, 1]])
        centre = np.array([0.5 * (cross[0] + cross[1]), 0.5 * (cross[2] + cross[3])])
    return centre, cross, fit.sigma_e / np.array([camera.fx, camera.fx, camera.fy, camera.fy])


def detect_from_outline(img, camera, R_B, xy, sigma, half_width, iterations=None):
    """
    Measure a detector.Detection by the paper's method.

    ``iterations`` of the ellipse correction: the paper's two by default, 0 for eqs. 9-16 alone.
    xy: the outline (normalized) that places the lines.
    """
    iterations = ITERATIONS if iterations is None else iterations
    try:
        centre, cross, sigma_cross = image_crossings(img, camera, xy, sigma, half_width)
        B, cov = paper_centre(cross, R_B, sigma_cross, iterations)
    except PaperMethodError as e:
        raise DetectionError(f'paper method: {e}') from None
    points = camera.to_pixels(np.array([[cross[0], centre[1]], [cross[1], centre[1]],
                                        [centre[0], cross[2]], [centre[0], cross[3]]]))
    return Detection(B, cov, points, float('nan'), 'paper' if iterations else 'tangent')
