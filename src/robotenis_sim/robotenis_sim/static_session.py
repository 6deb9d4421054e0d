"""
A calibration session without dynamics: what the robot reports at each rest, from the truth.

The live session (motion controller, motors, hand camera, detector) takes minutes; the residual
loop's statistics need hundreds of sessions. This module produces the same averaged measurements
the live session's rests give, from the same truth models:

* the controller brings the resolver readings to the command IK_declared(P_cmd) - theta0_declared
  (the robot only knows its declared model), so the readings are the command plus resolver noise;
* the motors sit where the readings say (gear-ratio error), the arms lag them by the backlash
  against the last motion (each joint moves monotonically between rests here) and sag under
  gravity;
* the effector is where the TRUE geometry puts those arm angles, and the hand camera, mounted at
  its true rotation and offset, sees the ball there, with the averaged-detection noise of Table 3.

Rests where the ball is out of the camera's view or range are skipped, as the live session would.
"""
import numpy as np

from robotenis_kinematics import delta, effects

DEFAULT_CAMERA = {'width': 640, 'height': 480, 'fx': 500.0, 'fy': 500.0, 'cx': 319.5, 'cy': 239.5}
RANGE = (0.15, 0.60)   # m, along the optical axis, where the detector is specified
MARGIN_PX = 40         # keep the ball's image this far inside the frame


def visible(sphere, radius, camera=DEFAULT_CAMERA):
    """Return the mask (K,) of sphere centres (optical frame, m) the camera sees whole in range."""
    x, y, z = np.asarray(sphere, dtype=float).T
    ok = (z >= RANGE[0]) & (z <= RANGE[1])
    zs = np.where(ok, z, 1.0)
    r_px = camera['fx'] * radius / zs
    u = camera['fx'] * x / zs + camera['cx']
    v = camera['fy'] * y / zs + camera['cy']
    return ok & (u - r_px > MARGIN_PX) & (u + r_px < camera['width'] - MARGIN_PX) \
        & (v - r_px > MARGIN_PX) & (v + r_px < camera['height'] - MARGIN_PX)


def sphere_in_camera(truth, P):
    """Return sphere centres in the true optical frame (K, 3) for effector positions P (K, 3)."""
    return (truth.sphere_position - P - truth.camera_translation) @ truth.camera_rotation


def rest_positions(truth, declared, P_cmd):
    """Return readings and true effector positions (K, 3) at rest after visiting P_cmd in order."""
    Theta = delta.inverse(declared, P_cmd) - declared.theta0
    motor = truth.motor_from_reading(Theta)
    arm = truth.arm_angles(motor, effects.motion_direction(Theta))
    return Theta, delta.forward(truth.geometry, arm)


def run(truth, declared, P_cmd, noise, rng, camera=DEFAULT_CAMERA, floor=(0.0, 0.0, 0.0)):
    """
    Simulate the averaged measurements of a static session over commanded positions P_cmd (K, 3).

    Returns (Theta, sigma_Theta, sphere, sphere_cov, kept): readings with noise, the sphere centres
    the camera measures (its undeclared errors, truth.camera_reading, and noise), and the indices
    of P_cmd whose rest gave a measurement. ``noise`` is a synthetic.NoiseModel (sigma_camera
    along the optical axes: the averaged frames' spread, what sphere_cov says);
    ``floor`` (m, optical axes) is each rest's own error beyond it, drawn once per rest and not
    in sphere_cov, as what a detector gets wrong at a pose is not in its frames' spread.
    """
    P_cmd = np.asarray(P_cmd, dtype=float)
    P_rest = rest_positions(truth, declared, P_cmd)[1]
    kept = np.flatnonzero(visible(sphere_in_camera(truth, P_rest), truth.geometry.sphere_radius,
                                  camera))
    # Visit only what the camera sees: the motion directions follow the poses actually visited.
    Theta, P = rest_positions(truth, declared, P_cmd[kept])
    sphere = truth.camera_reading(sphere_in_camera(truth, P))
    cov = np.diag(np.square(noise.sigma_camera))
    sphere = sphere + rng.multivariate_normal(np.zeros(3), cov, size=len(kept))
    if np.any(floor):
        sphere = sphere + rng.normal(size=sphere.shape) * np.asarray(floor, dtype=float)
    Theta = Theta + rng.normal(scale=noise.sigma_resolver, size=Theta.shape)
    sigma = np.full_like(Theta, noise.sigma_resolver)
    return Theta, sigma, sphere, np.broadcast_to(cov, (len(kept), 3, 3)).copy(), kept
