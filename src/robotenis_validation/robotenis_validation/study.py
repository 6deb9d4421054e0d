"""A static session on the simulated robot and its residual-loop diagnosis, for the studies."""
import numpy as np
from robotenis_calibration import diagnosis, poses
from robotenis_calibration.session import Session
from robotenis_kinematics import synthetic
from robotenis_sim import camera_model, static_session
from robotenis_sim.scenarios import BALL_GUESS_ERROR
from robotenis_vision import camera as vision_camera
from robotenis_vision import detector
from robotenis_vision.plate import BackgroundPlate, NOISE_FLOOR
from robotenis_vision.rest import MOTION_PX, outline_px, RestCorrection, STILL_FRAMES

REST_FRAMES = 12                # frames a session averages at a rest: the demo's
SETTLE_FRAMES = 12              # frames at rest before them: the demo's 0.1 s at 120 Hz


def detector_bias(C, radius, method='model', camera=None, plate=True, **render_options):
    """
    Return what the detector gets wrong (K, 3), m, for balls at true centres C (K, 3, optical).

    Each ball is rendered by the hand camera's renderer without sensor noise (its defaults
    otherwise, or ``render_options`` of camera_model.render: a lighting, a blur) and measured: the
    error left is the detector's bias at that pose, the part that averaging frames at a rest does
    not remove. A refused image gives a row of NaN. The model method's ball is fitted again from
    its detection, as the sphere_detector node fits a rest (the limb known where the light
    explains it, robotenis_vision.shading); ``plate``: with a background plate of the balls
    before it in C (robotenis_vision.plate, the node's ``background_plate``), each added once
    measured.
    """
    camera = camera or vision_camera.default()
    rng = np.random.default_rng(0)
    out = np.full((len(C), 3), np.nan)
    behind = (BackgroundPlate((camera.height, camera.width)) if plate and method == 'model'
              else None)
    for k, c in enumerate(np.asarray(C, dtype=float)):
        image = camera_model.render(camera, c, radius, rng, noise_sigma=0.0, **render_options)
        try:
            det = detector.detect(image, camera, radius, method)
            if method == 'model':
                det = detector.detect(image, camera, radius, method, det, search=False,
                                      background=behind)
        except detector.DetectionError:
            continue
        out[k] = det.position - c
        if behind is not None:      # a noise-free render: its noise is the 8 bits' rounding
            behind.add_ball(image, camera, det.position, radius, NOISE_FLOOR)
    return out


def rest_errors(C, radius, frames=REST_FRAMES, settle=SETTLE_FRAMES, seed=0, camera=None,
                plate=True, **render_options):
    """
    Return the error (K, 3), m, of rests at true centres C (K, 3, optical) as the node measures.

    Each rest is ``settle`` + ``frames`` frames of the still ball at C[k], the robot moving on
    between rests (``replayed_rests`` without times: each rest found by a search); a row is the
    mean of the ``frames`` positions published after the settle, less C[k]: what a session
    averages at that rest. Unlike detector_bias, it carries the frames' noise and the fit's bias
    on mean images of noisy frames, which may differ from its bias on a noise-free render.
    """
    C = np.asarray(C, dtype=float)
    window = np.arange(settle + frames) >= settle
    return replayed_rests([np.tile(c, (settle + frames, 1)) for c in C], [window] * len(C),
                          radius, seed, camera, plate, **render_options)


def replayed_rests(paths, windows, radius, seed, camera=None, plate=True, times=None,
                   **render_options):
    """
    Return the error (K, 3), m, of rests as the sphere_detector node measures them, frame by frame.

    ``paths``: for each rest, the ball's true centres (n_k, 3, optical) in the frames the camera
    took on the way to it and at it; ``windows``: (n_k,) booleans, the frames a session averages
    there. Each frame is rendered by the hand camera's renderer with fresh noise (``seed``;
    ``render_options`` of camera_model.render) and measured by the node's step, offline: the
    conic method seeded by the frames before (detector.moved_prior), corrected at rest by the
    model fit on mean images (rest.RestCorrection with the node's defaults), the fit's
    background plate (``plate``) built from the rests before, in order (the node's outline RMS
    check, which a still ball's detections pass, is left out). ``times``: each path's frame times
    (s), the frames of one continuous stream, as a session's camera took them; None: each rest
    alone, found by a search at its first frame. A row is the mean of the window's published
    positions less the true ones; NaN where one of those frames was not published.
    """
    camera = camera or vision_camera.default()
    rng = np.random.default_rng(seed)
    behind = BackgroundPlate((camera.height, camera.width)) if plate else None

    def accurate(image, start):
        return detector.detect(image, camera, radius, 'model', start, search=False,
                               background=behind)

    def seen(image, det, noise):
        behind.add_ball(image, camera, det.position, radius, noise)

    rest = RestCorrection(MOTION_PX, STILL_FRAMES, accurate, 'model', seen=seen if plate else None)
    out = np.full((len(paths), 3), np.nan)
    track = ()
    for k, (path, window) in enumerate(zip(paths, windows)):
        if times is None:
            rest.lost()                 # the robot moved on: the next rest starts afresh
            track = ()
        # without times, frame numbers: a still ball's prior is not moved (detector.TRACK_GAP)
        stamps = np.arange(len(path)) if times is None else times[k]
        published = []
        for c, t, averaged in zip(np.asarray(path, dtype=float), stamps, window):
            image = camera_model.render(camera, c, radius, rng, **render_options)
            try:
                det = detector.detect(image, camera, radius, 'conic',
                                      detector.moved_prior(camera, track, t) if track else None)
            except detector.DetectionError:
                rest.lost()
                track = ()
                continue
            track = track[-1:] + ((t, det),)
            det, _ = rest.update(image, det, outline_px(camera, det.position, radius))
            if averaged and det is not None:
                published.append(det.position - c)
        if published and len(published) == np.count_nonzero(window):
            out[k] = np.mean(published, axis=0)
    return out


def static_run(truth, declared, n, seed, selection='boundary', guess_error=BALL_GUESS_ERROR,
               images=None, max_range=poses.PLAN_RANGE[1]):
    """
    Run a static session of ``n`` planned poses on ``truth`` and the residual loop on it.

    Returns (session, measurements, diagnosis). The planner knows only the declared description
    and a guess of the ball position that is off by ``guess_error`` (m). ``images``: each rest's
    camera reading is then the truth's plus the error of the rest measured through rendered
    images as the sphere_detector node measures it (rest_errors: its frames' noise and the
    detector's error at rest, the robot's dynamics aside), in place of the noise model's, and
    rests the detector refuses are dropped; the rests keep the noise model's covariances (the
    calibration learns the floor beyond them). ``max_range``: the farthest the ball is planned
    (m).
    """
    rng = np.random.default_rng(seed)
    P = poses.select(selection, declared, truth.sphere_position + guess_error, n, rng, max_range)
    Theta, sigma, sphere, cov, kept = static_session.run(truth, declared, P,
                                                         synthetic.NoiseModel(), rng)
    if images:
        C = static_session.sphere_in_camera(truth, static_session.rest_positions(
            truth, declared, P[kept])[1])
        error = rest_errors(C, truth.geometry.sphere_radius, seed=seed)
        ok = np.all(np.isfinite(error), axis=1)
        Theta, sigma, cov = Theta[ok], sigma[ok], cov[ok]
        sphere = truth.camera_reading(C[ok]) + error[ok]
    s = Session(declared, Theta, sigma, sphere, cov, 8.0 * np.arange(len(Theta)))
    meas = s.measurements()
    return s, meas, diagnosis.run(declared, meas, s.sphere, s.stamps, seed=seed)
