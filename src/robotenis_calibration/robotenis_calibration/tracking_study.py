"""The tracking tests of the calibration paper (section 6.2.2, Table 5), simulated without ROS.

A ball flies a chaotic path (robotenis_sim.ball.ChaoticBall, a Lorenz attractor re-timed to a top
speed) in front of the robot; the robot keeps it centred in the image 600 mm ahead with the
position-based visual servoing law of eqs. 23-25 (robotenis_control.pbvs). Per run:

- the TRUE robot: the truth's geometry and masses, velocity-command drives (eq. 10), resolvers and
  RK4 rigid-body dynamics at 1 kHz (robotenis_sim.motors.SimulatedMotors);
- the motion controller at 1 kHz in velocity mode (robotenis_control.controller.MotionController):
  it integrates the Cartesian command u_r and follows it through the inverse kinematics and inverse
  dynamics of the description under test, i.e. the joints move at J_R^-1 u_r (eq. 25) with J_R that
  of the description, and the robot at J_R,true J_R^-1 u_r (eq. 26);
- the hand camera at 120 Hz (one frame every 8.33 ms): the ball's position s in the optical frame
  from the TRUE effector and ball positions through the TRUE camera mounting, plus Gaussian noise of
  one detection (``SIGMA_FRAME``), delivered one frame period late (the paper's visual loop delay);
- on each delivered detection, what pbvs.Tracker does: e_r = -R (s - s_d) with s_d = (0, 0, 600 mm)
  (the ball centred at 600 mm, as in the paper), v_p from the ball's Kalman filter (pbvs.BallKalman)
  on the ball's base-frame position P_est + R s (P_est: forward kinematics of the description on the
  resolvers read at the exposure), u_r = -K_p e_r + v_p (eq. 23, K_p = 16.8), sent to the motion
  controller.

The tracking error is what the paper reports (Table 5: "the mean of the tracking errors in
millimetres when 10 tests are done"): per test, the mean over its samples of |e_r| from the visual
measurement; per speed, the mean (and spread) over the tests. The true error |s_true - s_d|, without
the camera's noise, is recorded beside it. Nominal and calibrated runs of one test see the same ball,
the same camera noise and the same resolver noise (a paired comparison).

Speed. Two engines run the same loop: ``ScalarPlant`` and ``TrackerServo`` step the project's
SimulatedMotors, MotionController and pbvs.Tracker objects one robot at a time (the reference, what
the ROS nodes run), ``BatchPlant`` and ``BatchServo`` step all runs of one description at once with
the same equations vectorised over runs (robotenis_control.dynamics' forward and inverse dynamics,
motors.rk4_step, controller.velocity_command, one BallKalman carrying every run's state); a test
checks that both give the same errors. A scalar step costs about 0.5 ms per robot (the 100 runs of
42 s would take 40 minutes); a batch step costs a few ms almost whatever its width, so each test is
also cut into segments of ``Setup.segment_samples`` frames simulated side by side, each after its
own warm-up.

Without the velocity feedforward (``Setup(feedforward=False)``) the law is the pure proportional
-K_p e_r: the baseline of benchmarks/tracking.py. ``noise_response`` predicts the error on a still
ball from the camera noise and the loop's delays alone (a linear model of the loop).
"""
import os
import sys
import time
from collections import deque
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field, replace

import numpy as np

from robotenis_calibration import jacobian_study, paper
from robotenis_control import controller as ctl
from robotenis_control import dynamics, pbvs
from robotenis_kinematics import delta, description, workspace
from robotenis_kinematics.synthetic import NoiseModel
from robotenis_sim import ball as sim_ball
from robotenis_sim import motors
from robotenis_sim import truth as sim_truth

SPEEDS = (0.5, 0.75, 1.0, 1.25, 1.5)      # m/s: Table 5's maximum ball speeds
TESTS, SAMPLES = 10, 5000                  # the paper: 10 tests of 5,000 samples per speed
QUICK_TESTS, QUICK_SAMPLES = 2, 1000
FRAME_PERIOD = 1.0 / 120.0                 # s: the camera's 120 Hz (8.34 ms in the paper)
SIGMA_FRAME = pbvs.SIGMA_CAMERA            # m: one detection's noise, Table 2 scaled to 600 mm
# The region the robot works in: the 400 mm cube of the static tests (section 6.1), centred in the
# Jacobian study's cylinder (section 6.2.1); the ball flies the same cube shifted by the camera offset.
ROBOT_CENTRE = (0.0, 0.0, float(np.mean(jacobian_study.Z_RANGE)))
HALF_SIZE = (0.2, 0.2, 0.2)
BALL_PATH_DURATION = 4.0                   # ChaoticBall's duration argument: ~90 s of path at 1.5 m/s


