"""
Benchmark: measuring the sphere in hand-camera images (issues 4 and 13).

Two renderers, one scene list: ``mitsuba_scenes.cached_scene_list(SCENES, SEED)`` draws the paper's
ball (R_B = 19 mm) at 0.15-0.6 m, from the image centre to a corner, lit by point, area and
environment lights from the front, the side and behind, glossy or diffuse, on dark, mid-grey,
gradient, checkered (5-50 px squares) and random-texture backgrounds, in focus or defocused
(0.5-2 px), with sensor noise of 1-3 grey levels and a linear or gamma-2.2 response. Each scene is
rendered by Mitsuba 3 (a physically based renderer this project did not write; cached in
report/mitsuba-cache, so a second run renders nothing) and by the project's own renderer
(robotenis_sim.camera_model, the same geometry, light direction, material class, background
class, blur and noise: ``project_scene``). The detector is told the camera's response (gamma),
as a camera's calibration would.

Figures (issue 13's targets), per renderer and method, against the strong OpenCV baseline
(robotenis_vision.baseline: midpoint threshold, largest round contour, fitEllipse, depth from the
minor semi-axis) measured in the same run:

1. depth bias RMS (target 0.05 % of range) and lateral bias RMS (0.01 %): bias = a scene's mean
   error over repeated frames with fresh noise (the project renderer: FRAMES frames per scene;
   Mitsuba: REPEATS re-renders of the ball's window of the first REPEAT_SCENES scenes, and over
   the whole list the RMS error less the predicted noise), and the three scenes that carry most
   of the model's depth bias RMS, with the RMS over the others (one misread scene can make most
   of it);
2. single-frame precision over the bound: the std of a scene's frames along the line of sight over
   issue 13's closed form sigma_Z = Z^2 sigma_r / (f R), sigma_r = (sigma / C) sqrt(s / (sqrt(pi)
   r)) with the image's own contrast C, noise sigma and blur s (target 1.5x), and over the fit's
   own covariance (the Cramer-Rao bound of its model, whose shading is a nuisance: 1.1-3.3x the
   closed form at 0.15-0.6 m, robotenis_vision.model_fit);
3. NEES about each scene's mean: sum over frames of e^T P^-1 e against chi2(3 (n - 1)), 99 % band;
4. the 3D error per metre of range, median and RMS, and the baseline's over the model's (>= 10x);
5. the failure rate of frames with the whole ball in view (<= 1 %); a detection whose centre's ray
   misses the ball (a pattern's or a shadow's round outline measured instead) is a failure too,
   counted apart ("wrong ball") and kept out of the other figures; and images without a ball
   (each textured background of the list, the ball out of view or, for Mitsuba, taken out of the
   scene): every one must be refused ("no ball" in issue 13's bad input), a ball reported there
   is a false one;
6. speed on one core, 640x480: a stream of frames (each seeded by the last; target < 2 ms) and a
   single image (< 5 ms), and the render time of the project's renderer (< 4 ms);
7. at rest, as the sphere_detector node measures (robotenis_vision.rest.RestCorrection: the conic
   on every frame, the model fit on mean images at 1, 8, 16, 32 frames) against the node before
   it (the model fit seeded on every frame at rest): the model fits' CPU per rest, and the error
   of the mean of a rest's last frames, the part the calibration averages;
8. at rest on Mitsuba: the model fit on the mean of a scene's repeated renders (REST_REPEATS
   more of every scene after the first REPEAT_SCENES, cached too), as the node fits a rest's
   mean image, against the free limb's fit of the same image: the node's limb is known from the
   light on the disc where that agrees with the free limb (robotenis_vision.shading).
"""
import argparse
import os

os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')
os.environ.setdefault('OMP_NUM_THREADS', '1')

import sys  # noqa: E402
import time  # noqa: E402
from unittest import mock  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import cv2  # noqa: E402
import mitsuba_scenes as ms  # noqa: E402
import numpy as np  # noqa: E402
from robotenis_sim import camera_model as cm  # noqa: E402
from robotenis_vision import camera, detector, shading  # noqa: E402
from robotenis_vision.rest import outline_px, RestCorrection  # noqa: E402
from scipy.stats import chi2  # noqa: E402

cv2.setNumThreads(1)
TOP = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CACHE = os.path.join(TOP, 'report', 'mitsuba-cache')
R = 0.019                       # m: the paper's ball radius R_B
CAM = camera.default()          # the project's renderer: with the hand camera's distortion
PINHOLE = camera.Camera(ms.PROJECT_CAMERA.K, np.zeros(5), 640, 480, 'mitsuba')
# the benchmark's list: none of it is in the tests, but the detector's limits have been judged
# on it for many stops; --seed draws another (29, 37 and 41 have been used too: investigations)
SCENES, SEED = 120, 13
FRAMES = 6                      # project renderer: frames per scene
REPEAT_SCENES, REPEATS = 10, 10  # Mitsuba: scenes rendered again, and how often
REST_REPEATS = 7                # ... and the others, for their means at rest (section 8)
METHODS = ('model', 'conic', 'baseline')
TARGET_DEPTH_BIAS, TARGET_LATERAL_BIAS = 0.05, 0.01         # % of range
TARGET_PRECISION, TARGET_RATIO, TARGET_FAILURES = 1.5, 10.0, 1.0
TARGET_STREAM_MS, TARGET_SINGLE_MS, TARGET_RENDER_MS = 2.0, 5.0, 4.0
# std, range (mm), 50 samples: the paper's Table 2
OUT_OF_VIEW = np.array([3.0, 0.0, 0.5])   # m: a ball centre far outside the camera's view
TABLE2 = {'X': (0.014, 0.059), 'Y': (0.038, 0.163), 'Z': (0.092, 0.497)}


