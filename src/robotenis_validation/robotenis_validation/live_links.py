"""
Which link of the live chain limits a calibration: a recorded session scored link by link.

``python -m robotenis_validation.live_links BAG TRUTH [RESULT]`` reads a session bag (as the
calibration node records it) and the simulator's truth file it ran with, and prints:

* the rests against the truth: each rest's averaged sphere centre minus where the truth puts the
  ball for the rest's readings (its true arm angles, backlash side from the readings' motion);
* the detector alone: the ball rendered at those true positions with the hand camera's defaults
  and detected, per method (what the detector gets wrong at each pose, whatever the chain does);
* the backlash side: the same difference when each joint's side is the one that fits best (a
  side the readings got wrong shows as a large drop);
* with RESULT, its FK error against the truth over boundary poses of the whole workspace.
"""
import argparse
import itertools
import sys

import numpy as np
from robotenis_calibration import rests
from robotenis_kinematics import delta, description, effects, workspace
from robotenis_sim import camera_model, static_session
from robotenis_sim import truth as sim_truth
from robotenis_vision import camera as vision_camera
from robotenis_vision import detector

METHODS = ('conic', 'model')


def true_centres(truth, Theta, direction):
    """Return the ball's true centres in the optical frame (K, 3) for rests' readings."""
    arm = truth.arm_angles(truth.motor_from_reading(Theta), direction)
    return static_session.sphere_in_camera(truth, delta.forward(truth.geometry,
                                                                np.atleast_2d(arm)))


def true_sphere(truth, Theta, direction):
    """Return where the truth's camera measures the ball (K, 3) for rests' readings."""
    return truth.camera_reading(true_centres(truth, Theta, direction))


def detector_errors(truth, Theta, direction, method, rng):
    """Return detection minus truth (n, 3) of renders at the rests' true positions (m)."""
    C = true_centres(truth, Theta, direction)
    camera, R = vision_camera.default(), truth.geometry.sphere_radius
    out = []
    for c in C:
        try:
            out.append(detector.detect(camera_model.render(camera, c, R, rng), camera, R,
                                       method).position - c)
        except detector.DetectionError:
            continue  # a frame the detector refuses is not an error of it
    return np.array(out)


def best_sides(truth, session):
    """Return the rests' error (K, 3) with each joint's backlash side the one that fits best."""
    out, flipped = [], 0
    for k in range(len(session)):
        trials = []
        for signs in itertools.product((1.0, -1.0), repeat=3):
            e = session.sphere[k] - true_sphere(truth, session.Theta[k:k + 1],
                                                session.direction[k] * np.array(signs))[0]
            trials.append((float(np.linalg.norm(e)), signs, e))
        _, signs, e = min(trials, key=lambda t: t[0])
        out.append(e)
        flipped += sum(s < 0 for s in signs)
    return np.array(out), flipped


def workspace_error_mm(desc, truth, n=500, seed=900):
    """Return the RMS 3D error (mm) of a description's FK, as ``fk`` applies it, workspace-wide."""
    P_cmd = workspace.boundary_poses(description.nominal(), n, np.random.default_rng(seed))
    Theta, P_true = static_session.rest_positions(truth, description.nominal(), P_cmd)
    P = delta.forward(desc, effects.joint_angles(desc, Theta))
    return float(np.sqrt(np.mean(np.sum((P - P_true) ** 2, axis=1))) * 1e3)


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
    print('optical x, y, z:')
    print(_line('rests minus truth', session.sphere - true_sphere(truth, session.Theta,
                                                                  session.direction)))
    for method in METHODS:
        e = detector_errors(truth, session.Theta, session.direction, method,
                            np.random.default_rng(0))
        print(_line(f'detector alone ({method}), renders at the rests', e))
    e, flipped = best_sides(truth, session)
    print(_line(f'rests, best backlash sides ({flipped} of {3 * len(session)} flipped)', e))
    if args.result:
        print(f'FK of {args.result} against the truth over 500 boundary poses: '
              f'{workspace_error_mm(description.load(args.result), truth):.3f} mm '
              f'(nominal {workspace_error_mm(description.nominal(), truth):.3f} mm)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
