"""
One function to measure the ball in an image: ``detect(image, camera, radius, method, prior)``.

Methods (all return the sphere centre in the optical frame, m, with a covariance):

* ``'model'`` (default): the image modelled pixel by pixel near the outline (the ball's shading
  with its square-root limb, the blur, a local background) and fitted by Gauss-Newton
  (robotenis_vision.model_fit): the accurate one;
* ``'conic'``: sub-pixel outline points (robotenis_vision.edges), Taubin conic, closed-form centre
  and geometric refinement (robotenis_vision.conic): the fast one;
* ``'paper'``: the same outline points, the paper's tangent lines and ellipse correction
  (robotenis_vision.paper_method, eqs. 9-22); ``'tangent'``: its tangent lines alone (eqs. 9-16);
* ``'baseline'``: a midpoint threshold, the largest round contour, OpenCV's fitEllipse
  (robotenis_vision.baseline).

Without a prior, a ball alone in a plain image (no other edge steep enough for the search to take)
is measured from its rough circle (lone_ball); otherwise the balls are looked for
(robotenis_vision.search): open discs, sharp round outlines and radial-symmetry votes give
candidates, the steep points of rays from each must agree on one sphere of the known radius
(RANSAC); the spheres whose outline shows the longest arc of edge on one ellipse (round_arc: a
checkerboard's square meets its inscribed circle only near four points) are measured; each must
show its edge around MIN_ARC of its outline, and on one ellipse over MIN_ROUND_SHARE of it (a
texture's round blob does not), or over PATTERN_SHARE if its limb is rough or its edge straight or,
measured by an outline method, the model fit refuses it (_pattern); a sphere seen on a bigger
ball's disc is a mark on it (_on_ball), not a ball, and one whose outline runs hidden behind
another's disc lies behind it (_in_front: a ball's shadow). The balls measured are ranked by the
round arc of their measured outline (a search's sphere a few pixels off shows none) times the model
fit's clarity. Two balls measured in the image, each clear to the model fit (its edge around the
outline, its pixels kept: SECOND_BALL), alike (contrast and blur: _alike) and round alike
(SECOND_ROUND), make it ambiguous: it is refused (DetectionError), by every method. With a prior
(the previous frame's Detection), the outline is measured where it was, and the search runs only if
it is not found there.

The outline is measured in ideal (undistorted) pixels, K [x, y, 1] for the ray (x, y, 1): there the
sphere's outline is exactly an ellipse. Frames that cannot be trusted raise DetectionError with
the reason: no ball found, two balls, the ball touching the image border, too little of the
outline with contrast.
"""
from dataclasses import replace

import cv2
import numpy as np

from robotenis_vision import (baseline, conic, edges, highlight, model_fit, paper_method,
                              search, shading)
from robotenis_vision.detection import Detection, DetectionError, RANGE

METHODS = ('model', 'conic', 'paper', 'tangent', 'baseline')
MIN_SCORE = 0.5                # of the rays from a candidate must agree on its sphere
# of the rays a ball lit from the side still shows: its shadowed half can be as dark as the
# background, which leaves the lit half's rays (0.47-0.49 on a bench scene where the marks on
# that ball's terminator scored 0.52-0.63 and were measured as balls 0.4-1.0 m behind it)
HALF_LIT_SCORE = 0.35
MEASURED = 3                   # confirmed spheres measured, best first
MAX_RMS = 2.5                  # model fit: residual RMS over the noise beyond which it misfits
MIN_KEPT = 0.6                 # model fit: of the pixels its robust weights must keep
REFITS, REFIT_PX = 3, 0.5      # model fit: again around its outline if it moved this far
# model fit from a search: from its outline, and from one LARGER_START_PX larger. A fit left
# with its outline inside the ball's (the levels' ramps taking the edge's shoulder) reads the
# ball too far: on benchmarks/vision.py's list, in every frame so left (15, 4-68 mm too far) the
# fit from the larger start found the ball; a fit from one as much smaller did in 10
LARGER_START_PX = 1.5
# the larger start's fit is taken if it costs less than this share of the first's: those 15
# frames' fits cost 1.3-3.2 times the ball's; where the costs were closer, the model's own misfit
# (a defocus disc, a gloss) also moved its minimum, by up to 40 mm (model_fit.scores)
SWITCH_COST = 0.8
MAX_FLIPS = 6                  # sign changes of the edge's step around the outline, at most
# unless its limb varies less than this against its step (ModelFit.limb_variation): the 95th
# percentile of the balls of benchmarks/vision.py's scenes on the project's renderer
MAX_LIMB_VARIATION = 0.3
# a fit that keeps less than MIN_KEPT with a limb this smooth (ModelFit.limb_variation; a
# Lambertian limb leaves 3 % of its shading past order 2) is a ball over a pattern: on scenes
# kept out of the benchmark such balls measured 0.01-0.02, fits in a wrong minimum 0.14-0.76
SMOOTH_LIMB = 0.1
SECOND_BALL = 0.75             # a ball this clear (_clarity) makes a second one ambiguous
SECOND_STEP, SECOND_BLUR = 0.5, 2.0   # and if alike (_alike)
SECOND_ROUND = 0.5             # and round over this much of the first's share
# a ball found by a search shows its edge on one sphere over at least this share of its measured
# outline, when its profiles can tell (_round_on): the balls the model fit reported on the 72
# textured backgrounds of benchmarks/vision.py's list without a ball (the project's renderer)
# showed 0-0.33 (17 of 23 under 0.2), the balls of its frames on those backgrounds 0.24 and more
MIN_ROUND_SHARE = 0.2
# a ball round over no more of its outline than a circle inscribed in a checkerboard's square or
# a texture's blob shows, and whose limb varies more than MAX_LIMB_VARIATION, is a pattern too:
# the balls the model fit reported on the textured backgrounds without a ball (both renderers,
# the benchmark's list and a list kept out of it, seed 29) were round over 0.20-0.35; of the
# balls of those lists' frames, those round under 0.35 had a limb under 0.25, except wrong balls
# (0.24-0.97) and a fit 1.2 px outside the ball (the benchmark's Mitsuba scene 061: 0.51, 6.9 % of
# the range too near)
PATTERN_SHARE = 0.35
# or whose edge turns with its outline over less than this share of its strength (_turning): a
# square's side is straight. On the list kept out of the benchmark (seed 29), of the spheres round
# under PATTERN_SHARE, the squares and a wrong ball turned over 0.13-0.27 of it (Mitsuba) and
# 0.19 (the project's renderer), the balls over 0.60 and more
MIN_TURNING = 0.3
TURNING_SECTORS = 16           # _turning: the outline's sectors, each an edge direction's fit
# _turning: px, the image smoothed before its gradient's direction is read: on a sharp edge (a
# pinhole's, no blur) the pixels' steps run along the pixel grid and the direction follows them
TURNING_BLUR = 1.6
# lone_ball: how far beyond a ball's outline its own edge may still be steep, px: before it is
# measured, (a + b r) for an apparent radius r (a search's sphere can be a few px off, its blur
# unknown); once measured, (a + b s) for its blur s: a Gaussian-blurred step of 255 grey levels
# is steep (search.steep) to 3.4 px out at s = 1 and 5.6 px at s = 2
LONE_MARGIN = (8.0, 0.35)
EDGE_REACH = (3.0, 3.0)
LONE_CHAIN = 10                # px: connected steep pixels that make an edge (_steep_outside)
TEXTURED = 2.0                 # _told: a textured image's edges, times the least steep (steep)
MIN_ARC_MODEL = np.deg2rad(160)  # the model fits the known sphere to a shorter arc
RAY_SPACING = 1.5              # px between profiles along the outline
MIN_EDGE_POINTS = 16
MIN_FRACTION = 0.4             # of the outline's profiles must find the edge with contrast
MIN_ARC = np.deg2rad(200)      # the outline points must cover this much of the outline
BLUR_GUESS = 1.0               # px: the first profiles' blur, before the frame's is estimated
PRIOR_MIN_FRACTION = 0.6       # profiles that must find the edge near a prior's outline
PRIOR_KEEP = 0.8               # or this much of the prior's own fraction, if that was lower
NEAR = 0.5                     # of its apparent radius: how far _near finds a ball it lost
TRACK_GAP = 0.05               # s: detections further apart give no velocity to move a prior by
TRACK_MIN_SHIFT = 0.5          # px: a prior predicted to move less stays where it was
ROUND_FLOOR_PX = 0.1           # round_arc: the profile edge's own bias on a shaded ball, px
# _hidden: of the profiles where a ball's outline crosses another's disc that must find its edge
# for it to be in front; behind (a ball's shadow on a near background, as Mitsuba casts it, is
# as round and as big as the ball) it shows none there: the ball in front is smooth there
HIDDEN = 0.5
HIDDEN_MARGIN_PX = 3.0         # _hidden: how far inside the other's outline a profile must lie


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


