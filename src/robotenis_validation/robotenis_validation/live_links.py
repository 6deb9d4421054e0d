"""
Which link of the live chain limits a calibration: a recorded session scored link by link.

``python -m robotenis_validation.live_links BAG TRUTH [RESULT]`` reads a session bag (as the
calibration node records it) and the simulator's truth file it ran with, and prints:

* the rests against the truth: each rest's averaged sphere centre minus where the truth puts the
  ball for the rest's readings (its true arm angles, on the backlash sides the simulator had:
  ``TrueSides``);
* the detector alone: the ball rendered without sensor noise at those true positions with the
  hand camera's defaults and detected, per method: the detector's bias at each pose, the part of
  a rest's error that averaging its frames does not remove (study.detector_bias), and what is left
  of the rests' error without it; and the model method's bias without the renderer's specular
  highlight, then without its lens blur (BIAS_SOURCES): where the bias comes from;
* the rests emulated offline (study.rest_errors, twice with fresh noise): the node's own step
  on frames rendered at the true positions, without the robot's dynamics, the timing or ROS; the
  rests' error less the emulated, and how much of the emulated is noise (the two emulations'
  difference) and how much the detector's error at rest pose by pose (what they share); and
  the rests made of the truth, the emulations' noise and a share of what they share
  (``scaled_rests``: 1, 0.5, 0), calibrated: how small that error must be for a target;
* the rests replayed offline with the robot's motion (study.replayed_rests on ``replay_paths``):
  the node's step on every frame of the bag's camera stream, from the rest before to the end of
  each rest, rendered where the truth put the ball at that frame's joint state: what the robot's
  moves and settling add to the emulated rests (a rest taken while the ball still moved, a fit
  seeded from a ball elsewhere), and the rests' error less the replayed;
* the rests' first 1, 3, 10 frames averaged against the truth: where the rests' own floor stops
  more frames from helping;
* the backlash side: the same difference when each joint's side is the one that fits best (a
  side the scorer got wrong shows as a large drop), and how many of the sides the calibration
  took (a play of the gap it chose) differ from the simulator's;
* the bag calibrated as recorded and with each rest's detector bias taken out (what the chain
  would give with an unbiased detector): the effects claimed and the FK error against the truth
  at the session's rests (RMS, and less its common offset, which the hand camera barely sees)
  and over boundary poses of the whole workspace; and with the two emulations', then the two
  replays', mean error taken out (what the chain would give without the detector's error at
  rest, then without what the robot's motion adds to it, noise aside);
* with RESULT, its FK error against the truth over the whole workspace.

The held-out error against the truth is the loop's own held-out error (the demo's, issue 15's
measure) with each held-out rest's camera reading replaced by the truth's, noise-free: the error of
what the calibration predicts where it can be checked, free of the common offset that the fitted
ball position absorbs. The FK over the workspace extrapolates far from the poses a hand camera
watching one ball can reach.
"""
import argparse
from concurrent.futures import ProcessPoolExecutor
import dataclasses
import itertools
import os
import sys

import numpy as np
from robotenis_calibration import bag_io, diagnosis, pipeline, rests, result
from robotenis_kinematics import delta, description, effects, workspace
from robotenis_sim import camera_model, static_session
from robotenis_sim import truth as sim_truth
from robotenis_validation.study import detector_bias, replayed_rests, rest_errors, SETTLE_FRAMES

METHODS = ('conic', 'model')
FIRST_FRAMES = (1, 3, 10)       # frames of each rest averaged by first_frames_error
EMULATION_SEEDS = (1, 2)        # two emulations of the rests: their difference is the noise
# scaled_rests: shares of the detector's error at rest, pose by pose, a calibration is tried with
POSE_SHARES = (1.0, 0.5, 0.0)
# the renderer's defaults, one at a time, that the model method's bias comes from
BIAS_SOURCES = {'no specular highlight': {'lighting': camera_model.Lighting(specular=0.0)},
                'no lens blur': {'blur_sigma': 0.0}}