def verdict(ok):
    return 'met' if ok else 'NOT met'


def project_scene(scene):
    """
    Return the ball's centre and cm.render's arguments for a scene of mitsuba_scenes.

    The same ball, light direction (toward a point or area light, or an environment's bright
    pole; a constant environment is ambient light), glossy or diffuse ball (a Blinn-Phong
    highlight whose exponent follows the roughness), background pattern and levels (albedo to
    grey), blur (the thin lens's disc, the background's own), noise and response. Brightness: the
    ball's diffuse plus ambient at the scene's target grey, a fill or an environment's floor as
    ambient.
    """
    c = np.asarray(scene['ball']['center_m'], dtype=float)
    light, exposure, material = scene['light'], scene['exposure'], scene['material']
    target = exposure['target_grey']
    specular, shininess = 0.0, 30.0
    if material['type'] == 'glossy':
        specular = 0.5 * target
        shininess = float(np.clip(2 / material['alpha'] ** 2 - 2, 10, 400))
    if light['type'] == 'env' and light['profile'] == 'constant':
        lighting = cm.Lighting(direction=(0.0, 0.0, -1.0), ambient=0.9 * target, diffuse=0.0,
                               specular=0.0)
    else:
        if light['type'] == 'env':
            d = np.asarray(light['bright_direction'])
            ambient = target * (0.25 + 0.5 * light['low'])
        else:
            d = np.asarray(light['position_m']) - c
            ambient = target * (0.05 + light['fill'])
        lighting = cm.Lighting(direction=tuple(d / np.linalg.norm(d)), ambient=ambient,
                               diffuse=target - ambient, specular=specular, shininess=shininess)
    return c, {'lighting': lighting, 'background': _background(scene), 'blur_sigma': 0.0,
               'defocus_px': scene['blur']['radius_px'],
               'noise_sigma': scene['noise']['sigma_grey'], 'gamma': exposure['gamma']}


def _background(scene):
    bg = scene['background']
    k = 300.0 if scene['light'].get('direction') == 'back' else 220.0   # lit from behind: bright
    common = {'texture': 0.0, 'defocus_px': scene['blur']['background_radius_px'],
              'seed': int(scene['seed'] % 1000)}
    if bg['type'] in ('dark', 'grey'):
        return cm.Background(low=k * bg['albedo'], high=k * bg['albedo'], **common)
    low, high = k * bg['albedo_low'], k * bg['albedo_high']
    if bg['type'] == 'gradient':
        return cm.Background(low=low, high=high, angle=np.radians(bg['angle_deg']), **common)
    if bg['type'] == 'checker':
        return cm.Background(pattern='checker', low=low, high=high, square_px=bg['square_px'],
                             phase_px=tuple(bg['phase_px']), **common)
    return cm.Background(pattern='noise', low=low, high=high, scale_px=bg['scale_px'], **common)


def closed_form_bound(det, c):
    """
    Return issue 13's closed-form std of the range (m) for the image a detection came from.

    sigma_r = (sigma / C) sqrt(s / (sqrt(pi) r)), sigma_Z = Z^2 sigma_r / (f R), with the model
    fit's own estimate of the image's noise sigma, blur s (edge spread, pixel included) and the
    median step C from background to limb around the outline.
    """
    extra = det.extra
    if 'step' not in extra:
        return np.nan
    d = np.linalg.norm(c)
    r = CAM.fx * R / d
    sigma_r = extra['noise'] / extra['step'] * np.sqrt(extra['psf_sigma'] / (np.sqrt(np.pi) * r))
    return d * d * sigma_r / (CAM.fx * R)


class Tally:
    """Errors of one method on one renderer: per scene, frames of (error, covariance, bound)."""

    def __init__(self):
        self.scenes, self.failed, self.frames, self.reasons, self.wrong = {}, 0, 0, {}, 0
        self.failures = []         # (key, reason) of every failed frame

    def add(self, key, c, det):
        self.frames += 1
        if not isinstance(det, str) and wrong_ball(det.position, c):
            # not this ball (a pattern, a shadow): a failure, kept out of the error figures
            self.wrong += 1
            det = "wrong ball: its centre's ray misses the ball"
        if isinstance(det, str):
            self.failed += 1
            self.failures.append((key, det))
            reason = det.split(':')[0][:60]
            self.reasons[reason] = self.reasons.get(reason, 0) + 1
            return
        self.scenes.setdefault(key, (c, []))[1].append(
            (det.position - c, det.covariance, closed_form_bound(det, c)))

    def commonest(self, n=3):
        """Return the n commonest reasons of the failures, as 'count x reason; ...'."""
        top = sorted(self.reasons.items(), key=lambda kv: -kv[1])[:n]
        return '; '.join(f'{k} x {r}' for r, k in top)