@dataclass(frozen=True)
class Setup:
    """Everything a tracking run depends on besides the ball, the robot and the description (SI).

    K_p (1/s) and s_d (m, optical frame) are eq. 23's gain and reference; ``feedforward`` adds the
    Kalman velocity v_p (False: the pure proportional baseline); ``kalman_q`` is BallKalman's
    white-acceleration density (m^2/s^3); ``sigma_camera`` is one detection's noise and
    ``camera_bias`` its systematic error (m, optical x, y, z); ``filter_sigma`` is the noise the
    ball's filter assumes (None: sigma_camera; a live tracker assumes pbvs.SIGMA_CAMERA whatever its
    detector does); ``max_speed`` clips u_r (m/s) as the motion controller does; ``latency_frames``
    is the visual loop delay in frame periods; ``warmup_frames`` are run before the samples are
    counted (the robot starts at the reference, the filter at rest); ``segment_samples`` is the
    longest stretch of a test simulated in one piece (see ``run_description``).
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
        bad = [name for name in positive if not (np.isfinite(getattr(self, name)) and getattr(self, name) > 0)]
        if bad:
            raise ValueError(f"tracking setup: {', '.join(bad)} must be positive and finite")
        if self.latency_frames < 0 or self.warmup_frames < 0 or self.resolver_noise < 0 or self.segment_samples < 1:
            raise ValueError("tracking setup: latency_frames, warmup_frames, resolver_noise must be >= 0 "
                             "and segment_samples >= 1")
        for name in ('s_d', 'sigma_camera', 'camera_bias', 'robot_centre', 'half_size', 'assumed_sigma'):
            if np.shape(getattr(self, name)) != (3,) or not np.all(np.isfinite(getattr(self, name))):
                raise ValueError(f"tracking setup: {name} must have three finite components, "
                                 f"got {getattr(self, name)!r}")
        if min(self.sigma_camera) < 0 or min(self.assumed_sigma) < 0 or min(self.half_size) <= 0:
            raise ValueError("tracking setup: sigma_camera and filter_sigma must be >= 0 and half_size > 0")
        if self.frame_period < self.dt:
            raise ValueError(f"tracking setup: the frame period {self.frame_period} s is shorter than a control tick")

    @property
    def assumed_sigma(self):
        """The detection noise the ball's filter assumes (m, optical x, y, z)."""
        return self.sigma_camera if self.filter_sigma is None else self.filter_sigma


@dataclass
class TrackingTable:
    """Table 5 measured: per description label, per speed and test, the mean error (m).

    ``visual[label]`` has shape (len(speeds), tests): each test's mean |e_r| of the visual measurement
    (the paper's figure); ``true[label]`` the same for the true error. Means and spreads over the tests
    in mm come from ``mean_mm`` and ``std_mm``.
    """

    speeds: tuple
    labels: tuple
    visual: dict
    true: dict
    tests: int
    samples: int
    setup: Setup = field(default_factory=Setup)
    wall_time: float = 0.0

    def mean_mm(self, label, kind='visual'):
        return 1e3 * getattr(self, kind)[label].mean(axis=1)

    def std_mm(self, label, kind='visual'):
        """Spread of the per-test means over the tests (mm, sample standard deviation; 0 for one test)."""
        values = getattr(self, kind)[label]
        return 1e3 * (values.std(axis=1, ddof=1) if values.shape[1] > 1 else np.zeros(len(values)))


# ----------------------------------------------------------------------------------------------
# The robots: one reference engine, one vectorised engine, same interface.

class ScalarPlant:
    """N true robots (SimulatedMotors) each with its MotionController: the project's own objects."""

    def __init__(self, truth, descs, Theta_start, setup, rng):
        mass = motors.true_masses(truth)
        resolver = motors.ResolverParameters(noise=setup.resolver_noise)
        self.sims = [motors.SimulatedMotors(truth.geometry, mass, resolver=resolver, dt=setup.dt,
                                            rng=np.random.default_rng(rng.integers(2 ** 32)), Theta_start=th)
                     for th in Theta_start]
        self.ctls = [ctl.MotionController(d, max_speed=setup.max_speed) for d in descs]

    def read(self):
        readings = [s.read() for s in self.sims]
        return np.array([r[0] for r in readings]), np.array([r[1] for r in readings])

    def effector(self):
        return np.array([s.effector()[0] for s in self.sims])

    def set_velocity(self, U, t):
        for c, u in zip(self.ctls, U):
            c.set_velocity(u, t)

    def control(self, t, Theta, dTheta):
        for s, c, th, dth in zip(self.sims, self.ctls, Theta, dTheta):
            s.set_command(c.update(t, th, dth)[0])

    def step(self):
        for s in self.sims:
            s.step()


