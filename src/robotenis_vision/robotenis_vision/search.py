"""
Where the balls are in an image, without a prior: three sources of candidates, then confirmation.

``candidates``: radial-symmetry votes on a shrunk image. The image is shrunk ``Voting.factor``
times (area average: a checkerboard of squares under that many px turns grey); each pixel whose
gradient stands out of the image's noise votes for the centres one radius away along its
gradient, on both sides (the ball's outline may be brighter or darker than its background, and
change along it), for every radius of the working range. The votes of a disc's outline all meet
at its centre at its radius; a straight edge's spread along a line, a square's over a cross,
texture's over everything. Peaks of the votes, normalised by the circumference, are the
candidates: centre and radius to about a shrunk pixel. A candidate inside a bigger one (the
highlight, the terminator on the ball) is dropped. COARSE votes find a ball on a plain
background; on a texture its peak drowns among the texture's.

``sharp_candidates``: FINE votes (half the shrinking, thin edges: one pixel across each, so that a
blurred texture's wide edges do not outvote the ball's sharp outline), ranked by how much of a
circle of one radius a strong edge runs along (``outline_score``, on the whole image's gradient).

``open_discs``: the largest round regions no edge crosses (Canny's edges, their distance
transform): the ball's smooth shading is one, a fine checkerboard's squares are small ones.

``confirm`` then checks a candidate's outline against the sphere of the known radius.
"""
from dataclasses import dataclass

import cv2
import numpy as np

from robotenis_vision import conic, edges

RADIUS_STEP = 1.15             # ratio between the radii voted for
EDGE_SIGMAS = 4.0              # a vote needs a gradient this many noise sigmas strong
OUTER_SUPPORT = 0.4            # of a peak's support an outer ring at its centre needs


@dataclass(frozen=True)
class Voting:
    """How ``candidates`` votes."""

    factor: int                # the image is shrunk this many times
    thin: bool                 # only the gradient's maxima across an edge vote
    min_support: float         # of the circumference (as pixels across it) voting for a peak
    max_edges: int             # gradient pixels that vote, at most (evenly spread)
    most: int                  # candidates returned, at most
    per_radius: int            # of one radius voted for at most (a pattern's are alike)


COARSE = Voting(factor=4, thin=False, min_support=0.15, max_edges=12000, most=24, per_radius=3)
FINE = Voting(factor=2, thin=True, min_support=0.3, max_edges=40000, most=60, per_radius=6)
SHARP = 8                      # FINE candidates kept, best outline_score first
RAYS = 48                      # rays of outline_score and open_discs
ON_OUTLINE_PX = 1.5            # outline_score: a ray's step this close to the common radius
OPEN_DISCS = 4                 # open_discs kept
CANNY_SIGMAS = 3.0             # Canny's low threshold, noise sigmas of the smoothed gradient


@dataclass
class Candidate:
    centre: np.ndarray         # (2,) image pixels
    radius: float              # px
    support: float             # fraction of the circumference whose gradients point at it
    outer: float = 0.0         # px: the largest radius about as well supported (an outer ring)


def _noise(image):
    """Return the pixel noise (grey levels) from horizontal neighbours' differences (robust)."""
    return 1.4826 * np.median(np.abs(np.diff(image, axis=1))) / np.sqrt(2)


def _thin(gx, gy, mag):
    """Return where the gradient magnitude is a maximum across the edge (4 directions)."""
    direction = np.round(np.arctan2(gy, gx) / (np.pi / 4)).astype(int) % 4
    pad = np.pad(mag, 1)
    h, w = mag.shape
    keep = np.zeros(mag.shape, bool)
    for d, (dy, dx) in enumerate(((0, 1), (1, 1), (1, 0), (1, -1))):
        ahead = pad[1 + dy:1 + dy + h, 1 + dx:1 + dx + w]
        behind = pad[1 - dy:1 - dy + h, 1 - dx:1 - dx + w]
        keep |= (direction == d) & (mag >= ahead) & (mag >= behind)
    return keep