def wrong_ball(position, c):
    """Return whether a measured centre is another ball's: its ray misses the true ball."""
    u = np.asarray(position) / np.linalg.norm(position)
    return bool(np.linalg.norm(np.cross(u, c)) > R)


def split(e, c):
    """Return the error along the line of sight to c (+ too far) and across it (2,), m."""
    u = c / np.linalg.norm(c)
    a = np.cross(u, [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    return e @ u, np.array([e @ a, e @ np.cross(u, a)])


def attempt(image, cam, method, gamma=1.0, prior=None):
    """Return a detection, or the reason there is none (a string)."""
    try:
        return detector.detect(image, cam, R, method, prior, gamma)
    except detector.DetectionError as e:
        return str(e)


def summarise(name, tallies):
    """Print the figures of every method of one renderer; return them for the verdicts."""
    print(f'   {name}: per method, over the scenes measured (bias = RMS over scenes of the '
          "scene's mean error; % of range)")
    print('   method     depth bias  lateral bias  precision/bound  /own cov  NEES (99 % band)'
          '     3D error mm/m: median   RMS   failed (of which wrong ball)')
    out = {}
    for method, t in tallies.items():
        f = figures(t)
        out[method] = f
        band = f['nees_band']
        print(f"   {method:9s}  {f['depth_bias']:8.3f}    {f['lateral_bias']:8.4f}      "
              f"{f['precision']:6.2f}        {f['own']:6.2f}   {f['nees']:8.0f} "
              f"({band[0]:.0f}-{band[1]:.0f})   {f['median']:10.2f} {f['rms']:7.2f}   "
              f'{t.failed}/{t.frames} ({t.wrong})')
    for method, t in tallies.items():
        if t.reasons:
            print(f'   {method} failures: {t.commonest()}')
    return out


def figures(t):
    """Compute the bias, precision, NEES and error figures of a Tally."""
    depth_b, lat_b, prec, own, err3, nees_by_scene = [], [], [], [], [], {}
    for key, (c, frames) in t.scenes.items():
        d = np.linalg.norm(c)
        E = np.array([f[0] for f in frames])
        err3.extend(np.linalg.norm(E, axis=1) / d * 1e3)
        parts = [split(e, c) for e in E]
        along = np.array([p[0] for p in parts])
        across = np.array([p[1] for p in parts])
        n = len(E)
        P = np.mean([f[1] for f in frames], axis=0)
        u = c / d
        pred_along = np.sqrt(u @ P @ u)
        if n > 1:
            # bias: the mean less the noise it still carries (n frames)
            depth_b.append(max(along.mean() ** 2 - along.var(ddof=1) / n, 0.0) / d ** 2)
            lat_b.append(max(np.sum(across.mean(axis=0) ** 2)
                             - np.sum(across.var(axis=0, ddof=1)) / n, 0.0) / d ** 2)
            sd = along.std(ddof=1)
            # only the model fit states its Fisher bound
            bounds = [f[2] for f in frames if np.isfinite(f[2])]
            if bounds:
                prec.append(sd / np.mean(bounds))
            own.append(sd / pred_along)
            dev = E - E.mean(axis=0)
            nees_by_scene[key] = (float(np.einsum('ni,ij,nj->', dev, np.linalg.pinv(P), dev)),
                                  3 * (n - 1))
        else:
            depth_b.append(max(along[0] ** 2 - pred_along ** 2, 0.0) / d ** 2)
            lat_b.append(max(np.sum(across[0] ** 2) - (np.trace(P) - pred_along ** 2), 0.0)
                         / d ** 2)
    err3 = np.array(err3) if err3 else np.array([np.nan])
    nees, dof, band = nees_sum(nees_by_scene.values())
    return {'depth_bias': 100 * np.sqrt(np.mean(depth_b)) if depth_b else np.nan,
            'lateral_bias': 100 * np.sqrt(np.mean(lat_b)) if lat_b else np.nan,
            'precision': np.median(prec) if prec else np.nan,
            'own': np.nanmedian(own) if own else np.nan,
            'nees': nees if dof else np.nan, 'nees_band': band,
            'median': float(np.median(err3)), 'rms': float(np.sqrt(np.mean(err3 ** 2))),
            'failures': 100 * t.failed / max(t.frames, 1),
            'depth_bias_median': 100 * np.sqrt(np.median(depth_b)) if depth_b else np.nan,
            'depth_bias_within': (int(np.sum(np.sqrt(depth_b) <= TARGET_DEPTH_BIAS / 100)),
                                  len(depth_b)),
            'depth_bias_by_scene': dict(zip(t.scenes, np.sqrt(depth_b))),
            'nees_by_scene': nees_by_scene}


def project_renderer(scenes):
    print(f"1. the project's renderer: {len(scenes)} scenes x {FRAMES} frames with fresh noise "
          '(robotenis_sim.camera_model, hand camera with distortion)')
    rng = np.random.default_rng(13)
    tallies = {m: Tally() for m in METHODS}
    t0 = time.time()
    for k, scene in enumerate(scenes):
        c, kw = project_scene(scene)
        for _ in range(FRAMES):
            image = cm.render(CAM, c, R, rng, **kw)
            for m in METHODS:
                tallies[m].add(scene['id'], c, attempt(image, CAM, m, kw['gamma']))
        if (k + 1) % 20 == 0:
            print(f'   ... {k + 1} scenes ({time.time() - t0:.0f} s)', flush=True)
    return summarise('project renderer', tallies)


def empty_images(scenes, renderer):
    """
    Count, per method, the balls reported on the list's textured backgrounds without a ball.

    ``renderer``: 'project' (robotenis_sim.camera_model, the ball out of view) or 'mitsuba' (the
    scene without its ball, at its first render's exposure; cached like the others).
    """
    textured = [s for s in scenes if s['background']['type'] not in ('dark', 'grey')]
    rng = np.random.default_rng(4)
    false = {m: [] for m in METHODS}
    for scene in textured:
        if renderer == 'project':
            _, kw = project_scene(scene)
            image, cam, gamma = cm.render(CAM, OUT_OF_VIEW, R, rng, **kw), CAM, kw['gamma']
        else:
            _, truth, _ = ms.cached(scene, CACHE)
            image, cam = ms.cached_empty(scene, truth, CACHE)[0], PINHOLE
            gamma = truth['scene']['exposure']['gamma']
        for m in METHODS:
            if not isinstance(attempt(image, cam, m, gamma), str):
                false[m].append(f"{scene['id']} ({scene['background']['type']})")
    print(f'   no ball in view, {renderer} renderer: {len(textured)} textured backgrounds of the '
          'list (checkered, gradient, random texture), each must be refused; false balls: '
          + ', '.join(f'{m} {len(v)}' for m, v in false.items()))
    print(f"   model's false balls: {', '.join(false['model']) or 'none'}")


def mitsuba_available():
    try:
        import mitsuba  # noqa: F401
    except ImportError:
        return False
    return True


def mitsuba(scenes):
    print(f'2. Mitsuba 3: the same {len(scenes)} scenes, one render each; the first '
          f'{REPEAT_SCENES} rendered {REPEATS} times more (the window around the ball, fresh '
          'sampling and sensor noise)')
    print(f'   cache: {os.path.relpath(CACHE, TOP)} (renders missing from it take about 8 s '
          'each here)')
    tallies = {m: Tally() for m in METHODS}
    t0, rendered = time.time(), 0
    for k, scene in enumerate(scenes):
        image, truth, new = ms.cached(scene, CACHE)
        rendered += new
        c = np.asarray(truth['ball']['center_m'])
        gamma = truth['scene']['exposure']['gamma']
        frames = [image]
        if k < REPEAT_SCENES:
            for j in range(REPEATS):
                frame, new = ms.cached_repeat(scene, image, truth, j, CACHE)
                rendered += new
                frames.append(frame)
        for frame in frames:
            for m in METHODS:
                tallies[m].add(scene['id'], c, attempt(frame, PINHOLE, m, gamma))
        if new or (k + 1) % 20 == 0:
            print(f"   ... scene {scene['id']} ({k + 1}/{len(scenes)}, {rendered} rendered, "
                  f'{time.time() - t0:.0f} s)', flush=True)
    return summarise('Mitsuba', tallies)


def describe(scene):
    """Return a scene's light, ball, background and blur in a few words."""
    light, blur = scene['light'], scene['blur']
    lens = (f"thin lens {blur['radius_px']:.1f} px" if blur['model'] == 'thinlens'
            else 'pinhole')
    return (f"{light['type']} light {light.get('direction', '')}, {scene['material']['type']} "
            f"ball, {scene['background']['type']} background, {lens}")


def bias_carriers(name, f, scenes, most=3):
    """
    Print the scenes that carry most of the model's depth bias RMS, and the RMS without them.

    One scene far off (a ball the model misreads) can make most of the RMS over a hundred: what
    the figure is made of tells where the detector needs work.
    """
    by_scene = f['model']['depth_bias_by_scene']
    worst = sorted(by_scene, key=lambda k: -by_scene[k])[:most]
    rest = [b for k, b in by_scene.items() if k not in worst]
    scene = {s['id']: s for s in scenes}
    print(f'   {name}: model depth bias, the {most} largest scenes: '
          + '; '.join(f'{k} {100 * by_scene[k]:.2f} % ({describe(scene[k])})' for k in worst)
          + f'; RMS over the other {len(rest)}: {100 * np.sqrt(np.mean(np.square(rest))):.3f} %')


def nees_sum(parts):
    """Return the NEES and degrees of freedom summed over (nees, dof) parts; their 99 % band."""
    parts = list(parts)
    nees, dof = sum(p[0] for p in parts), sum(p[1] for p in parts)
    return nees, dof, chi2.ppf([0.005, 0.995], dof) if dof else (np.nan, np.nan)


def nees_carriers(name, f, scenes, most=2):
    """
    Print the scenes whose frames carry most of the model's NEES, and the NEES of the others.

    The NEES sums every frame's; a scene whose fit lands on another outline in one frame of six
    (far beyond the covariance the fit states) can put the sum out of its band alone, while the
    covariances of the other scenes are right: the two call for different work.
    """
    by_scene = f['model']['nees_by_scene']
    if not by_scene:
        return
    worst = sorted(by_scene, key=lambda k: -by_scene[k][0])[:most]
    rest = [v for k, v in by_scene.items() if k not in worst]
    scene = {s['id']: s for s in scenes}
    nees, _, band = nees_sum(rest)
    print(f'   {name}: model NEES, the {most} largest scenes: '
          + '; '.join(f'{k} {by_scene[k][0]:.0f} over {by_scene[k][1]} dof '
                      f'({describe(scene[k])})' for k in worst)
          + f'; the other {len(rest)}: {nees:.0f} in ({band[0]:.0f}, {band[1]:.0f})')


def verdicts(name, f):
    model, base = f['model'], f['baseline']
    ratio = base['median'] / model['median']
    print(f'   {name}: model depth bias RMS {model["depth_bias"]:.3f} % of range (target '
          f'<= {TARGET_DEPTH_BIAS}: {verdict(model["depth_bias"] <= TARGET_DEPTH_BIAS)}; '
          f'baseline {base["depth_bias"]:.3f}), lateral {model["lateral_bias"]:.4f} % (target '
          f'<= {TARGET_LATERAL_BIAS}: {verdict(model["lateral_bias"] <= TARGET_LATERAL_BIAS)}; '
          f'baseline {base["lateral_bias"]:.4f})')
    within, scenes = model['depth_bias_within']
    print(f'   {name}: model depth bias over scenes: median {model["depth_bias_median"]:.3f} % '
          f'of range, {within} of {scenes} scenes within {TARGET_DEPTH_BIAS} % (baseline: '
          f'median {base["depth_bias_median"]:.3f} %)')
    print(f'   {name}: model single-frame precision {model["precision"]:.2f}x the closed-form '
          f'bound (median over scenes; target <= {TARGET_PRECISION}: '
          f'{verdict(model["precision"] <= TARGET_PRECISION)}), {model["own"]:.2f}x its own '
          f'covariance (the bound of its model with the shading unknown); NEES '
          f'{model["nees"]:.0f} in ({model["nees_band"][0]:.0f}, {model["nees_band"][1]:.0f}): '
          f'{verdict(model["nees_band"][0] <= model["nees"] <= model["nees_band"][1])}')
    print(f'   {name}: 3D error median {model["median"]:.2f} mm/m (baseline {base["median"]:.2f}'
          f', conic {f["conic"]["median"]:.2f}): baseline / model {ratio:.1f}x (target >= '
          f'{TARGET_RATIO:.0f}x: {verdict(ratio >= TARGET_RATIO)}); failed '
          f'{model["failures"]:.1f} % of frames (target <= {TARGET_FAILURES}: '
          f'{verdict(model["failures"] <= TARGET_FAILURES)}; baseline '
          f'{base["failures"]:.1f} %, conic {f["conic"]["failures"]:.1f} %)')


def at_200mm(frames=60):
    print(f"0. single frames at 200 mm in the image centre ({frames} frames, the hand camera's "
          "default scene), mm, beside the paper's Table 2")
    rng = np.random.default_rng(200)
    c = np.array([0.0, 0.0, 0.2])
    images = [cm.render(CAM, c, R, rng) for _ in range(frames)]
    print('   method   axis    bias     std     RMS  | paper Table 2: std  range')
    for method in ('model', 'conic', 'baseline'):
        E = np.array([d.position - c for d in (attempt(im, CAM, method) for im in images)
                      if not isinstance(d, str)]) * 1e3
        for k, axis in enumerate('XYZ'):
            std, span = TABLE2[axis]
            print(f'   {method:8s}  {axis}  {E[:, k].mean():+8.4f} {E[:, k].std():7.4f} '
                  f'{np.sqrt(np.mean(E[:, k] ** 2)):7.4f} |              {std:.3f}  {span:.3f}')


def timed(fn, items):
    """Return the median wall and the mean CPU seconds per call of fn over items."""
    times, cpu = [], time.process_time()
    for item in items:
        t = time.perf_counter()
        fn(item)
        times.append(time.perf_counter() - t)
    return float(np.median(times)), (time.process_time() - cpu) / len(items)


def speed(scenes):
    print('3. detection time per 640x480 frame on one core, ms (wall median; CPU mean, the figure '
          'least disturbed by other processes)')
    rng = np.random.default_rng(7)
    plain = [s for s in scenes if s['background']['type'] in ('dark', 'grey', 'gradient')][:12]
    textured = [s for s in scenes if s['background']['type'] in ('checker', 'noise')][:12]
    rows = {}
    for label, subset in (('plain backgrounds', plain), ('textured backgrounds', textured)):
        images = []
        for s in subset:
            c, kw = project_scene(s)
            images.append((cm.render(CAM, c, R, rng, **kw), kw['gamma']))
        for m in ('model', 'conic', 'baseline'):
            attempt(images[0][0], CAM, m, images[0][1])
            rows[f'{m}, single image, {label}'] = timed(
                lambda im: attempt(im[0], CAM, m, im[1]), images)
        lone = sum(detector.lone_ball(detector.check_image(im, CAM), CAM, R, 'conic', g)
                   is not None for im, g in images)
        print(f'   {label}: {lone} of {len(images)} images measured without the search '
              '(the ball alone in them)')
    for m in ('conic', 'model'):
        rows[f'{m}, stream'] = stream_time(scenes[:15], m, rng)
    for name, (wall, cpu) in rows.items():
        print(f'   {name:42s} {wall * 1e3:7.2f} {cpu * 1e3:7.2f}')
    return rows


def stream_time(scenes, method, rng, length=9, drift=0.3e-3):
    """
    Time the frames of streams, each seeded by the detection of the frame before.

    A sequence per scene: the ball drifting ``drift`` m per frame (36 mm/s at 120 Hz), fresh
    noise in every frame; the first frame of each is detected cold and not timed.
    """
    times, cpu = [], 0.0
    for s in scenes:
        c, kw = project_scene(s)
        prior = None
        for k in range(length):
            image = cm.render(CAM, c + (k - length // 2) * np.array([drift, -drift / 2, 0.0]),
                              R, rng, **kw)
            t, c0 = time.perf_counter(), time.process_time()
            det = attempt(image, CAM, method, kw['gamma'], prior)
            if k > 0:
                times.append(time.perf_counter() - t)
                cpu += time.process_time() - c0
            prior = None if isinstance(det, str) else det
    return float(np.median(times)), cpu / len(times)


def render_speed():
    print('4. render time per 640x480 frame (robotenis_sim.camera_model.render), ms')
    rng = np.random.default_rng(8)
    cm.render(CAM, [0.0, 0.0, 0.2], R, rng)
    cases = [np.array([0.0, 0.0, z]) for z in (0.15, 0.2, 0.3, 0.6)] * 25
    wall, cpu = timed(lambda c: cm.render(CAM, c, R, rng), cases)

    def floor(_):
        frame = np.full((CAM.height, CAM.width), 100.0, np.float32)
        frame += 2.0 * rng.standard_normal(frame.shape, dtype=np.float32)
        return np.clip(cv2.GaussianBlur(frame, (0, 0), 0.8), 0, 255).astype(np.uint8)

    base = timed(floor, cases[:40])
    # the same ball again: only fresh noise (camera_model._Still), as an emulated rest draws
    still = timed(lambda c: cm.render(CAM, c, R, rng), [cases[1]] * 40)
    print(f'   render: {cpu * 1e3:.2f} ms CPU per frame (target < {TARGET_RENDER_MS:.0f} ms: '
          f'{verdict(cpu * 1e3 < TARGET_RENDER_MS)}); baseline, full-frame noise and blur only: '
          f'{base[1] * 1e3:.2f} ms; the same ball again: {still[1] * 1e3:.2f} ms')


def speed_verdicts(rows):
    """
    Print the speed targets against the node's methods.

    The node runs the conic on every frame, a cold one too (no prior: the ball lost), and the
    model fit only at rest, on mean images (robotenis_vision.rest), as issue 13 allows: the
    targets are the conic's; the model's single image is printed beside them.
    """
    stream = rows['conic, stream'][1] * 1e3
    print(f'   stream (conic, seeded, as the node while the ball moves): {stream:.2f} ms CPU '
          f'(target < {TARGET_STREAM_MS:.0f}: {verdict(stream < TARGET_STREAM_MS)}); model '
          f'seeded (the node at rest): {rows["model, stream"][1] * 1e3:.2f} ms')
    single = {m: [v[1] * 1e3 for k, v in rows.items() if k.startswith(f'{m}, single')]
              for m in ('conic', 'model')}
    print(f'   single image (conic, cold, as the node on a frame without a prior): '
          f"{min(single['conic']):.1f} ms CPU (plain backgrounds) to {max(single['conic']):.1f}"
          f' ms (textured) (target < {TARGET_SINGLE_MS:.0f}: '
          f"{verdict(max(single['conic']) < TARGET_SINGLE_MS)}); model fit, cold (the node "
          f"runs it at rest only): {min(single['model']):.1f}-{max(single['model']):.1f} ms")


def at_rest(scenes, n_scenes=8, rests=2, settle=36, averaged=30, far=0.45):
    """
    Compare the node's rest step with a model fit on every frame, on rests of the scene list.

    The first ``n_scenes`` scenes within ``far`` m, ``rests`` rests each of ``settle`` +
    ``averaged`` frames with fresh noise (the demo's 0.3 s settle and 30 frames at 120 Hz).
    """
    print(f'5. at rest, as the node measures: {rests} rests of {settle + averaged} frames per '
          f"scene, the last {averaged} averaged; the model fits' CPU per rest (ms) and the "
          "average's error (mm, along the line of sight and across it)")
    print('   scene  range | a fit per frame: CPU  along  across | on mean images: fits  CPU  '
          'along  across')
    rng = np.random.default_rng(9)
    rows = []
    near = [s for s in scenes if np.linalg.norm(s['ball']['center_m']) <= far][:n_scenes]
    for k, s in enumerate(near):
        c, kw = project_scene(s)
        for _ in range(rests):
            row = rest_pair(c, kw, rng, settle + averaged, averaged)
            if row is None:
                print(f'   {k:5d}  {np.linalg.norm(c):.3f} | refused (a frame by the conic, or '
                      'the rest by the model fit): left out')
                continue
            rows.append(row)
            print(f'   {k:5d}  {np.linalg.norm(c):.3f} | {row[0] * 1e3:19.0f} {row[1]:+6.3f} '
                  f'{row[2]:7.3f} | {row[6]:19d} {row[3] * 1e3:4.0f} {row[4]:+6.3f} {row[5]:7.3f}'
                  f'  ({100 * row[7]:.0f} % / {100 * row[8]:.0f} % of the frames at rest '
                  'published)')
    if not rows:
        print('   no rest kept')
        return
    a = np.array(rows)
    rms = np.sqrt(np.mean(a[:, [1, 4]] ** 2, axis=0))
    print(f'   {len(a)} rests: model fits {np.median(a[:, 0]) * 1e3:.0f} ms CPU a rest (median) '
          f'on every frame, {np.median(a[:, 3]) * 1e3:.0f} ms on mean images '
          f'({np.median(a[:, 0] / a[:, 3]):.1f}x less); depth error RMS {rms[0]:.3f} and '
          f'{rms[1]:.3f} mm; the two averages {np.sqrt(np.mean((a[:, 4] - a[:, 1]) ** 2)):.3f} mm '
          'RMS apart in depth')


def rest_pair(c, kw, rng, frames, averaged):
    """
    Measure one rest both ways; None if the conic refuses a frame or the model the rest.

    RestCorrection with the model fit on every frame at rest, and on mean images. Returns, for
    each way, the model fits' CPU (s) and the depth and lateral error (mm) of the last
    ``averaged`` frames' mean as published (a frame without the model fit's correction is
    dropped, as the node drops it: the last ``averaged`` published); the number of fits on mean
    images; the share of the frames at rest each way published.
    """
    gamma, cpu, fits = kw['gamma'], [0.0, 0.0], [0, 0]

    def accurate(way):
        def fit(image, seed):
            t = time.process_time()
            try:
                return detector.detect(image, CAM, R, 'model', seed, gamma, search=False)
            finally:
                fits[way] += 1
                cpu[way] += time.process_time() - t
        return fit

    ways = [RestCorrection(0.3, 3, accurate(k), 'model', every_frame=k == 0) for k in (0, 1)]
    prior, measured, still = None, ([], []), [0, 0]
    for _ in range(frames):
        image = cm.render(CAM, c, R, rng, **kw)
        fast = attempt(image, CAM, 'conic', gamma, prior)
        if isinstance(fast, str):
            return None
        prior = fast
        for k, way in enumerate(ways):
            det, _ = way.update(image, fast, outline_px(CAM, fast.position, R))
            if way.switch.still >= way.switch.frames:     # at rest: what the node publishes
                still[k] += 1
                if det is not None:
                    measured[k].append(det.position)
    if not all(len(P) >= averaged for P in measured):
        return None
    errors = []
    for P in measured:
        along, across = split(np.mean(P[-averaged:], axis=0) - c, c)
        errors += [float(along) * 1e3, float(np.linalg.norm(across)) * 1e3]
    return (cpu[0], errors[0], errors[1], cpu[1], errors[2], errors[3], fits[1],
            len(measured[0]) / still[0], len(measured[1]) / still[1])


def mitsuba_at_rest(scenes):
    """
    Compare the node's model fit at rest with the free limb's on Mitsuba's mean images.

    A scene's frames: its render and its repeats (REPEATS for the first REPEAT_SCENES,
    REST_REPEATS for the others); their mean is what the node fits at rest, seeded by the model
    fit of the first frame (as the node seeds each fit of a rest after its first by the fit
    before). The node's fit (detector.detect from that seed) takes the limb's
    shading from the light on the disc where it agrees with the free limb; the same fit with the
    limb left free (shading.fit refusing every disc: the node before) is the baseline.
    """
    print(f"8. at rest on Mitsuba: the mean of each scene's render and its {REPEATS} "
          f'(first {REPEAT_SCENES} scenes) or {REST_REPEATS} repeats, the model fit seeded by the '
          'model fit of the first; depth error, % of range')
    t0, rendered, rows = time.time(), 0, []
    for k, scene in enumerate(scenes):
        image, truth, new = ms.cached(scene, CACHE)
        rendered += new
        frames = [image]
        for j in range(REPEATS if k < REPEAT_SCENES else REST_REPEATS):
            frame, new = ms.cached_repeat(scene, image, truth, j, CACHE)
            rendered += new
            frames.append(frame)
        if new or (k + 1) % 40 == 0:
            print(f"   ... scene {scene['id']} ({k + 1}/{len(scenes)}, {rendered} rendered, "
                  f'{time.time() - t0:.0f} s)', flush=True)
        row = rest_on_mean(frames, truth)
        if row is not None:
            rows.append((scene['id'],) + row)
    if not rows:
        print('   no scene measured at rest')
        return
    ids = [r[0] for r in rows]
    a = np.array([r[1:] for r in rows])
    known = a[:, 2] > 0
    print(f'   {len(a)} scenes (the others refused by a fit): depth error RMS '
          f'{rms_pair(a, "free limb", "as the node")}; the limb known on {known.sum()}: there '
          f'{rms_pair(a[known])}')
    for k in np.argsort(-np.abs(a[:, 1] - a[:, 0]))[:3]:
        print(f'   scene {ids[k]}: free {a[k, 0]:+.3f} %, node {a[k, 1]:+.3f} % '
              f"({'known' if a[k, 2] else 'free'} limb)")


def rms_pair(a, free='free', node='known'):
    """Return 'x % free, y % known': the RMS over rows (free, node, ...) of each; or 'none'."""
    if not len(a):
        return 'none'
    rms = np.sqrt(np.mean(a[:, :2] ** 2, axis=0))
    return f'{rms[0]:.3f} % {free}, {rms[1]:.3f} % {node}'


def rest_on_mean(frames, truth):
    """
    Return a mean image's depth error, % of range, free limb and node, and if its limb was known.

    None where the model fit refuses the first frame or either fit refuses the mean.
    """
    c = np.asarray(truth['ball']['center_m'])
    gamma = truth['scene']['exposure']['gamma']
    mean = np.mean([f.astype(float) for f in frames], axis=0)
    try:
        seed = detector.detect(frames[0], PINHOLE, R, gamma=gamma)
        with mock.patch.object(shading, 'fit', return_value=None):
            free = detector.detect(mean, PINHOLE, R, 'model', seed, gamma, search=False)
        node = detector.detect(mean, PINHOLE, R, 'model', seed, gamma, search=False)
    except detector.DetectionError:
        return None
    along = [100 * split(p - c, c)[0] / np.linalg.norm(c) for p in (free.position, node.position)]
    return along[0], along[1], float(node.extra['limb'] == 'known')


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--seed', type=int, default=SEED,
                        help=f'seed of the scene list (default {SEED}, the benchmark list; '
                        'another draws another list, rendered on first use; 29, 37 and 41 were '
                        'used in docs/investigations.md)')
    parser.add_argument('--scenes', type=int, default=SCENES,
                        help=f'scenes in the list (default {SCENES})')
    parser.add_argument('--project-only', action='store_true',
                        help="the project's renderer alone: sections 1-7 without Mitsuba's "
                        'renders (about 8 s each where report/mitsuba-cache lacks them); the '
                        'scene list still needs its quick contrast previews')
    args = parser.parse_args(argv)
    at_200mm()
    scenes = None
    if mitsuba_available():
        print(f'   (drawing the scene list, seed {args.seed}, {args.scenes} scenes: its contrast '
              'previews render once, then are cached)')
        scenes = ms.cached_scene_list(args.scenes, args.seed, CACHE)
    else:
        print('mitsuba is not installed (benchmarks/requirements.txt): the scene list needs it')
        return 1
    project = project_renderer(scenes)
    empty_images(scenes, 'project')
    if not args.project_only:
        mitsuba_figures = mitsuba(scenes)
        empty_images(scenes, 'mitsuba')
    print('targets (issue 13):')
    verdicts('project renderer', project)
    if not args.project_only:
        verdicts('Mitsuba', mitsuba_figures)
    bias_carriers('project renderer', project, scenes)
    nees_carriers('project renderer', project, scenes)
    if not args.project_only:
        bias_carriers('Mitsuba', mitsuba_figures, scenes)
        nees_carriers('Mitsuba', mitsuba_figures, scenes)
    rows = speed(scenes)
    speed_verdicts(rows)
    render_speed()
    at_rest(scenes)
    if not args.project_only:
        mitsuba_at_rest(scenes)
    return 0


if __name__ == '__main__':
    sys.exit(main())