def detect(image, camera, radius, method='model', prior=None, gamma=1.0, search=True,
           background=None):
    """
    Measure the sphere of ``radius`` (m) in ``image`` (mono, as the camera gives it): a Detection.

    ``prior``: the Detection of a previous frame of the same scene (a ball at rest, a slow one).
    The outline is then measured where it was (no search): about half the time. If it is not found
    there, the ball is looked for around there (_near), then in the whole image, unless
    ``search`` is False: then the first DetectionError is raised (a refinement of that ball must
    not measure another); the model method from another method's prior: _seeded. ``gamma``: the
    camera's response (grey = 255 (I / 255)^(1 / gamma); 1 for a linear camera), used by the
    model method.
    ``background``: what lies behind the ball (``plate.BackgroundPlate``), for the model method
    measuring the ball where ``prior`` has it (measure).
    """
    if method not in METHODS:
        raise ValueError(f"method: expected one of {', '.join(METHODS)}, got {method!r}")
    if not radius > 0:
        raise ValueError(f'radius: must be positive, got {radius!r}')
    if not gamma > 0:
        raise ValueError(f'gamma: must be positive, got {gamma!r}')
    img = check_image(image, camera)
    if prior is not None and method != 'baseline':
        try:
            return _seeded(img, camera, radius, method, prior, gamma, background)
        except DetectionError:
            if not search:
                raise
        det = _near(img, camera, radius, method, prior.position, gamma)
        if det is not None:
            return det
    elif not search:
        raise ValueError('detect: search=False needs a prior (not with the baseline method)')
    lone = lone_ball(img, camera, radius, method, gamma)
    if lone is not None:
        return lone
    found, failures = [], []
    for sphere in find(img, camera, radius):
        try:
            det = measure(img, camera, radius, method, sphere.c, None, gamma)
        except DetectionError as e:
            failures.append(str(e))
            continue
        if any(_on_ball(camera, det.position, d.position, radius) for d, _ in found):
            continue
        found = [f for f in found if not _on_ball(camera, f[0].position, det.position, radius)]
        if not any(_same_ball(camera, det.position, d.position, radius) for d, _ in found):
            found.append((det, sphere.c))
    if not found:
        if failures:
            raise DetectionError(failures[0])
        raise DetectionError('no sphere: no round outline of a plausible size in the image')
    if len(found) > 1 and method != 'baseline':
        found = _in_front(img, camera, radius, found)
    shares = [_round_on(img, camera, radius, d.position) for d, _ in found]
    # not the baseline's: its outline, a threshold's, lies pixels off the ball's edge, where no
    # profile finds it (so checked, it refused 47 % of benchmarks/vision.py's frames, from 16 %)
    if method != 'baseline' and any(s is None for s in shares):
        found, shares = _told(img, camera, radius, found, shares)
    patterns = [_pattern(img, camera, radius, d, s, gamma)
                for (d, _), s in zip(found, shares)]
    if all(patterns):
        raise DetectionError(f'no ball: {patterns[0]}: a pattern of the background')
    # the baseline's balls are refused all together or not at all (_pattern)
    found = [(d, _arc(camera, radius, d.position, s), c)
             for (d, c), s, p in zip(found, shares, patterns) if not p or method == 'baseline']
    if len(found) == 1:
        return found[0][0]
    views = [_model_view(img, camera, radius, d, c, gamma) for d, _, c in found]
    ranked = sorted(zip(found, views), key=lambda f: -f[0][1] * _clarity(f[1]))
    (top, first), rest = ranked[0], ranked[1:]
    if _clarity(first) >= SECOND_BALL:
        share = _round_share(camera, radius, top)
        second = next((v for f, v in rest if _clarity(v) >= SECOND_BALL and _alike(first, v)
                       and _round_share(camera, radius, f) >= SECOND_ROUND * share), None)
        if second is not None:
            a, b = (camera.project(v.position) for v in (first, second))
            raise DetectionError(f'two balls in view, at pixels ({a[0]:.0f}, {a[1]:.0f}) and '
                                 f'({b[0]:.0f}, {b[1]:.0f}): ambiguous, not measured')
    return top[0]