def true_centres(truth, Theta, direction):
    """Return the ball's true centres in the optical frame (K, 3) for rests' readings."""
    arm = truth.arm_angles(truth.motor_from_reading(Theta), direction)
    return static_session.sphere_in_camera(truth, delta.forward(truth.geometry,
                                                                np.atleast_2d(arm)))


def true_sphere(truth, Theta, direction):
    """Return where the truth's camera measures the ball (K, 3) for rests' readings."""
    return truth.camera_reading(true_centres(truth, Theta, direction))


@dataclasses.dataclass
class TrueSides:
    """The simulator's backlash contact side (n, 3) at each joint state (n,) of a session bag."""

    t: np.ndarray
    sides: np.ndarray

    @classmethod
    def of_bag(cls, bag, truth):
        """Read them from a bag's joint states (sim_truth.reading_sides, the truth's widths)."""
        return cls.of_recording(read_recording(bag), truth)

    @classmethod
    def of_recording(cls, rec, truth):
        """Take them from a read bag's (rests.Recording) joint states, as ``of_bag``."""
        width = truth.effects.get('backlash', np.zeros(3))
        return cls(rec.t_joint, sim_truth.reading_sides(rec.Theta, width))

    def at(self, stamps):
        """Return the sides (K, 3) at the times ``stamps`` (K,), s: a rest's middle."""
        return self.sides[np.clip(np.searchsorted(self.t, stamps), 0, len(self.t) - 1)]


def read_recording(bag):
    """Return a bag's time series (rests.Recording)."""
    with bag_io.BagReader(bag) as reader:
        return rests.read(reader, [])


def best_sides(truth, session, sides):
    """Return the rests' error (K, 3) with each joint's backlash side the one that fits best."""
    out, flipped = [], 0
    for k in range(len(session)):
        trials = []
        for signs in itertools.product((1.0, -1.0), repeat=3):
            e = session.sphere[k] - true_sphere(truth, session.Theta[k:k + 1],
                                                sides[k] * np.array(signs))[0]
            trials.append((float(np.linalg.norm(e)), signs, e))
        _, signs, e = min(trials, key=lambda t: t[0])
        out.append(e)
        flipped += sum(s < 0 for s in signs)
    return np.array(out), flipped


def workspace_error_mm(desc, truth, n=500, seed=900):
    """
    Return the RMS 3D error (mm) of a description's FK, as ``fk`` applies it, workspace-wide.

    inf when the description cannot assemble the robot at one of the poses (its joint effects
    pull the forearms apart there): ``fk`` fails where the robot still goes.
    """
    P_cmd = workspace.boundary_poses(description.nominal(), n, np.random.default_rng(seed))
    Theta, P_true = static_session.rest_positions(truth, description.nominal(), P_cmd)
    try:
        P = delta.forward(desc, effects.joint_angles(desc, Theta))
    except ValueError:
        return np.inf
    return float(np.sqrt(np.mean(np.sum((P - P_true) ** 2, axis=1))) * 1e3)


def rest_error_mm(desc, truth, Theta, direction, sides):
    """
    Return the FK error (mm) of a description against the truth at rests read Theta (K, 3).

    The description on the calibration's backlash sides ``direction`` (K, 3), the truth on its
    own ``sides`` (K, 3). (RMS 3D error, the same less its mean over the rests): the second leaves
    out the common offset along which a hand camera's incremental measurements barely pin the
    robot.
    """
    fx = effects.parameters(desc)
    P = delta.forward(desc, effects.arm_angles(desc, fx, Theta, direction))
    arm = truth.arm_angles(truth.motor_from_reading(Theta), sides)
    e = (P - delta.forward(truth.geometry, arm)) * 1e3
    rms = float(np.sqrt(np.mean(np.sum(e ** 2, axis=1))))
    return rms, float(np.sqrt(np.mean(np.sum((e - e.mean(axis=0)) ** 2, axis=1))))


