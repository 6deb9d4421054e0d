"""
The tracking loop simulated without ROS: the robots, the visual servo and the camera between them.

Two engines run the same loop. ``ScalarPlant`` and ``TrackerServo`` step the project's
SimulatedMotors, MotionController and pbvs.Tracker objects one robot at a time (the reference, what
the ROS nodes run); ``BatchPlant`` and ``BatchServo`` step all runs at once with the same
equations vectorised over runs (motors.BatchMotors, controller.BatchVelocityController, one
pbvs.BallKalman carrying every run's state); a test checks that both give the same errors.
``simulate`` runs the loop: each control tick reads the resolvers, exposes a frame if one is due
(the detection is served ``latency_frames`` later), controls and steps.
"""
from collections import deque

import numpy as np
from robotenis_control import controller as ctl
from robotenis_control import pbvs
from robotenis_kinematics.synthetic import NoiseModel
from robotenis_sim import motors


class ScalarPlant:
    """N true robots (SimulatedMotors) with a MotionController each: the project's own objects."""

    def __init__(self, truth, descs, Theta_start, setup, rng):
        mass = motors.true_masses(truth)
        resolver = motors.ResolverParameters(noise=setup.resolver_noise)
        self.sims = [motors.SimulatedMotors(truth.geometry, mass, resolver=resolver, dt=setup.dt,
                                            rng=np.random.default_rng(rng.integers(2 ** 32)),
                                            Theta_start=th)
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
    """
    The same N robots and controllers, vectorised over runs.

    Robots: motors.BatchMotors of the truth (``quantise=False`` reads the resolvers without their
    counts, for tracking_linear.linearized_plant); controllers: controller.BatchVelocityController
    on each run's description, its commands clipped to ``setup.max_speed``. The workspace check of
    MotionController is left out: tracking_setup.check_region keeps the robots inside it.
    """

    def __init__(self, truth, descs, Theta_start, setup, rng, gains=ctl.Gains(),
                 velocity_timeout=0.1, quantise=True):
        self.motors = motors.BatchMotors(
            truth.geometry, motors.true_masses(truth), Theta_start,
            resolver=motors.ResolverParameters(noise=setup.resolver_noise), dt=setup.dt, rng=rng,
            quantise=quantise)
        self.controller = ctl.BatchVelocityController(descs, gains=gains,
                                                      max_speed=setup.max_speed,
                                                      velocity_timeout=velocity_timeout)

    def read(self):
        return self.motors.read()

    def effector(self):
        return self.motors.effector()

    def set_velocity(self, U, t):
        self.controller.set_velocity(U, t)

    def control(self, t, Theta, dTheta):
        self.motors.set_command(self.controller.update(t, Theta, dTheta))

    def step(self):
        self.motors.step()


def exposure_ticks(n_frames, setup):
    """List the control ticks exposing frames 0..n_frames-1: the first tick at or after k T_c."""
    return np.ceil(np.arange(n_frames) * setup.frame_period / setup.dt - 1e-9).astype(int)


class GroupFilter:
    """
    The ball filters of the runs that share one description, as one pbvs.BallKalman.

    BallKalman's algebra works column by column, and runs with the same camera rotation see the
    same measurement covariance at the same frame times, so their covariances P are identical: one
    filter carries every run's state [p, v] as a column of x (6, n).
    """

    def __init__(self, q, cov):
        self.kf, self.cov = pbvs.BallKalman(q), cov

    def update(self, z, dt):
        """Fuse the positions z (3, n) measured dt after the last ones (None: the first)."""
        if self.kf.x is None:
            # starts P as BallKalman does, and every run at its own position
            self.kf.update(z[:, 0], self.cov)
            self.kf.x = np.concatenate([z, np.zeros_like(z)])
            return
        self.kf.predict(dt)
        self.kf.update(z, self.cov)

    @property
    def velocity(self):
        return self.kf.velocity


class BatchServo:
    """
    pbvs.Tracker's law for every run at once, vectorised: one GroupFilter per description.

    u_r is not clipped here: BatchPlant clips it to the same max_speed, as the motion controller
    does.
    """

    def __init__(self, descs, setup):
        self.setup, self.groups = setup, ctl.description_groups(descs)
        self.theta0 = np.array([d.theta0 for d in descs])
        noise = NoiseModel(sigma_camera=setup.assumed_sigma)
        self.filters = [GroupFilter(setup.kalman_q, noise.cov_Pi(d.camera_rotation))
                        for d, _ in self.groups]
        self.last_t = None

    def command(self, t, s, Theta):
        """
        Return u_r (N, 3) for the detections s (N, 3, optical frame) exposed at t.

        Theta (N, 3) are the readings taken with them.
        """
        dt = None if self.last_t is None else t - self.last_t
        self.last_t = t
        P_est = ctl.forward_by_group(self.groups, self.theta0 + Theta)
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
    """One pbvs.Tracker per run (what the pbvs_tracker node runs): the reference for BatchServo."""

    def __init__(self, descs, setup):
        self.trackers = [pbvs.Tracker(d, setup.K_p, setup.s_d, setup.max_speed, setup.kalman_q,
                                      setup.assumed_sigma, setup.feedforward) for d in descs]

    def command(self, t, s, Theta):
        return np.array([tracker.update(t, s_i, Theta_i)[0]
                         for tracker, s_i, Theta_i in zip(self.trackers, s, Theta)])


ENGINES = {'batch': (BatchPlant, BatchServo), 'scalar': (ScalarPlant, TrackerServo)}


class VisualLoop:
    """
    The hand camera and a visual servo around a plant: one call per exposure.

    An exposure measures every run's ball in the optical frame from the TRUE positions and mounting
    plus the camera's bias and noise, and remembers the joints read at that tick; the detection is
    served ``latency_frames`` exposures later: the servo's u_r (BatchServo or TrackerServo) goes to
    the plant. Errors of the counted frames (after the warm-up) go to ``e_visual`` (|s - s_d|, the
    measurement) and ``e_true`` (|s_true - s_d|), each (N, n_samples), m.
    """

    def __init__(self, plant, servo, balls, truth, setup, n_samples, rng):
        self.plant, self.servo, self.balls = plant, servo, balls
        self.truth, self.setup, self.rng = truth, setup, rng
        self.n_frames = setup.warmup_frames + n_samples
        self.e_visual = np.empty((len(balls), n_samples))
        self.e_true = np.empty((len(balls), n_samples))
        self.pending, self.frame = deque(), 0

    def expose(self, t, Theta):
        """
        Take frame ``self.frame`` at time t; serve the one due.

        True once the last counted frame is served.
        """
        setup, s_d = self.setup, np.asarray(self.setup.s_d, dtype=float)
        B = np.array([b.at(t) for b in self.balls])
        s_true = ((B - self.plant.effector() - self.truth.camera_translation)
                  @ self.truth.camera_rotation)
        s = (s_true + np.asarray(setup.camera_bias)
             + self.rng.normal(size=s_true.shape) * np.asarray(setup.sigma_camera))
        self.pending.append((self.frame, t, s, Theta))
        if setup.warmup_frames <= self.frame < self.n_frames:
            self.e_true[:, self.frame - setup.warmup_frames] = np.linalg.norm(s_true - s_d, axis=1)
        self.frame += 1
        return len(self.pending) > setup.latency_frames and self.serve(t)

    def serve(self, t):
        """Feed the oldest detection to the servo and its command to the plant at time t."""
        shown, t_shown, s, Theta = self.pending.popleft()
        U = self.servo.command(t_shown, s, Theta)
        if shown >= self.setup.warmup_frames:
            column = shown - self.setup.warmup_frames
            self.e_visual[:, column] = np.linalg.norm(s - self.setup.s_d, axis=1)
        self.plant.set_velocity(U, t)
        return shown == self.n_frames - 1


def simulate(plant, servo, balls, truth, setup, n_samples, rng, progress=None):
    """
    Run the visual servoing loop on ``plant`` until ``n_samples`` frames after warm-up are served.

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