def _seeded(img, camera, radius, method, prior, gamma, background):
    """
    Measure the ball where a previous frame's Detection ``prior`` has it (measure).

    The model method from another method's prior (the conic's, as a rest's first fit starts):
    where its fit fails, or a fit from an outline LARGER_START_PX larger does not come back to
    it (_comes_back), it fits from the prior's ball as from a search, then from there as from a
    previous frame's model fit (as study.detector_bias measures). The conic's outline can lie
    pixels inside the model's (on a side-lit ball at 0.45 m behind 1.8 px of defocus it read
    40 mm far), and a model fit started there stayed 17-33 mm far on half the frames, some
    within half a pixel of the conic's outline; the fits of the rest after it, each seeded by the
    last, kept it. On 49 frames of benchmarks/vision.py's list within 0.6 m, 4 were fitted again
    so; the probe costs about 25 ms a first fit where it comes back. Where the fit at rest refuses
    what the fit from a search passed (a ball on a texture can keep too few of its pixels from
    one start and enough from the other), the latter stands.
    """
    def at_rest(start):
        return measure(img, camera, radius, method, np.asarray(start.position, dtype=float),
                       start.extra.get('psf_sigma'), gamma, start.extra.get('noise_levels'),
                       start.extra.get('edge_fraction'), background)

    if method != 'model' or prior.method == 'model':
        return at_rest(prior)
    try:
        det = at_rest(prior)
        if _comes_back(img, camera, radius, det, gamma):
            return det
    except DetectionError:
        pass
    searched = measure(img, camera, radius, method, prior.position, None, gamma)
    try:
        return at_rest(searched)
    except DetectionError:
        return searched


def _comes_back(img, camera, radius, det, gamma):
    """
    Return whether a model fit from an outline LARGER_START_PX larger ends within REFIT_PX of det.

    Where the ball's outline lies beyond det's, or det's own fit held it where a plain fit would
    not stay (a highlight's lobe looked for around the conic's ball took a matte ball's own
    shading, 79 grey levels: scene 001 of benchmarks/vision.py read 17 mm far so, a plain fit
    from there 2 mm near), the larger start ends apart. True where that fit cannot be made.
    """
    try:
        larger = model_fit.fit(img, camera, radius, _larger(camera, radius, det.position),
                               det.extra['psf_sigma'], gamma)
    except DetectionError:
        return True
    return max(model_fit.outline_offset(camera, radius, det.position, larger.c)) < REFIT_PX


def _larger(camera, radius, c):
    """Return sphere c moved along its line of sight: its outline LARGER_START_PX larger."""
    r = camera.apparent_radius(c, radius)
    return np.asarray(c, dtype=float) * (r / (r + LARGER_START_PX))


def moved_prior(camera, track, t):
    """
    Return the last detection of ``track`` moved to image time ``t`` at the ball's velocity.

    ``track``: the last detections of consecutive processed frames, ((t0, det0), (t1, det1)) or
    ((t1, det1),), times in s. The prior's profiles find the outline within about a pixel of
    where the prior puts it: a ball moving 2 px between frames failed, and each such frame
    searched the whole image (25-35 times the cost). Moved at constant velocity, a prior is off
    by the acceleration only, a (t - t1)^2. det1 is returned as it is without a det0, when either
    gap exceeds TRACK_GAP (the velocity is out of date) or when the move it predicts is under
    TRACK_MIN_SHIFT px (a ball at rest keeps its prior: the noise of two detections does not move
    it).
    """
    t1, det1 = track[-1]
    if len(track) < 2:
        return det1
    t0, det0 = track[-2]
    if not (0 < t1 - t0 <= TRACK_GAP and 0 < t - t1 <= TRACK_GAP):
        return det1
    c = det1.position + (det1.position - det0.position) * (t - t1) / (t1 - t0)
    if c[2] <= 0 or np.hypot(*(camera.project(c) - camera.project(det1.position))) \
            < TRACK_MIN_SHIFT:
        return det1
    return replace(det1, position=c)


def _near(img, camera, radius, method, c, gamma):
    """
    Look for the ball only around sphere ``c``, whose outline it has left: a Detection or None.

    The rays of search.confirm, cast from where c projects, find a ball up to about half its
    apparent radius away in 6-15 ms, where a search of the whole image takes 80-130 ms (the
    ball found within NEAR of c's apparent radius, else None).
    """
    c = np.asarray(c, dtype=float)
    centre, r = camera.project(c), camera.apparent_radius(c, radius)
    sphere = search.confirm(img, camera, radius, search.Candidate(centre, r, 1.0))
    if sphere is None or np.hypot(*(camera.project(sphere.c) - centre)) > NEAR * r:
        return None
    try:
        return measure(img, camera, radius, method, sphere.c, None, gamma)
    except DetectionError:
        return None


def lone_ball(img, camera, radius, method, gamma):
    """
    Return the ball of an image that shows no other edge, measured without the search, or None.

    The rough circle (edges.rough_circle), confirmed by its rays, is all that the search could
    find when no pixel outside that sphere's outline is steep enough for a ray to take a step
    there (search.steep): no other candidate could be confirmed. That is checked around the
    confirmed sphere's outline widened by LONE_MARGIN (before measuring: a texture fails at
    once), then around the measured outline widened by its blur's reach (EDGE_REACH). The ball
    must also be round over MIN_ROUND_SHARE of its outline, as from the search. None sends the
    image to the search: a plain 640x480 image costs 25-30 ms there.
    """
    try:
        centre, r = edges.rough_circle(img, *_radii(camera, radius))
    except edges.EdgeError:
        return None
    sphere = _confirmed(img, camera, radius, search.Candidate(centre, r, 1.0), MIN_SCORE)
    if sphere is None:
        return None
    steep = search.steep(img)
    margin = LONE_MARGIN[0] + LONE_MARGIN[1] * camera.apparent_radius(sphere.c, radius)
    if _steep_outside(steep, camera, radius, sphere.c, margin):
        return None
    try:
        det = measure(img, camera, radius, method, sphere.c, None, gamma)
    except DetectionError:
        return None
    if (_steep_outside(steep, camera, radius, det.position, _reach(det))
            or _pattern(img, camera, radius, det,
                        _round_on(img, camera, radius, det.position), gamma)):
        return None
    return det