def holdout_truth_error_mm(d, meas, session, truth, model=None, sides=None):
    """
    Return the RMS error (mm) of a diagnosis's model at its held-out rests against the truth.

    diagnosis.position_errors of ``model`` (default the final one) on the rests the loop held out
    (``d.holdout``; ``meas`` as the loop used it, its backlash sides included), each camera reading
    replaced by what the truth's camera reads there without noise (Pi_k = -R s_k, as
    Session.measurements), on the truth's own backlash sides ``sides`` (K, 3): for a live bag
    ``TrueSides.at(session.stamps)``; by default those of a play of the truth's width
    (Session.with_backlash), as the static simulators take them.
    """
    gap = truth.effects.get('backlash')
    if sides is None:
        sides = (session.direction if gap is None
                 else session.with_backlash(np.asarray(gap)).direction)
    s_true = true_sphere(truth, session.Theta, sides)
    R = session.description.camera_rotation
    seen = dataclasses.replace(meas, Pi=-s_true @ R.T, Pi_basis=None).subset(d.holdout)
    model = d.final.model if model is None else model
    return float(np.sqrt(np.mean(diagnosis.position_errors(model, seen) ** 2)) * 1e3)


def first_frames_error(rec, truth, session, sides, counts=FIRST_FRAMES):
    """
    Return {n: (K', 3)} each marked rest's first n frames averaged, less the truth (m).

    How many frames a rest needs on the live chain: once the rests' own floor dominates, their
    error against the truth stops falling with n (protocol.frames_per_rest's premise). ``rec``:
    the bag read (read_recording); rests are those of ``session`` (read with markers) with at
    least max(counts) frames; ``sides``: the truth's backlash sides at them
    (TrueSides.at(session.stamps)).
    """
    windows = {round(0.5 * (t0 + t1), 6): (t0, t1) for t0, t1, _ in
               rests.marked_windows(rec.markers, [])}
    true = true_sphere(truth, session.Theta, sides)
    out = {n: [] for n in counts}
    for k, stamp in enumerate(session.stamps):
        t0, t1 = windows.get(round(float(stamp), 6), (np.inf, -np.inf))
        frames = rec.sphere[rec.frames(t0, t1)]
        if len(frames) >= max(counts):
            for n in counts:
                out[n].append(frames[:n].mean(axis=0) - true[k])
    return {n: np.reshape(e, (-1, 3)) for n, e in out.items()}


def calibrated_as_the_service(bag, seed):
    """
    Return (session, diagnosis, measurements) of a session bag calibrated as the service does.

    ``pipeline.calibrate_session`` with the request's ``seed``: the held-out figures need the
    loop's own split, which the service's result file does not keep.
    """
    session, _ = rests.load_session(bag)
    d, meas = pipeline.calibrate_session(session, pipeline.Settings(seed=seed))
    return session, d, meas


def without_bias(session, bias):
    """Return the session with each rest's detector bias (K, 3) taken out (NaN rows dropped)."""
    ok = np.flatnonzero(np.all(np.isfinite(bias), axis=1))
    kept = session.subset(ok)
    return dataclasses.replace(kept, sphere=kept.sphere - bias[ok])


def calibration_line(label, session, truth, true_sides):
    """Calibrate a session as `calibrate` does and score it against the truth: one line."""
    d, meas = pipeline.calibrate_session(session)
    desc = result.calibrated_description(d, session.description)
    sides = true_sides.at(session.stamps)
    at_rests, less_offset = rest_error_mm(desc, truth, session.Theta, meas.direction, sides)
    held_out = holdout_truth_error_mm(d, meas, session, truth, sides=sides)
    differ = int(np.sum(meas.direction != sides)) if 'backlash' in truth.effects else 0
    return (f'{label}: claimed {", ".join(d.effects) or "nothing"}; held-out '
            f'{d.errors_mm["final"]:.3f} mm (camera), {held_out:.3f} mm against the truth; FK '
            'against the truth at the rests '
            f'{at_rests:.3f} mm ({less_offset:.3f} less its common offset), over the workspace '
            f'{workspace_error_mm(desc, truth):.3f} mm; {differ} of {sides.size} backlash sides '
            "differ from the simulator's")


