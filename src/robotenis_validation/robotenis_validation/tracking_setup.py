"""
The tracking tests' setup and scenario (calibration paper, section 6.2.2, Table 5).

``Setup`` holds everything a tracking run depends on besides the ball, the robot and the
description; the scenario functions say where the ball flies (a chaotic path in the robot's 400 mm
cube shifted by the camera offset) and where the robot starts.
"""
from dataclasses import dataclass

import numpy as np
from robotenis_control import pbvs
from robotenis_kinematics import delta, workspace
from robotenis_sim import ball as sim_ball
from robotenis_sim import motors
from robotenis_validation import jacobian_study

SPEEDS = (0.5, 0.75, 1.0, 1.25, 1.5)      # m/s: Table 5's maximum ball speeds
TESTS, SAMPLES = 10, 5000                  # the paper: 10 tests of 5,000 samples per speed
QUICK_TESTS, QUICK_SAMPLES = 2, 1000
FRAME_PERIOD = 1.0 / 120.0                 # s: the camera's 120 Hz (8.34 ms in the paper)
SIGMA_FRAME = pbvs.SIGMA_CAMERA            # m: one detection's noise, Table 2 scaled to 600 mm
# The region the robot works in: the 400 mm cube of the static tests (section 6.1), centred in the
# Jacobian study's cylinder (section 6.2.1); the ball flies the same cube shifted by the camera
# offset.
ROBOT_CENTRE = (0.0, 0.0, float(np.mean(jacobian_study.Z_RANGE)))
HALF_SIZE = (0.2, 0.2, 0.2)
# ChaoticBall's duration argument: ~90 s of path at 1.5 m/s
BALL_PATH_DURATION = 4.0


@dataclass(frozen=True)
class Setup:
    """
    Everything a tracking run depends on besides the ball, the robot and the description (SI).

    K_p (1/s) and s_d (m, optical frame) are eq. 23's gain and reference; ``feedforward`` adds the
    Kalman velocity v_p (False: the pure proportional baseline); ``kalman_q`` is BallKalman's
    white-acceleration density (m^2/s^3); ``sigma_camera`` is one detection's noise and
    ``camera_bias`` its systematic error (m, optical x, y, z); ``filter_sigma`` is the noise the
    ball's filter assumes (None: sigma_camera; a live tracker assumes pbvs.SIGMA_CAMERA whatever
    its detector does); ``max_speed`` clips u_r (m/s) as the motion controller does;
    ``latency_frames`` is the visual loop delay in frame periods; ``warmup_frames`` are run before
    the samples are counted (the robot starts at the reference, the filter at rest);
    ``segment_samples`` is the longest stretch of a test simulated in one piece (see
    ``run_description``).
    """

    K_p: float = pbvs.K_P
    s_d: tuple = tuple(pbvs.S_DESIRED)
    feedforward: bool = True
    kalman_q: float = pbvs.KALMAN_Q
    sigma_camera: tuple = SIGMA_FRAME
    camera_bias: tuple = (0.0, 0.0, 0.0)
    filter_sigma: tuple = None
    frame_period: float = FRAME_PERIOD
    latency_frames: int = 1
    warmup_frames: int = 60
    max_speed: float = pbvs.MAX_SPEED
    dt: float = 1e-3
    resolver_noise: float = motors.ResolverParameters.noise
    robot_centre: tuple = ROBOT_CENTRE
    half_size: tuple = HALF_SIZE
    segment_samples: int = 250

    def __post_init__(self):
        positive = ('K_p', 'kalman_q', 'frame_period', 'max_speed', 'dt')
        bad = [name for name in positive
               if not (np.isfinite(getattr(self, name)) and getattr(self, name) > 0)]
        if bad:
            raise ValueError(f"tracking setup: {', '.join(bad)} must be positive and finite")
        if (self.latency_frames < 0 or self.warmup_frames < 0 or self.resolver_noise < 0
                or self.segment_samples < 1):
            raise ValueError('tracking setup: latency_frames, warmup_frames, resolver_noise '
                             'must be >= 0 and segment_samples >= 1')
        for name in ('s_d', 'sigma_camera', 'camera_bias', 'robot_centre', 'half_size',
                     'assumed_sigma'):
            if (np.shape(getattr(self, name)) != (3,)
                    or not np.all(np.isfinite(getattr(self, name)))):
                raise ValueError(f'tracking setup: {name} must have three finite components, '
                                 f'got {getattr(self, name)!r}')
        if min(self.sigma_camera) < 0 or min(self.assumed_sigma) < 0 or min(self.half_size) <= 0:
            raise ValueError('tracking setup: sigma_camera and filter_sigma must be >= 0 '
                             'and half_size > 0')
        if self.frame_period < self.dt:
            raise ValueError(f'tracking setup: the frame period {self.frame_period} s '
                             'is shorter than a control tick')

    @property
    def assumed_sigma(self):
        """Return the detection noise the ball's filter assumes (m, optical x, y, z)."""
        return self.sigma_camera if self.filter_sigma is None else self.filter_sigma


def robot_offset(truth, setup):
    """Ball minus effector (base frame, m) when the ball is exactly at s_d in the true camera."""
    return truth.camera_translation + truth.camera_rotation @ np.asarray(setup.s_d, dtype=float)


def make_ball(truth, setup, speed, test):
    """
    Build the chaotic ball of one test: test index = seed.

    Its box is the robot's cube shifted by the camera offset.
    """
    centre = np.asarray(setup.robot_centre) + robot_offset(truth, setup)
    return sim_ball.ChaoticBall(centre, setup.half_size, speed, seed=test,
                                duration=BALL_PATH_DURATION)


def check_region(descs, truth, setup):
    """Raise ValueError unless the robot's box plus 50 mm margin is usable for each description."""
    corners = np.array(np.meshgrid(*[[-1.0, 1.0]] * 3, indexing='ij')).reshape(3, -1).T
    P = np.asarray(setup.robot_centre) + corners * (np.asarray(setup.half_size) + 0.05)
    for desc in [truth.geometry, *descs]:
        if not np.all(workspace.Workspace().contains(desc, P)):
            raise ValueError(f"tracking: the robot's box {setup.half_size} m "
                             f'about {setup.robot_centre} leaves the usable workspace')


def start_position(truth, setup, balls):
    """
    Return the resolver increments (N, 3) that put each true robot at the reference.

    The reference is taken relative to each robot's ball at t=0.
    """
    P = np.array([b.at(0.0) for b in balls]) - robot_offset(truth, setup)
    return delta.inverse(truth.geometry, P) - truth.geometry.theta0


def check_truth(truth):
    """
    Refuse joint-level effects in the truth.

    The study simulates the truth's geometry and camera mounting only.
    """
    unsupported = sorted(set(truth.effects) - {'base_geometry', 'hand_eye_rotation'})
    if unsupported:
        raise ValueError(f"tracking: truth effects {', '.join(unsupported)} "
                         'are not simulated by this study')


class ShiftedBall:
    """A ball whose clock starts ``t0`` seconds into another ball's path."""

    def __init__(self, ball, t0):
        self.ball, self.t0 = ball, float(t0)

    def at(self, t):
        return self.ball.at(np.asarray(t) + self.t0)


def segments(samples, setup):
    """
    Cut a test's samples into ``count`` pieces of ``length`` <= segment_samples: (count, length).

    count x length may exceed ``samples``: the extra samples at the end are dropped.
    """
    count = -(-samples // setup.segment_samples)
    return count, -(-samples // count)
