"""
Position-based visual servoing of the RoboTenis (calibration paper, section 6.2, eqs. 23-25).

The camera sees the ball at s (optical frame); the robot wants it at s_d (centred, 600 mm ahead).
With R the camera rotation (optical axes in the effector frame, which is parallel to the base), the
error of the robot's position relative to the ball is e_r = -R (s - s_d), and the law

    u_r = -K_p e_r + v_p          (23)      u_q = J_R^-1 u_r          (25)

drives it to zero while v_p, the ball's velocity from a Kalman filter on its measured positions,
feeds the motion forward. J_R^-1 comes from the robot description in use (nominal or calibrated);
the tracking error reported is |e_r|. ``Tracker`` puts the pieces together for one robot: what the
pbvs_tracker node and the tracking study's reference engine both run.
"""
from collections import deque

import numpy as np

from robotenis_control.controller import MOVING
from robotenis_kinematics import delta, effects

K_P = 16.8                                  # 1/s, the paper's gain
S_DESIRED = np.array([0.0, 0.0, 0.600])     # m: ball centred in the image, 600 mm ahead
MAX_SPEED = 2.5                             # m/s: u_r is clipped to this
KALMAN_Q = 20.0                             # m^2/s^3: the ball's white acceleration (BallKalman)
# One detection's noise along the optical x, y, z (m). The paper's Table 2 gives single frames at
# 200 mm (0.014, 0.038, 0.092 mm; Table 3 is for averages of 500 frames); at 600 mm the lateral
# noise grows with the distance (x3) and the depth noise, from the apparent size, with its square
# (x9).
SIGMA_CAMERA = (0.042e-3, 0.114e-3, 0.83e-3)
LOST_S = 0.5                                # s without a detection: ball lost, its filter restarts


def relative_error(s, R, s_desired=S_DESIRED):
    """Return e_r = -R (s - s_d) (m, base frame): the robot's offset from where it should be."""
    return -np.asarray(R) @ (np.asarray(s, dtype=float) - s_desired)


def cartesian_command(e_r, v_p, K_p=K_P):
    """Return u_r = -K_p e_r + v_p (eq. 23), m/s in the base frame."""
    return -K_p * np.asarray(e_r) + np.asarray(v_p)


def clip_speed(u, max_speed):
    """Return u scaled down to max_speed if it is faster (m/s)."""
    speed = float(np.linalg.norm(u))
    return u * (max_speed / speed) if speed > max_speed else u


def joint_command(J_inv, u_r):
    """Return u_q = J_R^-1 u_r (eq. 25), rad/s."""
    return np.asarray(J_inv) @ np.asarray(u_r)


class BallKalman:
    """
    Constant-velocity Kalman filter on the ball's position (base frame).

    State x = [p, v] (6). The ball's acceleration is modelled as white noise of spectral density q
    (m^2/s^3): a chaotic ball that turns at 1.5 m/s needs q of order (a_max)^2 * tau.
    """

    def __init__(self, q=KALMAN_Q):
        self.q = q
        self.x = None
        self.P = None

    def predict(self, dt):
        F = np.eye(6)
        F[:3, 3:] = dt * np.eye(3)
        G = np.block([[dt ** 3 / 3 * np.eye(3), dt ** 2 / 2 * np.eye(3)],
                      [dt ** 2 / 2 * np.eye(3), dt * np.eye(3)]])
        self.x = F @ self.x
        self.P = F @ self.P @ F.T + self.q * G

    def update(self, z, R):
        """Fuse a measured position z (3,) with covariance R (3, 3); start the filter if needed."""
        z = np.asarray(z, dtype=float)
        if self.x is None:
            self.x = np.concatenate([z, np.zeros(3)])
            # v unknown: (2 m/s)^2
            self.P = np.block([[R, np.zeros((3, 3))], [np.zeros((3, 3)), np.eye(3) * 4.0]])
            return
        H = np.hstack([np.eye(3), np.zeros((3, 3))])
        S = H @ self.P @ H.T + R
        K = self.P @ H.T @ np.linalg.inv(S)
        self.x = self.x + K @ (z - H @ self.x)
        self.P = (np.eye(6) - K @ H) @ self.P

    @property
    def velocity(self):
        return np.zeros(3) if self.x is None else self.x[3:].copy()