def _edges(small, voting):
    """Return the voting pixels: positions (n, 2), unit gradients (n, 2), of a shrunk image."""
    gx = cv2.Sobel(small, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(small, cv2.CV_32F, 0, 1, ksize=3)
    mag = cv2.magnitude(gx, gy)
    # a 3x3 Sobel of white noise sigma has a magnitude of about 4.4 sigma
    strong = mag > max(EDGE_SIGMAS * 4.4 * (_noise(small) + 1e-3), 4.0)
    if voting.thin:
        strong &= _thin(gx, gy, mag)
    ys, xs = np.nonzero(strong)
    m = mag[ys, xs]
    if len(m) > voting.max_edges:     # a texture: every other one (strength would favour it)
        keep = np.linspace(0, len(m) - 1, voting.max_edges).astype(int)
        ys, xs, m = ys[keep], xs[keep], m[keep]
    g = np.stack([gx[ys, xs], gy[ys, xs]], axis=1) / m[:, None]
    return np.stack([xs, ys], axis=1).astype(np.float32), g


def candidates(image, r_min, r_max, voting=COARSE):
    """
    Return the ball candidates of an image (float32) by votes, strongest first.

    ``r_min``, ``r_max``: the radii (px) a ball in the working range can have.
    """
    factor = voting.factor
    h, w = image.shape
    small = cv2.resize(np.asarray(image, dtype=np.float32), (w // factor, h // factor),
                       interpolation=cv2.INTER_AREA)
    sh, sw = small.shape
    radii = np.exp(np.arange(np.log(max(r_min / factor, 2.5)),
                             np.log(r_max / factor) + 1e-9, np.log(RADIUS_STEP)))
    pos, g = _edges(small, voting)
    if len(pos) < 8:
        return []
    # votes: every edge pixel, every radius, both directions along its gradient
    offsets = (radii[None, :, None, None] * np.array([1.0, -1.0])[None, None, :, None]
               * g[:, None, None, :])                                 # (n, R, 2, 2)
    centres = np.rint(pos[:, None, None, :] + offsets).astype(np.int32)
    r_index = np.broadcast_to(np.arange(len(radii))[None, :, None], centres.shape[:3])
    ok = ((centres[..., 0] >= 0) & (centres[..., 0] < sw)
          & (centres[..., 1] >= 0) & (centres[..., 1] < sh))
    flat = (r_index[ok] * sh + centres[..., 1][ok]) * sw + centres[..., 0][ok]
    votes = np.bincount(flat, minlength=len(radii) * sh * sw).reshape(len(radii), sh, sw)
    votes = votes.astype(np.float32)
    support = np.empty_like(votes)
    for k in range(len(radii)):
        # a vote lands within a shrunk pixel of the centre; texture votes everywhere: the local
        # mean (over 9 x 9) is taken off
        near = cv2.blur(votes[k], (3, 3)) * 9
        support[k] = near - cv2.blur(votes[k], (9, 9)) * 9
    # an outline gives about 2 pi r votes per shrunk pixel across it, and the 3x3 Sobel makes
    # about 2 pixels across it vote (thinned: 1)
    support /= 2 * np.pi * radii[:, None, None] * (1.0 if voting.thin else 2.0)
    peak = support == cv2.dilate(support.max(axis=0), np.ones((3, 3), np.uint8))[None]
    k, ys, xs = np.nonzero(peak & (support >= voting.min_support))
    order = np.argsort(-support[k, ys, xs])
    # a pattern repeats (a checkerboard's squares all vote alike at one radius), a ball does not:
    # at most per_radius candidates of each radius voted for
    rank = np.empty(len(order), int)
    for j in np.unique(k):
        at = order[k[order] == j]
        rank[at] = np.arange(len(at))
    order = order[rank[order] < voting.per_radius][:voting.most]
    found = []
    for i in order:
        centre = (np.array([xs[i], ys[i]], dtype=float) + 0.5) * factor - 0.5
        r = radii[k[i]] * factor
        if any(np.linalg.norm(centre - c.centre) < max(c.outer, r) for c in found):
            continue                              # inside (or around) a stronger candidate
        # a shaded ball's terminator can vote at its centre too: the outline may be the outer ring
        box = support[:, max(ys[i] - 1, 0):ys[i] + 2, max(xs[i] - 1, 0):xs[i] + 2]
        here = box.max(axis=(1, 2))
        rings = np.flatnonzero(here >= OUTER_SUPPORT * support[k[i], ys[i], xs[i]])
        found.append(Candidate(centre, float(r), float(support[k[i], ys[i], xs[i]]),
                               float(max(radii[rings.max()] * factor, r))))
    return found


def _rays():
    phi = np.linspace(0, 2 * np.pi, RAYS, endpoint=False)
    return np.stack([np.cos(phi), np.sin(phi)], axis=1)


def gradients(image, sigma=0.7):
    """Return the image's gradient (gx, gy), grey levels per px, smoothed by sigma px (float32)."""
    smooth = cv2.GaussianBlur(image, (0, 0), sigma)
    # the 3x3 Sobel weighs a slope of 1 as 8; scaled inside, no array is made twice
    return (cv2.Sobel(smooth, cv2.CV_32F, 1, 0, ksize=3, scale=0.125),
            cv2.Sobel(smooth, cv2.CV_32F, 0, 1, ksize=3, scale=0.125))


def steep(image, factor=1.0):
    """
    Return where the image is steep enough for ``confirm`` to take a step there (bool, its shape).

    A ray takes a step of at least max(MIN_STEP, 6 sigma) grey levels (sigma the pixel noise)
    whose steepest slope is at least SHARPNESS of it: blurred by at most 1.6 px. Smoothed as
    ``gradients`` does, such a step is still at least 0.23 of it steep per px; three quarters of
    that is the threshold (times ``factor``, for steeper edges). Noise reaches it at single pixels
    (the smoothed gradient's noise is 0.22 sigma a component, the threshold 4.6 of those or
    more): an edge is a chain of them (detector.LONE_CHAIN).
    """
    gx, gy = gradients(image)
    threshold = 0.75 * 0.23 * max(MIN_STEP, 6 * _noise(image[::4, ::2]))
    return cv2.magnitude(gx, gy) > factor * threshold


def outline_score(gx, gy, centre, r):
    """
    Return how well a strong edge runs along one circle about ``centre``: 0 for none.

    Along RAYS rays from the centre, the steepest radial step between 0.75 and 1.5 r (px); the
    rays whose step lies within ON_OUTLINE_PX (or 5 %) of their median radius are on one circle:
    their fraction times their median step (grey levels per px). A ball's outline is a strong
    edge at one radius all round; a texture's blob is softer, and its edge wanders.
    """
    u = _rays()
    rho = np.arange(0.75 * r, 1.5 * r + 0.5, 0.5)
    pts = np.asarray(centre, dtype=float) + rho[None, :, None] * u[:, None, :]   # (rays, K, 2)
    mx, my = pts[..., 0].astype(np.float32), pts[..., 1].astype(np.float32)
    ax = cv2.remap(gx, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    ay = cv2.remap(gy, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    radial = np.abs(ax * u[:, None, 0] + ay * u[:, None, 1])
    k = np.argmax(radial, axis=1)
    at, step = rho[k], radial[np.arange(RAYS), k]
    common = np.median(at)
    on = np.abs(at - common) <= max(ON_OUTLINE_PX, 0.05 * common)
    return float(on.mean() * np.median(step[on])) if on.any() else 0.0


def sharp_candidates(image, r_min, r_max, n=SHARP):
    """Return the n FINE vote candidates whose outline_score is highest, best first."""
    found = candidates(image, r_min, r_max, FINE)
    gx, gy = gradients(image)
    score = [outline_score(gx, gy, c.centre, c.radius) for c in found]
    return [found[i] for i in np.argsort(score)[::-1][:n]]


def open_discs(image, r_min, r_max, n=OPEN_DISCS):
    """
    Return the n largest round regions that no edge crosses, as candidates (largest first).

    Canny's edges (thresholds from the image's noise) and their distance transform: a local
    maximum rho within the working range is a disc of radius rho free of edges. It is round when
    the edge lies near rho all round: the fraction of RAYS rays that meet an edge within 1.1 rho
    (1 for a disc, about 0.6 for a square); candidates are ranked by rho times that fraction.
    """
    noise = _noise(image[::2, ::2]) + 0.5             # at least the 8-bit rounding's
    low = CANNY_SIGMAS * 2.2 * noise                  # about 5 sigmas of the smoothed Sobel
    smooth = cv2.GaussianBlur(np.clip(image, 0, 255).astype(np.uint8), (0, 0), 1.0)
    edge = cv2.Canny(smooth, low, 2 * low, L2gradient=True) > 0
    dt = cv2.distanceTransform((~edge).astype(np.uint8), cv2.DIST_L2, 5)
    peak = ((dt == cv2.dilate(dt, np.ones((5, 5), np.uint8)))
            & (dt >= 0.8 * r_min) & (dt <= 1.1 * r_max))
    ys, xs = np.nonzero(peak)
    biggest = np.argsort(dt[ys, xs])[::-1][:100]
    u = _rays()
    h, w = edge.shape
    ranked = []
    for y, x in zip(ys[biggest], xs[biggest]):
        rho = float(dt[y, x])
        steps = np.arange(0.0, 1.5 * rho + 3, 0.5)
        px = np.clip(np.rint(x + u[:, :1] * steps), 0, w - 1).astype(int)
        py = np.clip(np.rint(y + u[:, 1:] * steps), 0, h - 1).astype(int)
        hit = edge[py, px]
        first = np.where(hit.any(axis=1), steps[hit.argmax(axis=1)], np.inf)
        round_ = np.mean(first <= 1.1 * rho + 1.5)
        ranked.append((rho * round_, Candidate(np.array([x, y], dtype=float), rho, round_, rho)))
    ranked.sort(key=lambda t: -t[0])
    return [c for _, c in ranked[:n]]


@dataclass
class Sphere:
    """A candidate confirmed by its outline: the sphere whose outline most rays agree on."""

    c: np.ndarray              # (3,) optical frame, m
    score: float               # fraction of the rays with an outline point on its outline
    points: np.ndarray         # (k, 2) those points, ideal pixels
    candidate: Candidate


RAY_SPACING_PX = 3.0
PEAKS_PER_RAY = 3
INLIER_PX = 1.0
TRIALS = 160
SHARPNESS = 0.25               # 1/px: steepest slope over step of a sharp edge
MIN_STEP = 8.0                 # grey levels


def _ray_peaks(image, camera, centre_ideal, radius, outer):
    """
    Return up to PEAKS_PER_RAY sharp steps per ray from a candidate's centre, ideal pixels.

    The rays span 0.6 of the candidate's radius to 1.3 of its outer ring's.
    Points (rays, PEAKS_PER_RAY, 2) and their strengths (|slope|, 0 where a ray has fewer). A
    step counts when it is sharp: its steepest slope is at least SHARPNESS times the step across
    it (the difference of the means 1.5-4.5 px on either side), as a lens-blurred outline is and
    a smooth texture, further away and out of focus, is not; and when that step stands out of the
    noise.
    """
    lo, hi = 0.6 * radius, 1.3 * max(outer, radius)
    radius, half = 0.5 * (lo + hi), max(6.0, 0.5 * (hi - lo)) + 5.0
    n = int(np.clip(2 * np.pi * radius / RAY_SPACING_PX, 24, 120))
    phi = np.linspace(0, 2 * np.pi, n, endpoint=False)
    normals = np.stack([np.cos(phi), np.sin(phi)], axis=1)
    s = np.arange(-half, half + edges.STEP / 2, edges.STEP)
    profiles, inside = edges.sample_profiles(image, centre_ideal + radius * normals, normals, s,
                                             camera.distort_pixels)
    d = np.diff(profiles, axis=1) / edges.STEP
    a = np.abs(d)
    pad = np.pad(a, ((0, 0), (1, 1)), constant_values=-1.0)
    peak = (a >= pad[:, :-2]) & (a > pad[:, 2:])
    noise = _noise(profiles[:, ::2]) + 1e-6
    # the step across each sample: means over 1.5-4.5 px beyond it on either side
    c = np.cumsum(np.pad(profiles, ((0, 0), (1, 0))), axis=1)
    k0, k1 = int(round(1.5 / edges.STEP)), int(round(4.5 / edges.STEP))
    j = np.arange(a.shape[1])
    lo_a, lo_b = np.clip(j - k1, 0, None), np.clip(j - k0, 0, None)
    hi_a, hi_b = np.clip(j + 1 + k0, None, profiles.shape[1]), np.clip(j + 1 + k1, None,
                                                                       profiles.shape[1])
    before = (c[:, lo_b + 1] - c[:, lo_a]) / np.maximum(lo_b + 1 - lo_a, 1)
    after = (c[:, hi_b] - c[:, hi_a]) / np.maximum(hi_b - hi_a, 1)
    step = np.abs(after - before)
    usable = (peak & (a >= SHARPNESS * step) & (step > max(MIN_STEP, 6 * noise))
              & (j >= k1) & (j < a.shape[1] - k1))
    strength = np.where(usable, a, 0.0)
    strength[~inside] = 0.0
    top = np.argsort(-strength, axis=1)[:, :PEAKS_PER_RAY]
    rows = np.arange(n)[:, None]
    value = strength[rows, top]
    k = np.clip(top, 1, a.shape[1] - 2)
    y0, y1, y2 = a[rows, k - 1], a[rows, k], a[rows, k + 1]
    den = y0 - 2 * y1 + y2
    offset = k + np.clip(np.where(den < 0, 0.5 * (y0 - y2) / np.where(den < 0, den, -1.0), 0.0),
                         -0.5, 0.5)
    along = radius + s[0] + (offset + 0.5) * edges.STEP
    points = centre_ideal + along[..., None] * normals[:, None, :]
    return points, value


def confirm(image, camera, R, candidate, rng=None):
    """
    Find the sphere whose outline the steep points of most rays from a candidate agree on.

    Each ray offers its few steepest points (the ball's outline, a background edge, a highlight);
    triples of rays, one point each (the stronger the likelier), give spheres of radius R
    (conic.sphere_from_three_rays), and the one most rays agree with within INLIER_PX is refitted
    on those points (Taubin, closed form). None when no sphere is found.
    """
    rng = np.random.default_rng(0) if rng is None else rng
    centre = camera.undistort_pixels(candidate.centre)
    points, value = _ray_peaks(image, camera, centre, candidate.radius, candidate.outer)
    ok = value.sum(axis=1) > 0
    points, value = points[ok], value[ok]
    if len(points) < 12:
        return None
    n = len(points)
    prob = value / value.sum(axis=1, keepdims=True)
    rays = np.argpartition(rng.random((TRIALS, n)), 3, axis=1)[:, :3]
    pick = (rng.random((TRIALS, 3, 1)) > np.cumsum(prob[rays], axis=2)).sum(axis=2)
    pick = np.minimum(pick, PEAKS_PER_RAY - 1)
    xy = camera.to_normalized(points[rays, pick])                       # (T, 3, 2)
    C = conic.sphere_from_three_rays(xy[:, 0], xy[:, 1], xy[:, 2], R)
    good = np.all(np.isfinite(C), axis=1) & (C[:, 2] > R)
    if not np.any(good):
        return None
    C = C[good]
    all_xy = camera.to_normalized(points.reshape(-1, 2))
    dist = np.abs(camera.fx * conic.sampson(all_xy, C, R)).reshape(len(C), n, PEAKS_PER_RAY)
    dist = np.where(value[None] > 0, dist, np.inf)
    hits = (dist.min(axis=2) < INLIER_PX).sum(axis=1)
    best = int(np.argmax(hits))
    near = dist[best].argmin(axis=1)
    inl = dist[best, np.arange(n), near] < INLIER_PX
    if inl.sum() < 8:
        return None
    chosen = points[np.arange(n), near][inl]
    try:
        c = conic.sphere_from_conic(conic.taubin(camera.to_normalized(chosen)), R)
    except conic.ConicError:
        c = C[best]
    return Sphere(c, float(inl.sum() / len(ok)), chosen, candidate)