def _told(img, camera, radius, found, shares):
    """
    Return the found balls (and their shares) less those not told from the background's blobs.

    A ball whose outline shows the profiles no edge (round_arc cannot tell: a share of None) is
    kept in a plain image, where nothing else is round (a back-lit ball's edge can be that faint),
    and dropped when the image has edges of its own beyond the ball's outline, TEXTURED times as
    steep as the weakest a ray takes (search.steep): a texture's smooth blob shows no edge either.
    On benchmarks/vision.py's list without a ball, 6 of the 11 false balls of the project's
    renderer and 10 of Mitsuba's 20 showed none; the balls that showed none, 4 of Mitsuba's 120,
    lay on plain backgrounds. At TEXTURED their images' longest edge chain beyond the ball was 0
    px (49 px at 1: path-tracing noise in a bright patch, which the image-wide noise level
    understates), the textured backgrounds' 21 px or more. DetectionError when none is left.
    """
    steep = search.steep(img, TEXTURED)
    kept = [s is not None or not _steep_outside(steep, camera, radius, d.position, _reach(d))
            for (d, _), s in zip(found, shares)]
    if not any(kept):
        raise DetectionError('no ball: the profiles find no edge along the outline measured, and '
                             'the image has edges elsewhere: a blob of the background, not told '
                             'from a ball')
    return ([f for f, k in zip(found, kept) if k], [s for s, k in zip(shares, kept) if k])


def _in_front(img, camera, radius, found):
    """
    Return the found balls (det, c) less those whose outline is hidden behind another's disc.

    Two discs that overlap, neither within the other: the one in front shows its edge where its
    outline crosses the other's disc, the one behind does not (_hidden). A ball hides what lies
    behind it, so the one behind is not a whole ball in view: a ball's own shadow on a close
    background (the benchmark's Mitsuba scenes cast it; a light beside the camera does), or a
    ball partly hidden, whose outline could not be measured whole: two balls that overlap so
    are not refused as ambiguous, the one in front is measured. Before _told and _pattern: a
    disc they would refuse can still hide another.
    """
    c = [d.position for d, _ in found]
    pairs = [(k, j) for k in range(len(c)) for j in range(len(c))
             if k != j and _overlap(camera, radius, c[k], c[j])]
    seen = {k: _edge_seen(img, camera, radius, c[k]) for k in {k for pair in pairs for k in pair}}
    behind = {k for k, j in pairs if seen[k] and seen[j]
              and _hidden(camera, radius, c[k], seen[k], c[j], seen[j])}
    return [f for k, f in enumerate(found) if k not in behind] or found


def _overlap(camera, radius, a, b):
    """Return whether the discs of spheres a and b (m) overlap, neither within the other."""
    pa, pb = camera.project(a), camera.project(b)
    ra, rb = camera.apparent_radius(a, radius), camera.apparent_radius(b, radius)
    return abs(ra - rb) < np.linalg.norm(pa - pb) < ra + rb


def _edge_seen(img, camera, radius, c):
    """Return sphere c's outline (ideal px) and whether each profile finds its edge; () if none."""
    profiled = _profiled(img, camera, radius, c)
    if profiled is None:
        return ()
    pts, _, fit = profiled
    return pts, fit.ok & (np.abs(fit.e) < 3 * fit.sigma_e + 1.0)


def _profiled(img, camera, radius, c):
    """
    Return one profile pass along sphere c's outline (blur estimated): points, normals, fit.

    None when c's outline cannot be laid out (ellipse_points).
    """
    try:
        pts, normals, kappa = ellipse_points(camera, c, radius)
    except DetectionError:
        return None
    fit, _ = edges.profile_edges(img, pts, normals, kappa, _window(camera, c, radius, BLUR_GUESS),
                                 BLUR_GUESS, camera.distort_pixels, refit_blur=True)
    return pts, normals, fit


def _hidden(camera, radius, a, seen_a, b, seen_b):
    """
    Return whether sphere a's outline is hidden behind sphere b's disc (a, b in m).

    ``seen_a``, ``seen_b``: _edge_seen's outline points and edges. Where a's outline runs
    HIDDEN_MARGIN_PX or more inside b's, under HIDDEN of its profiles find its edge, and where
    b's runs inside a's, HIDDEN or more of b's do: b is in front there. Each over MIN_EDGE_POINTS
    / 2 profiles at least, or it cannot tell.
    """
    inside = [_within_outline(camera, radius, other, pts)
              for other, (pts, _) in ((b, seen_a), (a, seen_b))]
    if min(k.sum() for k in inside) < MIN_EDGE_POINTS // 2:
        return False
    return bool(seen_a[1][inside[0]].mean() < HIDDEN <= seen_b[1][inside[1]].mean())


def _within_outline(camera, radius, c, pts):
    """
    Return which ideal pixels lie about HIDDEN_MARGIN_PX or more inside sphere c's outline.

    Inside the outline of the sphere shrunk by that margin over its apparent radius on the axis:
    off the axis the outline is an ellipse larger than that, and the margin up to twice as wide.
    """
    shrunk = radius * max(1.0 - HIDDEN_MARGIN_PX / camera.apparent_radius(c, radius), 0.0)
    rays = np.column_stack([pts, np.ones(len(pts))]) @ np.linalg.inv(camera.K).T
    cone = np.einsum('ni,ij,nj->n', rays, conic.sphere_conic(c, shrunk), rays)
    return (cone > 0) & (rays @ c > 0)