def emulated_rests(C, radius, frames, settle=SETTLE_FRAMES, seeds=EMULATION_SEEDS):
    """
    Return the rests' errors (len(seeds), K, 3), m, emulated offline (study.rest_errors).

    Each seed draws fresh noise over the same poses: the emulations' difference is the rests'
    noise; what they share is the detector's bias at rest, pose by pose. One process per seed
    (about 40 s each for 90 rests here).
    """
    with ProcessPoolExecutor(max_workers=min(len(seeds), os.cpu_count() or 1)) as pool:
        runs = [pool.submit(rest_errors, C, radius, frames, settle, seed) for seed in seeds]
        return np.array([run.result() for run in runs])


def replay_paths(rec, truth, session):
    """
    Return each rest's frames from a bag as study.replayed_rests takes them: paths, windows, times.

    For the session's rest k: the bag's camera frames (its sphere stamps) from the end of the
    rest before (the first: from the stream's start) to the end of rest k's window between its
    markers, each at the ball's true centre for the joint state at that frame (its true arm
    angles on the simulator's backlash sides, ``TrueSides``); the window's frames; their stamps.
    """
    windows = rests.marked_windows(rec.markers, [])
    sides = TrueSides.of_recording(rec, truth)
    paths, masks, times = [], [], []
    for stamp in session.stamps:
        k = next(i for i, (t0, t1, _) in enumerate(windows) if t0 <= stamp <= t1)
        start = windows[k - 1][1] if k else -np.inf
        t0, t1, _ = windows[k]
        t = rec.t_sphere[(rec.t_sphere > start) & (rec.t_sphere <= t1)]
        j = np.clip(np.searchsorted(rec.t_joint, t), 0, len(rec.t_joint) - 1)
        paths.append(true_centres(truth, rec.Theta[j], sides.sides[j]))
        masks.append(t >= t0)
        times.append(t)
    return paths, masks, times


def replayed(rec, truth, session, seeds=EMULATION_SEEDS):
    """Return the rests' errors (len(seeds), K, 3), m, replayed from a bag (``replay_paths``)."""
    paths, masks, times = replay_paths(rec, truth, session)
    radius = truth.geometry.sphere_radius
    with ProcessPoolExecutor(max_workers=min(len(seeds), os.cpu_count() or 1)) as pool:
        runs = [pool.submit(replayed_rests, paths, masks, radius, seed, times=times)
                for seed in seeds]
        return np.array([run.result() for run in runs])


def split_noise(emulated):
    """
    Return the rests' noise and pose-dependent error, each (3,) std, m, from two emulations.

    noise^2 = var(e1 - e2) / 2; the pose-dependent part's variance is var((e1 + e2) / 2) less
    the half of noise^2 left in a mean of two (floored at 0).
    """
    e1, e2 = emulated[:2]
    ok = np.all(np.isfinite(e1) & np.isfinite(e2), axis=1)
    noise2 = np.var(e1[ok] - e2[ok], axis=0) / 2
    shared = np.var((e1[ok] + e2[ok]) / 2, axis=0) - noise2 / 2
    return np.sqrt(noise2), np.sqrt(np.maximum(shared, 0.0))


def scaled_rests(session, true, emulated, share):
    """
    Return the session with readings the truth's plus emulated noise and ``share`` of its error.

    ``true`` (K, 3): where the truth's camera measures the ball at each rest (true_sphere);
    ``emulated`` (2, K, 3): two emulations of the rests with fresh noise (emulated_rests). Each
    rest reads true + share (e1 + e2) / 2 + (e1 - e2) / sqrt(2): the detector's error at rest
    pose by pose scaled by ``share`` (their mean, which keeps half an emulation's noise), and one
    emulation's noise (their difference). What a calibration would give with a detector whose
    error at rest that depends on the pose were ``share`` of this one's. The rests keep the
    session's covariances (the calibration learns the floor beyond them); rests an emulation
    refused (NaN) are dropped.
    """
    e1, e2 = emulated[:2]
    ok = np.flatnonzero(np.all(np.isfinite(e1) & np.isfinite(e2), axis=1))
    kept = session.subset(ok)
    error = share * (e1[ok] + e2[ok]) / 2 + (e1[ok] - e2[ok]) / np.sqrt(2)
    return dataclasses.replace(kept, sphere=true[ok] + error)