class BatchPlant:
    """The same N robots and controllers, vectorised over runs.

    Robots: SimulatedMotors' model (drives of eq. 10 clipped to the torque limit, RK4 over one tick
    with motors.rk4_step on dynamics.forward_dynamics, quantised noisy resolvers, brakes until the
    first command). Controllers: MotionController in velocity mode (the held position integrates the
    command while it is fresher than the timeout; eq. 11 on the inverse dynamics of the description).
    The workspace check of MotionController is left out: ``check_region`` keeps the robots inside it.
    ``quantise=False`` reads the resolvers without their counts (for ``linearized_plant``).
    """

    def __init__(self, truth, descs, Theta_start, setup, rng, gains=ctl.Gains(), velocity_timeout=0.1,
                 quantise=True):
        self.geometry, self.mass = truth.geometry, motors.true_masses(truth)
        self.drives, self.gains, self.setup, self.rng = motors.DriveParameters(), gains, setup, rng
        self.q = motors.ResolverParameters().resolution if quantise else None
        self.theta0 = np.asarray(truth.geometry.theta0, dtype=float)
        self.alpha = self.theta0 + np.asarray(Theta_start, dtype=float)
        self.dalpha = np.zeros_like(self.alpha)
        self.command = np.zeros_like(self.alpha)
        self.brakes = True
        self.last_reading = self._quantised(self.alpha - self.theta0)
        self.groups = _groups(descs)
        self.theta0_used = np.array([d.theta0 for d in descs])
        self.velocity_timeout = velocity_timeout
        self.hold, self.last_t = None, None
        self.v = np.zeros_like(self.alpha)
        self.received = np.full(len(descs), -np.inf)
        self.ctl_mass = dynamics.MassParameters()

    def _quantised(self, Theta):
        return Theta if self.q is None else np.round(Theta / self.q) * self.q

    def read(self):
        noise = self.rng.normal(scale=self.setup.resolver_noise, size=self.alpha.shape)
        Theta = self._quantised(self.alpha - self.theta0 + noise)
        dTheta = (Theta - self.last_reading) / self.setup.dt
        self.last_reading = Theta
        return Theta, dTheta

    def effector(self):
        return delta.forward(self.geometry, self.alpha)

    def set_velocity(self, U, t):
        U = np.asarray(U, dtype=float)
        speed = np.linalg.norm(U, axis=1, keepdims=True)
        self.v = U * np.minimum(1.0, self.setup.max_speed / np.maximum(speed, 1e-300))
        self.received[:] = t

    def control(self, t, Theta, dTheta):
        alpha = self.theta0_used + Theta
        if self.hold is None:
            self.hold = _forward_by_group(self.groups, alpha)
        active = (t - self.received <= self.velocity_timeout)[:, None]
        if self.last_t is not None:
            self.hold = self.hold + np.where(active, self.v, 0.0) * max(t - self.last_t, 0.0)
        self.last_t = t
        v = np.where(active, self.v, 0.0)
        for desc, idx in self.groups:
            jm = dynamics.inverse_dynamics(desc, self.ctl_mass, self.hold[idx], v[idx], np.zeros((len(idx), 3)))
            self.command[idx] = ctl.velocity_command(jm.alpha, jm.dalpha, jm.tau, alpha[idx], dTheta[idx], self.gains)
        self.brakes = False

    def _accelerations(self, t, alpha, dalpha):
        alpha, dalpha = np.asarray(alpha).T, np.asarray(dalpha).T
        tau = np.clip(ctl.drive_torque(self.command, dalpha, self.drives.K_V),
                      -self.drives.torque_limit, self.drives.torque_limit)
        return dynamics.forward_dynamics(self.geometry, self.mass, alpha, dalpha, tau).T

    def step(self):
        if not self.brakes:
            alpha, dalpha = motors.rk4_step(self._accelerations, 0.0, self.alpha.T, self.dalpha.T, self.setup.dt)
            self.alpha, self.dalpha = np.asarray(alpha).T, np.asarray(dalpha).T


def _groups(descs):
    """[(description, indices)] for the runs sharing one description object."""
    out = {}
    for i, d in enumerate(descs):
        out.setdefault(id(d), (d, []))[1].append(i)
    return [(d, np.array(idx)) for d, idx in out.values()]


def _forward_by_group(groups, alpha):
    """Forward kinematics of each run's own description at absolute arm angles alpha (N, 3)."""
    P = np.empty_like(alpha)
    for desc, idx in groups:
        P[idx] = delta.forward(desc, alpha[idx])
    return P


# ----------------------------------------------------------------------------------------------
# The visual loop.

def exposure_ticks(n_frames, setup):
    """Control ticks at which frames 0..n_frames-1 are exposed: the first tick at or after k T_c."""
    return np.ceil(np.arange(n_frames) * setup.frame_period / setup.dt - 1e-9).astype(int)


class GroupFilter:
    """The ball filters of the runs that share one description, as one pbvs.BallKalman.

    BallKalman's algebra works column by column, and runs with the same camera rotation see the same
    measurement covariance at the same frame times, so their covariances P are identical: one filter
    carries every run's state [p, v] as a column of x (6, n).
    """

    def __init__(self, q, cov):
        self.kf, self.cov = pbvs.BallKalman(q), cov

    def update(self, z, dt):
        """Fuse the positions z (3, n) measured dt after the last ones (None: the first)."""
        if self.kf.x is None:
            self.kf.update(z[:, 0], self.cov)                     # starts P as BallKalman does
            self.kf.x = np.concatenate([z, np.zeros_like(z)])     # and every run at its own position
            return
        self.kf.predict(dt)
        self.kf.update(z, self.cov)

    @property
    def velocity(self):
        return self.kf.velocity