def _pattern(img, camera, radius, det, share, gamma):
    """
    Return why a measured ball is a pattern of the background, or '' if it may be a ball.

    ``share``: of its outline on one sphere (_round_on; None when the profiles cannot tell).
    Under MIN_ROUND_SHARE, unless its edges are round along the sphere they fit (_round_again: a
    ball's outline and its dark limb's rise); or under PATTERN_SHARE with a limb (the model
    fit's, extra 'limb_variation') rougher than MAX_LIMB_VARIATION or an edge that turns with the
    outline over less than MIN_TURNING of it (_turning); a baseline's ball by its share alone. An
    outline method's ball (no limb of its own) round under PATTERN_SHARE is fitted by the model
    too, and is a pattern if the model fit refuses it: on a list kept out of the benchmark (seed
    37) the conic measured a circle on a checkerboard round over 25 % and turning over 52 %,
    which the model fit refused as a misfit. Not by that fit's limb: from the conic's centre it
    read 0.30-0.41 on a ball the model measures (benchmarks/vision.py's scene 011), which cold
    frames then refused.
    """
    if share is None:
        return ''
    if share < MIN_ROUND_SHARE and (det.method == 'baseline'
                                    or not _round_again(img, camera, radius, det.position)):
        return (f'the outline measured lies on one sphere over only {100 * share:.0f} % of it '
                f'(at least {100 * MIN_ROUND_SHARE:.0f} %)')
    # not the baseline's shape: its outline, a threshold's, lies pixels off the ball's edge
    if share >= PATTERN_SHARE or det.method == 'baseline':
        return ''
    if det.method != 'model' and _model_view(img, camera, radius, det, det.position,
                                             gamma) is None:
        return (f'the outline measured lies on one sphere over only {100 * share:.0f} % of it '
                'and the model fit refuses it')
    limb = det.extra.get('limb_variation', 0.0)
    if limb > MAX_LIMB_VARIATION:
        return (f'the outline measured lies on one sphere over only {100 * share:.0f} % of it '
                f'and its inner side varies {limb:.2f} of its step')
    turning = _turning(img, camera, radius, det.position)
    if turning < MIN_TURNING:
        return (f'the outline measured lies on one sphere over only {100 * share:.0f} % of it '
                f'and its edge turns with it over only {100 * turning:.0f} %: straight sides')
    return ''


def _reach(det):
    """Return how far beyond a measured ball's outline its own edge may be steep, px."""
    return EDGE_REACH[0] + EDGE_REACH[1] * det.extra.get('psf_sigma', BLUR_GUESS)


def _steep_outside(steep, camera, radius, c, margin):
    """
    Return whether an edge of ``steep`` pixels lies beyond sphere c's outline widened by margin.

    An edge: LONE_CHAIN connected pixels or more. A sphere is confirmed on the steps of 8 rays or
    more, along an outline of at least 50 px: a chain of steep pixels tens long. Noise alone makes
    steep pixels one to a few together, more where the image is brighter than its median (the
    noise grows with the signal).
    """
    try:
        pts, normals, _ = ellipse_points(camera, c, radius, spacing=4 * RAY_SPACING)
    except DetectionError:
        return True
    polygon = camera.distort_pixels(pts + margin * normals)
    outside = steep.astype(np.uint8)
    cv2.fillPoly(outside, [np.rint(polygon).astype(np.int32)], 0)
    _, labels = cv2.connectedComponents(outside, connectivity=8)
    return bool(np.any(np.bincount(labels[outside > 0])[1:] >= LONE_CHAIN))


def _model_view(img, camera, radius, det, c, gamma):
    """
    Return the model fit's Detection of a found ball, or None if it fails.

    A detection by another method is fitted again from sphere c (m): the search's, or its own.
    """
    if det.method == 'model':
        return det
    try:
        return measure(img, camera, radius, 'model', c, None, gamma)
    except DetectionError:
        return None


def _clarity(view):
    """Return how clearly a model Detection is a ball, 0 to 1: its edge's coverage, pixels kept."""
    if view is None:
        return 0.0
    return view.extra['coverage'] / (2 * np.pi) * view.extra['kept']


def _round_share(camera, radius, found):
    """Return the share of a measured ball's outline on one ellipse (det, round_arc, c): 0 to 1."""
    det, arc, _ = found
    return arc / (2 * np.pi * camera.apparent_radius(det.position, radius))


def _alike(a, b):
    """
    Return whether two model Detections are alike enough for the image to be ambiguous.

    Two balls of one scene stand out of their background alike and are blurred alike by the lens:
    the second one's edge step must be at least SECOND_STEP of the first's and its blur at most
    SECOND_BLUR times the first's (plus half a pixel). A texture's round blob, weaker and softer,
    is not a second ball.
    """
    return (b.extra['step'] >= SECOND_STEP * a.extra['step']
            and b.extra['psf_sigma'] <= SECOND_BLUR * a.extra['psf_sigma'] + 0.5)


def _same_ball(camera, a, b, R):
    """
    Return whether spheres a and b (m) are one blob of the image: a centre inside the other disc.

    Not by their distance in space: a search's sphere of the wrong size at the same place (the
    highlight's ring, the terminator) is far from the right one in depth, yet the same ball.
    """
    radius_px = max(camera.apparent_radius(a, R), camera.apparent_radius(b, R))
    return np.linalg.norm(camera.project(a) - camera.project(b)) < radius_px


def find(img, camera, radius):
    """
    Return the spheres whose outline the image shows, best first (robotenis_vision.search).

    The candidates of robotenis_vision.search (the rough circle of edges.rough_circle first, which
    a clean image gives fastest; then the open discs, the sharp outlines, the coarse votes; less
    any lying within the disc of a bigger one, as a highlight or a shading feature on the ball
    does, which measured as a ball reads it a few times too far) are confirmed by their rays:
    distinct spheres with MIN_SCORE of their rays on the outline, within RANGE of the camera. A
    sphere with only HALF_LIT_SCORE of them (a ball whose shadowed half is as dark as its
    background) is kept in place of the spheres that are marks on its disc: the ball hides what
    lies behind it; and measured if no other sphere is confirmed. The MEASURED with the longest
    round_arc are returned, longest first: the rays' score counts any steep point within a pixel,
    and a checkerboard's square scores as high as the ball.
    """
    r_min, r_max = _radii(camera, radius)
    found = (search.open_discs(img, r_min, r_max) + search.sharp_candidates(img, r_min, r_max)
             + search.candidates(img, r_min, r_max))
    candidates = [c for c in found if not any(_inside(c, v) for v in found)]
    try:
        centre, r = edges.rough_circle(img, r_min, r_max)
        candidates.insert(0, search.Candidate(centre, r, 1.0))
    except edges.EdgeError:
        pass
    spheres, half_lit = [], []
    for cand in candidates:
        sphere = _confirmed(img, camera, radius, cand, HALF_LIT_SCORE)
        if sphere is None:
            continue
        if sphere.score < MIN_SCORE:
            half_lit.append(sphere)
            continue
        # a mark on a ball and the ball are kept apart: the model fit tells them (detect)
        same = [k for k, s in enumerate(spheres) if _same_ball(camera, s.c, sphere.c, radius)
                and not _on_ball(camera, s.c, sphere.c, radius)
                and not _on_ball(camera, sphere.c, s.c, radius)]
        if same:
            if sphere.score > spheres[same[0]].score:
                spheres[same[0]] = sphere
            continue
        spheres.append(sphere)
    spheres = _marks_replaced(camera, radius, spheres, half_lit)
    if len(spheres) > 1:
        arcs = [round_arc(img, camera, radius, s.c) for s in spheres]
        order = sorted(range(len(spheres)), key=lambda k: (-arcs[k], -spheres[k].score))
        spheres = [spheres[k] for k in order]
    return spheres[:MEASURED]