def _line(label, e):
    return (f'{label:46s} mean {np.round(e.mean(axis=0) * 1e3, 3)} std '
            f'{np.round(e.std(axis=0) * 1e3, 3)} mm ({len(e)})')


def main(argv=None):
    parser = argparse.ArgumentParser(prog='live_links', description=__doc__.splitlines()[1])
    parser.add_argument('bag')
    parser.add_argument('truth')
    parser.add_argument('result', nargs='?')
    args = parser.parse_args(argv)
    truth = sim_truth.load(args.truth)
    session, _ = rests.load_session(args.bag)
    rec = read_recording(args.bag)
    true_sides = TrueSides.of_recording(rec, truth)
    sides = true_sides.at(session.stamps)
    print('optical x, y, z:')
    error = session.sphere - true_sphere(truth, session.Theta, sides)
    print(_line('rests minus truth', error))
    C = true_centres(truth, session.Theta, sides)
    bias = {m: detector_bias(C, truth.geometry.sphere_radius, m) for m in METHODS}
    for method in METHODS:
        ok = np.all(np.isfinite(bias[method]), axis=1)
        print(_line(f'detector bias ({method}), noise-free renders', bias[method][ok]))
        print(_line(f'rests minus truth minus the {method} bias', (error - bias[method])[ok]))
    for label, options in BIAS_SOURCES.items():
        b = detector_bias(C, truth.geometry.sphere_radius, 'model', **options)
        print(_line(f'detector bias (model), {label}', b[np.all(np.isfinite(b), axis=1)]))
    emulated = emulated_rests(C, truth.geometry.sphere_radius, int(np.median(session.samples)))
    ok = np.all(np.isfinite(emulated), axis=(0, 2))
    print(_line('rests emulated offline (the node, fresh noise)', emulated[0][ok]))
    print(_line('rests minus the emulated', (error - emulated[0])[ok]))
    r = [np.corrcoef(error[ok, i], emulated[0][ok, i])[0, 1] for i in range(3)]
    print(f'  correlation of the rests with the emulated, x y z: {np.round(r, 2)}')
    noise, pose = split_noise(emulated)
    print(f'  emulated rests: noise std {np.round(noise * 1e3, 3)} mm, the detector at rest '
          f'pose by pose {np.round(pose * 1e3, 3)} mm')
    for share in POSE_SHARES:
        print(calibration_line(f"emulated rests, the detector's error at rest x{share:g} (its "
                               'noise kept)', scaled_rests(session, truth.camera_reading(C),
                                                           emulated, share),
                               truth, true_sides))
    replay = replayed(rec, truth, session)
    ok = np.all(np.isfinite(replay), axis=(0, 2))
    print(_line('rests replayed with the motion (fresh noise)', replay[0][ok]))
    print(_line('rests minus the replayed', (error - replay[0])[ok]))
    r = [np.corrcoef(error[ok, i], replay[0][ok, i])[0, 1] for i in range(3)]
    print(f'  correlation of the rests with the replayed, x y z: {np.round(r, 2)}')
    for n, e in first_frames_error(rec, truth, session, sides).items():
        print(_line(f'rests minus truth, their first {n} frames', e))
    e, flipped = best_sides(truth, session, sides)
    print(_line(f'rests, best backlash sides ({flipped} of {3 * len(session)} flipped)', e))
    print(calibration_line('calibrated as recorded', session, truth, true_sides))
    print(calibration_line('calibrated with the model bias taken out',
                           without_bias(session, bias['model']), truth, true_sides))
    print(calibration_line("calibrated with the emulated rests' mean error taken out",
                           without_bias(session, emulated.mean(axis=0)), truth, true_sides))
    print(calibration_line("calibrated with the replayed rests' mean error taken out",
                           without_bias(session, replay.mean(axis=0)), truth, true_sides))
    if args.result:
        print(f'FK of {args.result} against the truth over 500 boundary poses: '
              f'{workspace_error_mm(description.load(args.result), truth):.3f} mm '
              f'(nominal {workspace_error_mm(description.nominal(), truth):.3f} mm)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