class BatchServo:
    """pbvs.Tracker's law for every run at once, vectorised: one GroupFilter per description.

    u_r is not clipped here: BatchPlant clips it to the same max_speed, as the motion controller does.
    """

    def __init__(self, descs, setup):
        self.setup, self.groups = setup, _groups(descs)
        self.theta0 = np.array([d.theta0 for d in descs])
        noise = NoiseModel(sigma_camera=setup.assumed_sigma)
        self.filters = [GroupFilter(setup.kalman_q, noise.cov_Pi(d.camera_rotation)) for d, _ in self.groups]
        self.last_t = None

    def command(self, t, s, Theta):
        """u_r (N, 3) for the detections s (N, 3, optical frame) exposed at t with the readings Theta (N, 3)."""
        dt = None if self.last_t is None else t - self.last_t
        self.last_t = t
        P_est = _forward_by_group(self.groups, self.theta0 + Theta)
        s_d = np.asarray(self.setup.s_d, dtype=float)
        U = np.empty_like(s)
        for (desc, idx), kf in zip(self.groups, self.filters):
            R = np.asarray(desc.camera_rotation, dtype=float)
            kf.update((P_est[idx] + s[idx] @ R.T).T, dt)
            v_p = kf.velocity if self.setup.feedforward else np.zeros((3, len(idx)))
            e_r = pbvs.relative_error(s[idx].T, R, s_d[:, None])
            U[idx] = pbvs.cartesian_command(e_r, v_p, self.setup.K_p).T
        return U


class TrackerServo:
    """One pbvs.Tracker per run (the object the pbvs_tracker node runs): the reference for BatchServo."""

    def __init__(self, descs, setup):
        self.trackers = [pbvs.Tracker(d, setup.K_p, setup.s_d, setup.max_speed, setup.kalman_q, setup.assumed_sigma,
                                      setup.feedforward) for d in descs]

    def command(self, t, s, Theta):
        return np.array([tracker.update(t, s_i, Theta_i)[0] for tracker, s_i, Theta_i in zip(self.trackers, s, Theta)])


ENGINES = {'batch': (BatchPlant, BatchServo), 'scalar': (ScalarPlant, TrackerServo)}


class VisualLoop:
    """The hand camera and a visual servo around a plant: one call per exposure.

    An exposure measures every run's ball in the optical frame from the TRUE positions and mounting
    plus the camera's bias and noise, and remembers the joints read at that tick; the detection is
    served ``latency_frames`` exposures later: the servo's u_r (BatchServo or TrackerServo) goes to
    the plant. Errors of the counted frames (after the warm-up) go to ``e_visual`` (|s - s_d|, the
    measurement) and ``e_true`` (|s_true - s_d|), each (N, n_samples), m.
    """

    def __init__(self, plant, servo, balls, truth, setup, n_samples, rng):
        self.plant, self.servo, self.balls, self.truth, self.setup, self.rng = plant, servo, balls, truth, setup, rng
        self.n_frames = setup.warmup_frames + n_samples
        self.e_visual, self.e_true = np.empty((len(balls), n_samples)), np.empty((len(balls), n_samples))
        self.pending, self.frame = deque(), 0

    def expose(self, t, Theta):
        """Take frame ``self.frame`` at time t; serve the one due. True once the last counted frame is served."""
        setup, s_d = self.setup, np.asarray(self.setup.s_d, dtype=float)
        B = np.array([b.at(t) for b in self.balls])
        s_true = (B - self.plant.effector() - self.truth.camera_translation) @ self.truth.camera_rotation
        s = s_true + np.asarray(setup.camera_bias) + self.rng.normal(size=s_true.shape) * np.asarray(setup.sigma_camera)
        self.pending.append((self.frame, t, s, Theta))
        if setup.warmup_frames <= self.frame < self.n_frames:
            self.e_true[:, self.frame - setup.warmup_frames] = np.linalg.norm(s_true - s_d, axis=1)
        self.frame += 1
        return len(self.pending) > setup.latency_frames and self.serve(t)

    def serve(self, t):
        """The oldest detection in: the servo's command to the plant at time t."""
        shown, t_shown, s, Theta = self.pending.popleft()
        U = self.servo.command(t_shown, s, Theta)
        if shown >= self.setup.warmup_frames:
            self.e_visual[:, shown - self.setup.warmup_frames] = np.linalg.norm(s - self.setup.s_d, axis=1)
        self.plant.set_velocity(U, t)
        return shown == self.n_frames - 1