def _radii(camera, radius):
    """Return the least and the most apparent radius (px) of a ball of ``radius`` within RANGE."""
    return camera.fx * radius / RANGE[1], camera.fx * radius / RANGE[0]


def _confirmed(img, camera, radius, candidate, least):
    """
    Return the sphere a candidate's rays confirm (search.confirm), or None.

    A sphere under MIN_SCORE is confirmed again from where it lies (its centre and apparent
    radius), and replaced if that reaches MIN_SCORE: rays from a candidate's centre a few pixels
    off meet the outline aslant and take other steps too (a ball on a checkerboard of the list
    kept out of the benchmark, seed 29: 0.40 of the rays from an open disc 8 px off, 0.82 from
    the sphere they found; two more balls of that list were found only from spheres under
    HALF_LIT_SCORE); a weaker one is left as it was. None unless ``least`` of the rays or more
    agree on it and it lies in front, within RANGE.
    """
    sphere = search.confirm(img, camera, radius, candidate)
    if sphere is not None and sphere.score < MIN_SCORE and sphere.c[2] > radius:
        again = search.confirm(img, camera, radius, search.Candidate(
            camera.project(sphere.c), camera.apparent_radius(sphere.c, radius), 1.0))
        if again is not None and again.score >= MIN_SCORE:
            sphere = again
    if (sphere is None or sphere.score < least or not sphere.c[2] > radius
            or not RANGE[0] <= np.linalg.norm(sphere.c) <= RANGE[1]):
        return None
    return sphere


def _marks_replaced(camera, R, spheres, half_lit):
    """
    Return ``spheres`` with those that are marks on a half-lit ball replaced by that ball.

    Not by one that is the same blob as a sphere left (_same_ball): that sphere, confirmed by
    more rays, is the blob's reading. Without any sphere, the half-lit ones, best first: a ball
    alone whose shadowed half is lost in its background (the model fit's checks then tell it
    from a pattern).
    """
    half_lit = sorted(half_lit, key=lambda s: -s.score)
    if not spheres:
        return half_lit
    for ball in half_lit:
        kept = [s for s in spheres if not _on_ball(camera, s.c, ball.c, R)]
        if (len(kept) < len(spheres)
                and not any(_same_ball(camera, s.c, ball.c, R) for s in kept)):
            spheres = kept + [ball]
    return spheres


def _on_ball(camera, a, b, R):
    """
    Return whether sphere a (m) is a mark on the ball b: b 1.5x its size, a's disc within b's.

    A ball hides whatever lies behind its disc, so a sphere two thirds its size or less seen
    within a bigger ball's disc (as _inside: to 1.1 of its radius) is a mark on that ball (its
    highlight, its terminator, a shading feature), measured as a ball a few times too far; not
    a ball of its own. One that reaches out of the disc may be a ball beside it, whole.
    """
    return _within(camera.project(a), camera.apparent_radius(a, R),
                   camera.project(b), camera.apparent_radius(b, R))


def _inside(small, big):
    """Return whether candidate ``small`` lies within the disc of a candidate 1.5x its size."""
    return _within(small.centre, small.radius, big.centre, big.radius)


def _within(centre_a, ra, centre_b, rb):
    """Return whether disc a (px) lies within disc b, to 1.1 of its radius, b 1.5x a's size."""
    return rb >= 1.5 * ra and np.linalg.norm(centre_a - centre_b) + ra <= 1.1 * rb