class Tracker:
    """
    Eq. 23 for one robot, one detection at a time: the ball's filter, e_r and the command u_r.

    desc: the robot description in use (forward kinematics and camera rotation R); K_p (1/s) and
    s_desired (m, optical frame) are eq. 23's gain and reference; max_speed (m/s) clips u_r;
    kalman_q is BallKalman's q; sigma_camera (m, optical x, y, z) one detection's noise, which the
    filter sees in the base frame as R diag(sigma^2) R^T; feedforward=False drops v_p (the pure
    proportional law); a gap of more than lost_after seconds between detections restarts the
    filter, since its velocity is then stale.
    """

    def __init__(self, desc, K_p=K_P, s_desired=S_DESIRED, max_speed=MAX_SPEED,
                 kalman_q=KALMAN_Q, sigma_camera=SIGMA_CAMERA, feedforward=True,
                 lost_after=LOST_S):
        self.desc, self.K_p, self.max_speed = desc, float(K_p), float(max_speed)
        self.s_desired = np.asarray(s_desired, dtype=float)
        self.q, self.feedforward, self.lost_after = (float(kalman_q), bool(feedforward),
                                                     float(lost_after))
        R = desc.camera_rotation
        self.cov = R @ np.diag(np.square(np.asarray(sigma_camera, dtype=float))) @ R.T
        self.kalman, self.last_t = None, None
        self.joint_fx = {k: v for k, v in effects.parameters(desc).items()
                         if effects.is_joint_effect(k)}
        self.direction, self.last_Theta = np.ones(3), None

    def update(self, t, s, Theta):
        """
        Return the command for one detection: (u_r, e_r), or None for a stale one.

        Detection s (3,) in the optical frame (m), exposed at time t (s) while the resolvers read
        Theta (rad, increments from home). Returns (u_r, e_r) in the base frame (m/s, m), or None
        if t is not after the last detection's (a repeat, or out of order: the filter cannot go
        back).
        """
        if self.last_t is not None and t <= self.last_t:
            return None
        dt, self.last_t = (None if self.last_t is None else t - self.last_t), t
        s = np.asarray(s, dtype=float)
        v_p = self.ball_velocity(dt, s, Theta) if self.feedforward else np.zeros(3)
        e_r = relative_error(s, self.desc.camera_rotation, self.s_desired)
        return clip_speed(cartesian_command(e_r, v_p, self.K_p), self.max_speed), e_r

    def ball_velocity(self, dt, s, Theta):
        """
        Return v_p after fusing the ball's base-frame position P_est + R s (``effector``).

        The position is measured dt seconds after the previous detection (None: the first).
        """
        if self.kalman is None or dt > self.lost_after:
            self.kalman = BallKalman(self.q)
        else:
            self.kalman.predict(dt)
        self.kalman.update(self.effector(dt, Theta) + self.desc.camera_rotation @ s, self.cov)
        return self.kalman.velocity

    def effector(self, dt, Theta):
        """
        Return P_est: forward kinematics of the description's arm angles for the readings Theta.

        The arm angles come with the description's joint effects (a calibrated model's gear scale,
        backlash, sag) as the motion controller applies them; each joint's motion direction from
        the readings since the last detection (dt seconds ago).
        """
        Theta = np.asarray(Theta, dtype=float)
        base = self.desc.theta0 + Theta
        if not self.joint_fx:
            return delta.forward(self.desc, base)
        if self.last_Theta is not None and dt:
            step = Theta - self.last_Theta
            self.direction = np.where(np.abs(step) > MOVING * dt, np.sign(step), self.direction)
        self.last_Theta = Theta
        P = delta.forward(self.desc, base)
        theta = effects.model_joint_angles(self.desc, self.joint_fx, Theta[None],
                                           self.direction[None], P[None],
                                           effects.gravity_load(self.desc))[0][0]
        return delta.forward(self.desc, theta)


class ReadingMatcher:
    """
    Pairs each detection with the joint reading nearest its exposure.

    A detection waits for a joint reading at or after its exposure: a node's executor may hand
    the detection over before the readings queued ahead of it, and an older reading would
    misplace the ball by the robot's motion since then (5 mm at 1 m/s and 5 ms), which the ball's
    filter would take for a jump. ``reading`` and ``detection`` return the pairs ready to track, as
    (t, s, key, Theta) with Theta None when no reading lies within ``match_s`` of the exposure.
    """

    STAMP_TOLERANCE = 1e-6   # s: stamps travel in whole nanoseconds

    def __init__(self, match_s=0.02, history=200, waiting=10):
        """Keep ``history`` readings and ``waiting`` detections (more: the readings stopped)."""
        self.match_s = match_s
        self.readings = deque(maxlen=history)      # (t, Theta)
        self.waiting = deque(maxlen=waiting)       # (t, s, key) ahead of their reading

    def reading(self, t, Theta):
        """Record a joint reading at time t; return the detections that were waiting for it."""
        self.readings.append((t, Theta))
        ready = []
        while self.waiting and self.waiting[0][0] <= t + self.STAMP_TOLERANCE:
            ready.append(self._pair(*self.waiting.popleft()))
        return ready

    def detection(self, t, s, key=None):
        """Take a detection exposed at t; return it paired, or nothing while its reading is due."""
        if not self.readings or self.readings[-1][0] < t - self.STAMP_TOLERANCE:
            self.waiting.append((t, s, key))
            return []
        return [self._pair(t, s, key)]

    def clear(self):
        """Forget the detections waiting (e.g. for a tracker just replaced)."""
        self.waiting.clear()

    def _pair(self, t, s, key):
        stamp, Theta = min(self.readings, key=lambda r: abs(r[0] - t))
        return t, s, key, (Theta if abs(stamp - t) <= self.match_s else None)