def simulate(plant, servo, balls, truth, setup, n_samples, rng, progress=None):
    """Run the visual servoing loop on ``plant`` until ``n_samples`` frames after the warm-up are served.

    servo: BatchServo or TrackerServo of the descriptions the runs use; balls: one object with
    ``at(t)`` per run; plant: ScalarPlant, BatchPlant or anything with their methods. Each control
    tick: read the resolvers, expose a frame if one is due, control, step. Returns (e_visual,
    e_true), each (N, n_samples) in m (see VisualLoop).
    """
    loop = VisualLoop(plant, servo, balls, truth, setup, n_samples, rng)
    ticks = exposure_ticks(loop.n_frames + setup.latency_frames, setup)
    every = max(1, (loop.n_frames + 9) // 10)
    for k in range(ticks[-1] + 1):
        t = k * setup.dt
        Theta, dTheta = plant.read()
        if k == ticks[loop.frame]:
            if loop.expose(t, Theta):
                break
            if progress and loop.frame % every == 0:
                progress(loop.frame / loop.n_frames)
        plant.control(t, Theta, dTheta)
        plant.step()
    return loop.e_visual, loop.e_true


def kalman_gain(setup, W):
    """Steady-state gain K (6, 3) and transition (I - K H) F of BallKalman at the frame period, for
    measurement covariance W (3, 3): the filter's own covariance iterated until it settles."""
    T = setup.frame_period
    kf = pbvs.BallKalman(setup.kalman_q)
    kf.update(np.zeros(3), W)
    H = np.hstack([np.eye(3), np.zeros((3, 3))])
    for _ in range(5000):
        kf.predict(T)
        P_minus = kf.P.copy()
        kf.update(np.zeros(3), W)
    K = P_minus @ H.T @ np.linalg.inv(H @ P_minus @ H.T + W)
    F = np.eye(6)
    F[:3, 3:] = T * np.eye(3)
    return K, (np.eye(6) - K @ H) @ F


def ideal_plant(setup):
    """(A, B, C) of a robot that moves exactly at the commanded velocity: p_(k+1) = p_k + T v_k."""
    I3 = np.eye(3)
    return I3, setup.frame_period * I3, I3


def linearized_plant(truth, desc, setup, P, eps=1e-6, settle=0.3):
    """(A, B, C): one true robot with its motion controller (BatchPlant) over one frame, linearised
    at rest at P (m) by central differences: x_(k+1) = A x_k + B v_k and p_k = C x_k, with x the
    deviations of (alpha, alphad, held position), v the velocity command held over the frame and p
    the true effector position. Resolver counts and noise are left out (they are far below the camera
    noise); the frame must last a whole number of ticks, and the controller must not use kd.
    """
    ticks = int(round(setup.frame_period / setup.dt))
    if abs(ticks * setup.dt - setup.frame_period) > 1e-12 or ctl.Gains().kd != 0:
        raise ValueError("linearized_plant: needs a frame of whole ticks and a controller without kd")
    n = 12                                               # alpha, alphad, hold, v
    Theta = delta.inverse(truth.geometry, np.asarray(P, dtype=float)) - truth.geometry.theta0
    plant = BatchPlant(truth, [desc] * (2 * n + 1), np.tile(Theta, (2 * n + 1, 1)),
                       replace(setup, resolver_noise=0.0), np.random.default_rng(0), quantise=False)
    t = 0.0
    for _ in range(int(round(settle / setup.dt))):       # settle under gravity, no command
        plant.control(t, *plant.read())
        plant.step()
        t += setup.dt
    state = np.hstack([plant.alpha, plant.dalpha, plant.hold, np.zeros((2 * n + 1, 3))])
    state[1:] += np.vstack([eps * np.eye(n), -eps * np.eye(n)])
    plant.alpha, plant.dalpha, plant.hold = state[:, 0:3].copy(), state[:, 3:6].copy(), state[:, 6:9].copy()
    plant.set_velocity(state[:, 9:12], t)
    for _ in range(ticks):
        plant.control(t, *plant.read())
        plant.step()
        t += setup.dt
    after = np.hstack([plant.alpha, plant.dalpha, plant.hold])
    D = (after[1:n + 1] - after[n + 1:]).T / (2 * eps)   # (9, 12)
    alpha = state[0, 0:3]
    J = delta.jacobian(truth.geometry, delta.forward(truth.geometry, alpha), alpha)
    return D[:, :9], D[:, 9:], np.hstack([J, np.zeros((3, 6))])


def closed_loop(setup, R, plant=None):
    """The visual loop on a still ball as a linear system, frame by frame: S_(k+1) = M S_k + G w_k.

    Frame period T, L = latency_frames. The robot is a linear plant x_(k+1) = A x_k + B v_k,
    e_k = C x_k (``plant``; default ``ideal_plant``, or the ``linearized_plant`` of the simulated
    robot). The camera measures y_k = e_k + w_k, w_k its noise in the base frame, covariance
    W = R diag(sigma^2) R^T. The ball is still, so only the noise moves its measured position, and the
    filter at its steady gain K (for the noise it assumes, ``Setup.assumed_sigma``) is
    f_k = A_f f_(k-1) - K w_k; a camera bias only shifts e's mean and is left out. The command
    u_k = -K_p y_k + v_k (eq. 23, v_k the filter's velocity) drives the plant during frame k + L.
    State S_k = (x_k, f_(k-1), u_(k-1) .. u_(k-L)). Returns (M, G, W, Ce) with e_k = Ce S_k.
    """
    A, B, C = plant if plant is not None else ideal_plant(setup)
    L, nx = setup.latency_frames, A.shape[0]
    R = np.asarray(R, dtype=float)
    W = R @ np.diag(np.square(setup.sigma_camera)) @ R.T
    K, A_f = kalman_gain(setup, R @ np.diag(np.square(setup.assumed_sigma)) @ R.T)
    V = np.hstack([np.zeros((3, 3)), np.eye(3)]) if setup.feedforward else np.zeros((3, 6))
    ns = nx + 6 + 3 * L
    f, pend = slice(nx, nx + 6), [slice(nx + 6 + 3 * j, nx + 9 + 3 * j) for j in range(L)]
    Ux, Uw = np.zeros((3, ns)), -setup.K_p * np.eye(3) - V @ K      # u_k = Ux S_k + Uw w_k
    Ux[:, :nx] = -setup.K_p * C
    Ux[:, f] = V @ A_f
    M, G = np.zeros((ns, ns)), np.zeros((ns, 3))
    M[:nx, :nx] = A
    if L == 0:
        M[:nx] += B @ Ux
        G[:nx] = B @ Uw
    else:
        M[:nx, pend[-1]] = B
        M[pend[0]], G[pend[0]] = Ux, Uw
        for j in range(1, L):
            M[pend[j], pend[j - 1]] = np.eye(3)
    M[f, f], G[f] = A_f, -K
    Ce = np.zeros((3, ns))
    Ce[:, :nx] = C
    return M, G, W, Ce


def noise_response(setup, R, n_samples, runs=1, plant=None, max_lag=3000):
    """Mean square of the true error (m^2) on a still ball, from the camera noise and the delays alone,
    and the standard error of its estimate from ``runs`` runs of ``n_samples`` frames.

    The stationary covariance of ``closed_loop`` solves a discrete Lyapunov equation; the
    autocovariances C(tau) of e give the variance of a sample mean of |e|^2 for a Gaussian process,
    (2/n) sum_tau tr(C(tau) C(tau)^T).
    """
    from scipy.linalg import solve_discrete_lyapunov

    M, G, W, Ce = closed_loop(setup, R, plant)
    if max(abs(np.linalg.eigvals(M))) >= 1:
        raise ValueError("noise_response: the linear loop is unstable for this setup")
    S = solve_discrete_lyapunov(M, G @ W @ G.T)
    C0 = Ce @ S @ Ce.T
    total, MS = np.sum(C0 * C0), S @ Ce.T
    for _ in range(max_lag):
        MS = M @ MS
        Ct = Ce @ MS
        total += 2 * np.sum(Ct * Ct)
    return float(np.trace(C0)), float(np.sqrt(2 * total / (n_samples * runs)))


# ----------------------------------------------------------------------------------------------
# Scenario: where the ball flies and where the robot starts.

def robot_offset(truth, setup):
    """Ball minus effector (base frame, m) when the ball is exactly at s_d in the true camera."""
    return truth.camera_translation + truth.camera_rotation @ np.asarray(setup.s_d, dtype=float)


def make_ball(truth, setup, speed, test):
    """The chaotic ball of one test: test index = seed, the robot's cube shifted by the camera offset."""
    centre = np.asarray(setup.robot_centre) + robot_offset(truth, setup)
    return sim_ball.ChaoticBall(centre, setup.half_size, speed, seed=test, duration=BALL_PATH_DURATION)


def check_region(descs, truth, setup):
    """Raise ValueError unless the robot's box (plus a 50 mm margin) is usable for every description."""
    corners = np.array(np.meshgrid(*[[-1.0, 1.0]] * 3, indexing='ij')).reshape(3, -1).T
    P = np.asarray(setup.robot_centre) + corners * (np.asarray(setup.half_size) + 0.05)
    for desc in [truth.geometry, *descs]:
        if not np.all(workspace.Workspace().contains(desc, P)):
            raise ValueError(f"tracking: the robot's box {setup.half_size} m about {setup.robot_centre} "
                             "leaves the usable workspace")


def start_position(truth, setup, balls):
    """Resolver increments (N, 3) that put each true robot at the reference relative to its ball at t=0."""
    P = np.array([b.at(0.0) for b in balls]) - robot_offset(truth, setup)
    return delta.inverse(truth.geometry, P) - truth.geometry.theta0


def check_truth(truth):
    """The study simulates the truth's geometry and camera mounting only: refuse joint-level effects."""
    unsupported = sorted(set(truth.effects) - {'base_geometry', 'hand_eye_rotation'})
    if unsupported:
        raise ValueError(f"tracking: truth effects {', '.join(unsupported)} are not simulated by this study")


class ShiftedBall:
    """A ball whose clock starts ``t0`` seconds into another ball's path."""

    def __init__(self, ball, t0):
        self.ball, self.t0 = ball, float(t0)

    def at(self, t):
        return self.ball.at(np.asarray(t) + self.t0)


def segments(samples, setup):
    """(count, length): a test's samples cut into ``count`` pieces of ``length`` <= segment_samples
    (count x length may exceed ``samples``: the extra samples at the end are dropped)."""
    count = -(-samples // setup.segment_samples)
    return count, -(-samples // count)


def run_description(label, desc, truth, speeds, tests, samples, setup, seed, engine='batch', progress=True):
    """All speeds x tests of one description: (visual, true) per-test means, each (len(speeds), tests), m.

    A test is ``samples`` consecutive frames of one ball path. Its segments are simulated side by
    side, each from ``warmup_frames`` before its first frame with the robot at the reference and the
    filter at rest: after the warm-up (8 time constants 1/K_p) the start no longer shows, so the
    counted samples are those of one continuous test, and the batch is wider (numpy's cost per call
    dominates, so a wide batch is almost free).
    """
    count, length = segments(samples, setup)
    balls = []
    for v in speeds:
        for j in range(tests):
            path = make_ball(truth, setup, v, j)
            needed = (setup.warmup_frames + count * length + setup.latency_frames + 1) * setup.frame_period
            if path.duration < needed:
                raise ValueError(f"tracking: the ball's path lasts {path.duration:.1f} s, a test needs {needed:.1f} s")
            balls += [ShiftedBall(path, m * length * setup.frame_period) for m in range(count)]
    descs = [desc] * len(balls)
    rng = np.random.default_rng(seed)
    plant_rng, camera_rng = (np.random.default_rng(s) for s in rng.integers(2 ** 32, size=2))
    Plant, Servo = ENGINES[engine]
    plant = Plant(truth, descs, start_position(truth, setup, balls), setup, plant_rng)
    start = time.perf_counter()

    def report(fraction):
        if progress:
            print(f'tracking [{label}]: {100 * fraction:3.0f} % ({time.perf_counter() - start:.0f} s)',
                  file=sys.stderr, flush=True)

    e_visual, e_true = simulate(plant, Servo(descs, setup), balls, truth, setup, length, camera_rng, report)
    shape = (len(speeds), tests, count * length)
    return (e_visual.reshape(shape)[..., :samples].mean(axis=2), e_true.reshape(shape)[..., :samples].mean(axis=2))


def _load(desc):
    return description.load(desc) if isinstance(desc, (str, os.PathLike)) else desc


def run(quick=False, tests=None, samples=None, speeds=SPEEDS, descriptions=None, truth=None, setup=Setup(),
        seed=0, workers=None, progress=True):
    """Table 5 in simulation: a TrackingTable.

    quick: 2 tests of 1,000 samples per speed instead of 10 of 5,000 (``tests``/``samples`` override);
    descriptions: {label: RobotDescription or YAML path}, default the nominal description and the
    truth's geometry (what a perfect calibration finds; on the default truth, Table 1's calibrated
    column); truth: a robotenis_sim Truth, default the simulator's default; workers: processes, one
    description each (default: as many as descriptions and CPUs allow). Progress goes to stderr.
    """
    truth = truth or sim_truth.load()
    check_truth(truth)
    tests = (QUICK_TESTS if quick else TESTS) if tests is None else tests
    samples = (QUICK_SAMPLES if quick else SAMPLES) if samples is None else samples
    if tests < 1 or samples < 1 or not speeds or min(speeds) <= 0:
        raise ValueError(f"tracking: need tests >= 1, samples >= 1 and positive speeds "
                         f"(got {tests}, {samples}, {speeds})")
    descriptions = descriptions or {'nominal': description.nominal(), 'calibrated': truth.geometry}
    descriptions = {label: _load(d) for label, d in descriptions.items()}
    check_region(list(descriptions.values()), truth, setup)
    workers = workers or min(len(descriptions), os.cpu_count() or 1)
    args = [(label, d, truth, tuple(speeds), tests, samples, setup, seed) for label, d in descriptions.items()]
    start = time.perf_counter()
    if workers > 1:
        with ProcessPoolExecutor(workers) as pool:
            futures = [pool.submit(run_description, *a, progress=progress) for a in args]
            results = [f.result() for f in futures]
    else:
        results = [run_description(*a, progress=progress) for a in args]
    labels = tuple(descriptions)
    return TrackingTable(tuple(speeds), labels, {k: r[0] for k, r in zip(labels, results)},
                         {k: r[1] for k, r in zip(labels, results)}, tests, samples, setup,
                         time.perf_counter() - start)


# ----------------------------------------------------------------------------------------------
# Presentation.

def paper_row(speed):
    """(nominal, calibrated) of the paper's Table 5 at a speed (m/s), in mm; None off the table."""
    mm = round(speed * 1e3)
    if mm not in paper.TABLE5_SPEEDS:
        return None
    i = paper.TABLE5_SPEEDS.index(mm)
    return paper.TABLE5_NOMINAL[i], paper.TABLE5_CALIBRATED[i]


def _paired(table, a, b, kind):
    """Mean over tests of (a - b) per speed, and its standard error (mm)."""
    d = 1e3 * (getattr(table, kind)[a] - getattr(table, kind)[b])
    se = d.std(axis=1, ddof=1) / np.sqrt(d.shape[1]) if d.shape[1] > 1 else np.full(len(d), np.nan)
    return d.mean(axis=1), se


def table_lines(table):
    """Text lines: Table 5's layout, the paper's numbers beside ours (mm)."""
    labels, width = table.labels, max(16, *(len(lab) for lab in table.labels))
    lines = [f'Table 5, tracking error mean (mm): {table.tests} tests of {table.samples} samples per speed '
             f'(paper: 10 x 5,000), K_p = {table.setup.K_p:g}/s, '
             f'{"with" if table.setup.feedforward else "WITHOUT"} the Kalman velocity feedforward']
    for kind, title in (('visual', 'visual error |e_r|, as the paper measures it'),
                        ('true', 'true error |s_true - s_d| (without the camera noise)')):
        lines += [f'{title}: mean over the tests +- spread of the test means',
                  f'  {"speed (mm/s)":>12s}  {"paper nominal":>13s}  {"paper calibr.":>13s}'
                  + ''.join(f'  {lab:>{width}s}' for lab in labels)]
        for j, v in enumerate(table.speeds):
            ref = paper_row(v)
            ref_txt = f'{ref[0]:13.2f}  {ref[1]:13.2f}' if ref else f'{"-":>13s}  {"-":>13s}'
            ours = ''.join(f'  {f"{table.mean_mm(lab, kind)[j]:.2f} +- {table.std_mm(lab, kind)[j]:.2f}":>{width}s}'
                           for lab in labels)
            lines.append(f'  {1e3 * v:12.0f}  {ref_txt}{ours}')
    if len(labels) >= 2:
        a, b = labels[0], labels[1]
        lines.append(f'{a} minus {b}, paired over the tests (+- standard error), relative to {a}:')
        dv, sv = _paired(table, a, b, 'visual')
        dt, st = _paired(table, a, b, 'true')
        for j, v in enumerate(table.speeds):
            ref = paper_row(v)
            ref_txt = f'paper {100 * (ref[0] - ref[1]) / ref[0]:4.1f} %' if ref else 'paper -'
            lines.append(f'  {1e3 * v:12.0f}  visual {dv[j]:+.4f} +- {sv[j]:.4f} mm '
                         f'({100 * dv[j] / table.mean_mm(a)[j]:+.1f} %), true {dt[j]:+.4f} +- {st[j]:.4f} mm '
                         f'({100 * dt[j] / table.mean_mm(a, "true")[j]:+.1f} %); {ref_txt}')
    return lines


def plot(table, path):
    """PNG of the tracking error against the ball's top speed: the paper's Table 5 beside ours."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    speeds = 1e3 * np.asarray(table.speeds)
    fig, ax = plt.subplots(figsize=(7, 4.5))
    ax.plot(paper.TABLE5_SPEEDS, paper.TABLE5_NOMINAL, 'ks-', mfc='none', label='paper, nominal')
    ax.plot(paper.TABLE5_SPEEDS, paper.TABLE5_CALIBRATED, 'k^--', mfc='none', label='paper, calibrated')
    for k, label in enumerate(table.labels):
        color = f'C{k}'
        ax.errorbar(speeds + 8 * k, table.mean_mm(label), yerr=table.std_mm(label), fmt='o-', color=color,
                    capsize=3, label=f'simulated, {label} (visual, +- spread over tests)')
        ax.plot(speeds + 8 * k, table.mean_mm(label, 'true'), ':', color=color, label=f'simulated, {label} (true)')
    ax.set_xlabel('maximum speed of the ball (mm/s)')
    ax.set_ylabel('tracking error mean (mm)')
    ax.set_title(f'Tracking (Table 5): {table.tests} tests x {table.samples} samples per speed')
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    folder = os.path.dirname(os.path.abspath(path))
    os.makedirs(folder, exist_ok=True)
    tmp = os.path.join(folder, f'.{os.path.basename(path)}.{os.getpid()}.tmp.png')
    try:
        fig.savefig(tmp, dpi=110)
        os.replace(tmp, path)
    finally:
        plt.close(fig)
        if os.path.exists(tmp):
            os.unlink(tmp)