def measure(img, camera, radius, method, c0, blur, gamma=1.0, noise_levels=None,
            edge_fraction=None, background=None):
    """
    Measure the sphere whose outline lies near that of sphere c0 (m), by ``method``.

    DetectionError when its edge is not seen around MIN_ARC of the outline, or the fit misfits.
    A ball's edge changes sign (brighter or darker than its background) a few times around it, or
    often on a checkerboard, but its limb stays smooth; a false outline on a pattern changes sign
    all the time and its inner side jumps with the outer one (MAX_FLIPS and MAX_LIMB_VARIATION
    together). ``blur``: a previous frame's (px), or None from a search; then the model is fitted
    from the search's sphere and from one LARGER_START_PX larger (_fit_from_search).
    A specular highlight found on the ball's disc (``highlight.fit``) is taken out of the pixels
    the fit uses: looked for in each image, never taken from a previous frame's fit. At rest the
    fits are made on mean images of more and more frames, and a lobe measured on the rest's first,
    single frame carried its noise into all of them (a ball at 0.415 m read 0.24 mm near on the
    16-frame mean with the first frame's lobe in 8 of 8 noise draws, 0.03-0.10 mm far with the
    mean's own).
    A previous frame's ball is where it was: its fit is not made again (a wrong prior must fail,
    not wander to what lies beside it); its limb's shading is the light's measured on its disc
    where one light explains the disc and the fit agrees with the free limb's (``shading.fit``,
    ``shading.agrees``: the model's free limb term doubles the depth noise at rest), the free
    limb's otherwise (the detection's extra 'limb': 'known' or 'free'). From a previous frame's
    model fit, its ``noise_levels`` settle the robust weights at once (model_fit.fit); its
    ``edge_fraction`` (extra 'edge_fraction' of an outline method's) sets what ``outline`` needs.
    ``background``: a plate of what lies behind the ball (model_fit.fit), for the model fit from a
    previous frame's.
    """
    if method == 'baseline':
        centre = camera.project(c0)
        r = camera.apparent_radius(c0, radius)
        return baseline.detect(img, camera, radius, centre, r)
    if method == 'model':
        limb_shading = 'free'
        if blur is None:                    # from a search: the lobe where the fit ended
            fit = _fit_from_search(img, camera, radius, c0, gamma)
            lobe = highlight.fit(img, camera, fit.c, radius, fit.blur, gamma)
            if lobe is not None:
                fit = model_fit.fit(img, camera, radius, fit.c, fit.blur, gamma, highlight=lobe)
        else:
            lobe = highlight.fit(img, camera, c0, radius, blur, gamma)    # around c0, at rest
            fit = model_fit.fit(img, camera, radius, c0, blur, gamma,
                                noise_levels=noise_levels, highlight=lobe,
                                background=background)
            # the limb's shading from the light on the disc where it explains the limb too
            known = shading.fit(img, camera, radius, c0, blur, gamma, noise_levels, lobe,
                                background)
            if known is not None and shading.agrees(known, fit):
                fit, limb_shading = known, 'known'
        covered = fit.coverage()
        flips = fit.polarity_flips()
        limb = fit.limb_variation()
        if flips > MAX_FLIPS and limb > MAX_LIMB_VARIATION:
            raise DetectionError(f'the outline changes polarity {flips} times and its inner side '
                                 f'varies {limb:.2f} of its step: a pattern of the background, '
                                 'not a ball')
        if covered < MIN_ARC_MODEL:
            raise DetectionError(f'outline seen over only {np.degrees(covered):.0f} deg '
                                 '(low contrast against the background)')
        # the background's model (a level and its slopes per bin) cannot follow a checkerboard's
        # or a texture's edges, and a ball over one keeps less than MIN_KEPT: its fit is trusted
        # if its limb is smooth, as a ball's is; a fit in a wrong minimum has a rough one
        if fit.rms > MAX_RMS or (fit.kept < MIN_KEPT and limb > SMOOTH_LIMB):
            raise DetectionError(f'the ball model misfits the image (residual {fit.rms:.1f} '
                                 f'times the noise, {100 * fit.kept:.0f} % of the pixels kept)')
        edge = ellipse_points(camera, fit.c, radius)[0]
        step = np.abs(fit.levels[:, 2] - fit.levels[:, 0])[fit.edge_bins()]
        return Detection(fit.c, fit.cov, edge, float('nan'), 'model',
                         {'psf_sigma': fit.blur, 'noise': fit.noise, 'coverage': covered,
                          'rms': fit.rms, 'kept': fit.kept, 'iterations': fit.iterations,
                          'step': float(np.median(step)), 'noise_levels': fit.noise_levels,
                          'highlight': lobe, 'limb_variation': limb, 'limb': limb_shading,
                          'plate_share': fit.plate_share})
    ideal, pf, sigma, c_out, fraction = outline(img, camera, radius, c0, blur, edge_fraction)
    xy = camera.to_normalized(ideal)
    weights = 1.0 / np.maximum(pf.sigma_e, 0.02) ** 2      # floored: no point outweighs the rest
    if method in ('paper', 'tangent'):
        c = _conic(xy, ideal, camera, radius, weights, c_out).position
        _check_arc(ideal, camera.to_pixels(c[:2] / c[2]))
        det = paper_method.detect_from_outline(img, camera, radius, xy, sigma,
                                               _window(camera, c, radius, sigma),
                                               0 if method == 'tangent' else None)
    else:
        det = _conic(xy, ideal, camera, radius, weights, c_out)
        _check_arc(det.edge_points, camera.to_pixels(det.position[:2] / det.position[2]))
    det.extra.update(psf_sigma=sigma, edge_fraction=fraction)
    return det


def _fit_from_search(img, camera, radius, c0, gamma):
    """
    Return the model fit of the ball whose outline lies near a search's sphere c0 (m).

    First without the limb's shading, which pulls the outline a pixel or two into place; then
    from there (DetectionError if that fit cannot be made) and from the outline LARGER_START_PX
    larger: a search's radius can be a few pixels off, and a fit started inside the ball's
    outline can stay there. The fit from there is kept unless the other's outline lies apart
    from it and explains the pixels clearly better (model_fit.scores: SWITCH_COST).
    """
    first = model_fit.fit(img, camera, radius, c0, 1.5, gamma, iterations=4, limb=False)
    fit = _refitted(img, camera, radius, first.c, first.blur, gamma)
    try:
        larger = _refitted(img, camera, radius, _larger(camera, radius, first.c), first.blur,
                           gamma)
        if max(model_fit.outline_offset(camera, radius, fit.c, larger.c)) < REFIT_PX:
            return fit
        cost = model_fit.scores(img, camera, radius, [fit, larger], gamma)
    except DetectionError:          # no fit from there, or the two outlines leave the image
        return fit
    return larger if cost[1] < SWITCH_COST * cost[0] else fit


def _refitted(img, camera, radius, c0, blur, gamma):
    """
    Return the model fit from sphere c0, made again from where it ended while it moves.

    A fit whose outline moved REFIT_PX or more is made again (at most REFITS times): its annulus
    was cut around the start, and a start a few pixels off leaves the fit halfway.
    """
    fit = model_fit.fit(img, camera, radius, c0, blur, gamma)
    for _ in range(REFITS):
        if max(model_fit.outline_offset(camera, radius, c0, fit.c)) < REFIT_PX:
            break
        c0 = fit.c
        fit = model_fit.fit(img, camera, radius, c0, fit.blur, gamma)
    return fit


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


def outline(img, camera, radius, c, blur, prior_fraction=None):
    """
    Measure the outline points, in ideal pixels, of the sphere whose outline is near sphere c's.

    Returns the points (n, 2), their edges.ProfileFit, the frame's blur sigma (px), the sphere
    (m) whose outline the profiles were laid along and the fraction of its profiles that found
    the edge. ``blur``: a previous frame's blur (px), kept; None from a search: estimated,
    starting from BLUR_GUESS. From a previous frame, the edge must be found on PRIOR_MIN_FRACTION
    of the outline, or on PRIOR_KEEP of ``prior_fraction``, that frame's fraction, if less: a
    ball whose side in shadow does not stand out of a dark background shows its edge on less of
    its outline in every frame, and would otherwise be searched for again each time.

    The profiles look for the edge within edges.REACH of the predicted outline; when the outline
    found lies near that limit on average, the prediction was off and the profiles are laid again
    along the outline found (at most twice).
    """
    c = np.asarray(c, dtype=float)
    # the blur is the lens's: with a prior of the same scene it is kept
    refit = from_search = blur is None
    blur = BLUR_GUESS if from_search else blur
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
    fraction = float(fit.ok.mean())
    least = PRIOR_MIN_FRACTION
    if prior_fraction is not None:
        least = min(least, PRIOR_KEEP * prior_fraction)
    if not from_search and fraction < least:
        raise DetectionError(f'the outline is not where the prior puts it (its edge found on '
                             f'{100 * fraction:.0f} % of it, {100 * least:.0f} % needed)')
    keep = fit.ok
    points = pts[keep] + fit.e[keep, None] * normals[keep]
    fields = ('e', 'sigma_e', 'contrast', 'rms', 'ok', 'inside')
    return points, edges.ProfileFit(*(getattr(fit, k)[keep] for k in fields)), blur, c, fraction


def round_arc(img, camera, radius, c):
    """
    Return how much of the outline of sphere c (m) shows an edge on one sphere's outline, px.

    One profile pass along c's outline (blur estimated) finds an edge on each profile; a sphere is
    fitted to them (conic.fit_sphere, started from c), and the profiles whose edge lies within
    3 sigma_e + ROUND_FLOOR_PX of its outline give the arc, their share of its circumference. A
    ball's outline is an ellipse wherever it shows an edge; a circle inscribed in a
    checkerboard's square meets the square's sides only near where it touches them (within
    0.35 px over a quarter of the circle at 20 px radius), however strong and sharp they are.
    An arc, not a fraction: the evidence grows with the profiles, and a small blurred square is
    round over more of its outline than a big one. 0 when the profiles cannot tell (_round_on).
    """
    return _arc(camera, radius, c, _round_on(img, camera, radius, c))


def _arc(camera, radius, c, share):
    """Return the arc (px) a ``share`` of sphere c's outline makes; 0 for None (untold)."""
    return 0.0 if share is None else float(2 * np.pi * camera.apparent_radius(c, radius) * share)


def _round_on(img, camera, radius, c):
    """
    Return the share of the profiles along c's outline whose edge lies on one sphere (round_arc).

    None when they cannot tell: fewer than MIN_EDGE_POINTS profiles find an edge (a low contrast,
    a back-lit ball's edge the profiles miss), or no sphere fits them.
    """
    found = _round_fit(img, camera, radius, c)
    return None if found is None else found[0]


def _round_again(img, camera, radius, c):
    """
    Return whether the edges along c's outline are round along the sphere they fit.

    Round: PATTERN_SHARE of the profiles along that sphere's outline or more have their edge on one
    sphere (_round_fit). A ball whose limb is darker than its background (lit from the camera's
    side: the limb at the ambient level, a brighter background) shows two edges a pixel or two
    apart, its outline (down) and its limb's rise (up); profiles centred between them take
    either, and few lie on one sphere: benchmarks/vision.py's scene 045, 0.04-0.16 along the
    outline the model fit measured, 0.76-0.93 along the sphere of the edges they took, the rise.
    """
    first = _round_fit(img, camera, radius, c)
    second = None if first is None else _round_fit(img, camera, radius, first[1])
    return second is not None and second[0] >= PATTERN_SHARE


def _round_fit(img, camera, radius, c):
    """Return _round_on's share and the sphere (m) the edges fit; None when they cannot tell."""
    profiled = _profiled(img, camera, radius, c)
    if profiled is None:
        return None
    pts, normals, fit = profiled
    if fit.ok.sum() < MIN_EDGE_POINTS:
        return None
    xy = camera.to_normalized(pts[fit.ok] + fit.e[fit.ok, None] * normals[fit.ok])
    try:
        sphere = conic.fit_sphere(xy, radius, camera.fx, 1.0 / np.maximum(fit.sigma_e[fit.ok],
                                                                          0.02) ** 2, c)
    except conic.ConicError:
        return None
    on = np.abs(sphere.residuals_px) < 3 * fit.sigma_e[fit.ok] + ROUND_FLOOR_PX
    return on.sum() / len(pts), sphere.c


def _turning(img, camera, radius, c):
    """
    Return the share of the edge's strength along sphere c's outline that turns with it: 0 to 1.

    Across the band of the outline's profiles (_window), each sector of TURNING_SECTORS fits the
    direction of the image's gradient (smoothed by TURNING_BLUR; within 45 deg of the outline's
    normal, mod 180 deg, weighted by its square) against the normal's own: a ball's edge turns
    with its outline (rate 1), a straight edge does not (0), as a square's sides about their
    inscribed circle. The sectors whose rate exceeds a half, their share of the weight. 1 when
    no sector has an edge.
    """
    pts, normals, _ = ellipse_points(camera, c, radius)
    s = np.arange(-1.0, 1.0 + 1e-9, 0.125) * _window(camera, c, radius, BLUR_GUESS)
    normal = (camera.distort_pixels(pts + 0.5 * normals)
              - camera.distort_pixels(pts - 0.5 * normals))
    theta_n = np.unwrap(np.arctan2(normal[:, 1], normal[:, 0]))
    at = camera.distort_pixels((pts[:, None, :] + s[:, None] * normals[:, None, :]).reshape(-1, 2))
    x0, y0 = np.maximum(np.floor(at.min(axis=0)).astype(int) - 4, 0)
    x1, y1 = np.ceil(at.max(axis=0)).astype(int) + 5
    gx, gy = search.gradients(np.ascontiguousarray(img[y0:y1, x0:x1]), TURNING_BLUR)
    mx, my = (at - (x0, y0)).astype(np.float32).T.reshape(2, len(pts), len(s))
    g = [cv2.remap(d, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
         for d in (gx, gy)]
    # the gradient's direction against the normal's, mod pi
    delta = np.angle(np.exp(2j * (np.arctan2(g[1], g[0]) - theta_n[:, None]))) / 2
    weight = (g[0] ** 2 + g[1] ** 2) * (np.abs(delta) < np.pi / 4)
    turning = total = 0.0
    for k in np.array_split(np.arange(len(pts)), TURNING_SECTORS):
        w = weight[k].ravel()
        if w.sum() <= 0:
            continue
        x = np.repeat(theta_n[k] - theta_n[k].mean(), len(s))
        y = delta[k].ravel()
        x, y = x - np.average(x, weights=w), y - np.average(y, weights=w)
        rate = 1 + np.sum(w * x * y) / max(np.sum(w * x * x), 1e-12)
        total += w.sum()
        turning += w.sum() * (rate > 0.5)
    return turning / total if total > 0 else 1.0


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
    r_px = camera.apparent_radius(c, R)
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
