"""
Nonlinear feedforward PD through velocity-command drives (dynamics paper, eqs. 10-11).

The drives close a velocity loop and accept no torque (eq. 10):

    tau = K_V (alphad_ref - alphad)

The law of eq. 11 as printed, alphad_ref = K_p e + K_d ed + K_V^-1 tau_d (e = alpha_d - alpha),
would leave tau = tau_d - K_V alphad_d on the desired motion: the drive's own velocity feedback
brakes the arm, and the position error must grow to alphad_d / K_p (40 mm at 4 m/s and
K_p = 100/s) to push against it. So the desired velocity is also commanded, as a velocity servo
needs:

    alphad_ref = alphad_d + K_p (alpha_d - alpha) + K_d (alphad_d - alphad) + K_V^-1 tau_d    (11)

which gives tau = tau_d + K_V K_p e + K_V (1 + K_d) ed, a PD around the model's torque, with K_V
the derivative gain the drive provides by itself (so K_d = 0 is a sensible default and the
controller then needs no velocity measurement). tau_d comes from the inverse dynamics (eqs. 4-5) of
the desired Cartesian motion; IK, Jacobians and dynamics all use the robot description in use
(nominal or calibrated), which can be replaced while running. A calibrated description's joint
effects (gear ratio, backlash, compliance) turn the readings into arm angles before the law
compares them.
"""
from dataclasses import dataclass

import numpy as np

from robotenis_control import dynamics, trajectory
from robotenis_kinematics import delta, effects, workspace

MOVING = 1e-3   # rad/s: a joint faster than this sets its motion direction (for backlash)


@dataclass(frozen=True)
class Gains:
    """
    The gains of eq. 11: kp, kd and the controller's value of K_V.

    kp (1/s) on the joint position error, kd (dimensionless) on the joint velocity error, and kv
    (N m s/rad), the controller's value of the drives' velocity gain K_V (eq. 10).
    """

    kp: float = 150.0
    kd: float = 0.0
    kv: float = 60.0

    def __post_init__(self):
        if not (self.kp >= 0 and self.kd >= 0 and self.kv > 0):
            raise ValueError(f'gains: need kp >= 0, kd >= 0, kv > 0 (got kp={self.kp}, '
                             f'kd={self.kd}, kv={self.kv})')


def drive_torque(dalpha_ref, dalpha, K_V):
    """Return tau = K_V (alphad_ref - alphad) (eq. 10): a velocity-command drive's torque (N m)."""
    return K_V * (np.asarray(dalpha_ref) - np.asarray(dalpha))


def velocity_command(alpha_d, dalpha_d, tau_d, alpha, dalpha, gains):
    """Return eq. 11's alphad_ref (rad/s), desired velocity commanded (see module docstring)."""
    alpha_d, dalpha_d = np.asarray(alpha_d), np.asarray(dalpha_d)
    return (dalpha_d + gains.kp * (alpha_d - np.asarray(alpha))
            + gains.kd * (dalpha_d - np.asarray(dalpha)) + np.asarray(tau_d) / gains.kv)


class GoalError(ValueError):
    """A goal or a velocity command the robot cannot follow; the message says why."""


class MotionController:
    """
    Cartesian goals and velocity commands in, drive velocity commands out, one tick at a time.

    Goals are chained rest to rest (4-5-6-7 segments, trajectory.Chain timing) after whatever
    motion is planned. A Cartesian velocity command replaces the plan: the desired position
    integrates it for as long as commands keep coming (``velocity_timeout``), then holds. Times are
    seconds on the caller's clock; joint readings are resolver increments Theta (rad) from home.
    """

    def __init__(self, desc, mass=dynamics.MassParameters(), gains=Gains(), max_speed=2.0,
                 max_acceleration=4 * dynamics.G, velocity_timeout=0.1,
                 region=workspace.Workspace()):
        if max_speed <= 0 or max_acceleration <= 0:
            raise ValueError('max_speed and max_acceleration must be positive, '
                             f'got {max_speed}, {max_acceleration}')
        self.mass, self.gains = mass, gains
        self.set_description(desc)
        self.max_speed, self.max_acceleration = float(max_speed), float(max_acceleration)
        self.velocity_timeout, self.region = velocity_timeout, region
        self.segments = []          # planned segments, oldest first
        self.hold = None            # desired position when nothing moves (m)
        self.velocity = None        # (v (3,), time received) in velocity mode
        self.last_t = None

    def set_description(self, desc):
        """Use another robot description from the next tick (the plan stays in Cartesian space)."""
        self.desc = desc
        # per-tick IK, FK, inverse dynamics
        self.model = dynamics.SingleRobotDynamics(desc, self.mass)
        self.joint_fx = {k: v for k, v in effects.parameters(desc).items()
                         if effects.is_joint_effect(k)}
        self.direction = np.ones(3)

    def check_position(self, P, what='goal'):
        """Raise GoalError unless P is inside the usable workspace of the current description."""
        P = np.asarray(P, dtype=float)
        if P.shape != (3,) or not np.all(np.isfinite(P)):
            raise GoalError(f'{what}: expected three finite coordinates (m), got {P!r}')
        if not self.region.contains(self.desc, P):
            raise GoalError(f'{what} ({P[0]:.3f}, {P[1]:.3f}, {P[2]:.3f}) m is outside the usable '
                            'workspace')

    def add_goal(self, P, t):
        """Plan a straight segment to P after the current plan (or from the held position)."""
        P = np.asarray(P, dtype=float)
        self.check_position(P)
        if self.hold is None:
            raise GoalError('goal before the first joint reading: the start position is unknown')
        self._retire(t)
        if self.segments and self.velocity is None:
            start, start_t = self.segments[-1].P1, self.segments[-1].t1
        else:
            start, start_t = self.hold, t
        # a straight segment between two usable points can still cross a hole: check along it
        for u in np.linspace(0.0, 1.0, 21)[1:-1]:
            self.check_position(start + u * (P - start), 'path to the goal')
        self.velocity = None
        self.segments.append(trajectory.segment(start, P, start_t, self.max_speed,
                                                self.max_acceleration))

    def set_velocity(self, v, t):
        """Follow a Cartesian velocity (m/s, base frame) from now on, clipped to max_speed."""
        v = np.asarray(v, dtype=float)
        if v.shape != (3,) or not np.all(np.isfinite(v)):
            raise GoalError(f'velocity command: expected three finite components (m/s), got {v!r}')
        speed = np.linalg.norm(v)
        if speed > self.max_speed:
            v = v * (self.max_speed / speed)
        if self.segments:
            self.hold = np.array(self.desired(t)[0])
            self.segments = []
        self.velocity = (v, t)

    def desired(self, t):
        """Return (P, Pd, Pdd) desired at t; advance the hold (velocity mode, finished plan)."""
        zero = np.zeros(3)
        if self.velocity is not None:
            v, received = self.velocity
            dt = 0.0 if self.last_t is None else max(t - self.last_t, 0.0)
            if t - received > self.velocity_timeout:
                self.velocity = None
                return self.hold, zero, zero
            nxt = self.hold + v * dt
            if not self.region.contains(self.desc, nxt):
                self.velocity = None      # stop at the edge of the workspace rather than leave it
                return self.hold, zero, zero
            self.hold = nxt
            return self.hold, v, zero
        self._retire(t)
        if self.segments and self.segments[0].t0 <= t:
            return self.segments[0].at(t)
        return self.hold, zero, zero

    def _retire(self, t):
        """Drop the segments finished by time t; the robot is then held at the last one's end."""
        while self.segments and self.segments[0].t1 <= t:
            self.hold = self.segments.pop(0).P1

    def update(self, t, Theta, dTheta=None):
        """
        Run one control tick: resolver increments (rad) and rates (rad/s, only needed when kd > 0).

        Returns (alphad_ref (3,) rad/s for the drives, P_est (3,) m from the forward kinematics of
        the current description).
        """
        alpha = self.arm_angles(np.asarray(Theta, dtype=float), dTheta)
        P_est = np.array(self.model.forward_kinematics(alpha)[0])
        if self.hold is None:
            self.hold = P_est
        P_d, dP_d, ddP_d = self.desired(t)
        self.last_t = t
        alpha_d, dalpha_d, tau_d = self.model.inverse_dynamics(P_d, dP_d, ddP_d)
        dalpha = np.zeros(3) if dTheta is None else np.asarray(dTheta, dtype=float)
        return velocity_command(alpha_d, dalpha_d, tau_d, alpha, dalpha, self.gains), P_est

    def arm_angles(self, Theta, dTheta):
        """Return the arm angles for the readings under the joint effects of a calibrated model."""
        base = self.desc.theta0 + Theta
        if not self.joint_fx:
            return base
        if dTheta is not None:
            dTheta = np.asarray(dTheta, dtype=float)
            self.direction = np.where(np.abs(dTheta) > MOVING, np.sign(dTheta), self.direction)
        P = np.array(self.model.forward_kinematics(base)[0])
        return effects.model_joint_angles(self.desc, self.joint_fx, Theta[None],
                                          self.direction[None], P[None],
                                          effects.gravity_load(self.desc))[0][0]

    @property
    def moving(self):
        return bool(self.segments) or self.velocity is not None


def description_groups(descs):
    """Return [(description, indices)] of the runs that share one description object."""
    out = {}
    for i, d in enumerate(descs):
        out.setdefault(id(d), (d, []))[1].append(i)
    return [(d, np.array(idx)) for d, idx in out.values()]


def forward_by_group(groups, alpha):
    """Return the forward kinematics of each run's own description at arm angles alpha (N, 3)."""
    P = np.empty_like(alpha)
    for desc, idx in groups:
        P[idx] = delta.forward(desc, alpha[idx])
    return P


class BatchVelocityController:
    """
    MotionController's velocity mode for N runs at once, vectorised over runs.

    Each run follows its own description (``descs``, one per run; runs sharing a description
    object are computed together): the held position integrates the run's Cartesian command while
    it is fresher than ``velocity_timeout``, and eq. 11 on the inverse dynamics of the description
    gives the drive commands. Left out: goals, the workspace check and joint effects (the
    descriptions must declare none).
    """

    def __init__(self, descs, mass=dynamics.MassParameters(), gains=Gains(), max_speed=2.0,
                 velocity_timeout=0.1):
        joint = [d for d in descs if any(map(effects.is_joint_effect, effects.parameters(d)))]
        if joint:
            raise ValueError('BatchVelocityController: descriptions with joint effects '
                             'are not supported')
        self.mass, self.gains, self.max_speed = mass, gains, float(max_speed)
        self.velocity_timeout = velocity_timeout
        self.groups = description_groups(descs)
        self.theta0 = np.array([d.theta0 for d in descs])
        self.hold, self.last_t = None, None
        self.v = np.zeros((len(descs), 3))
        self.received = np.full(len(descs), -np.inf)
        self.command = np.zeros((len(descs), 3))

    def set_velocity(self, U, t):
        """Follow the Cartesian velocities U (N, 3), m/s, from t on; each clipped to max_speed."""
        U = np.asarray(U, dtype=float)
        speed = np.linalg.norm(U, axis=1, keepdims=True)
        self.v = U * np.minimum(1.0, self.max_speed / np.maximum(speed, 1e-300))
        self.received[:] = t

    def update(self, t, Theta, dTheta):
        """Return the drive commands (N, 3), rad/s, for the readings Theta, dTheta (N, 3) at t."""
        alpha = self.theta0 + Theta
        if self.hold is None:
            self.hold = forward_by_group(self.groups, alpha)
        active = (t - self.received <= self.velocity_timeout)[:, None]
        v = np.where(active, self.v, 0.0)
        if self.last_t is not None:
            self.hold = self.hold + v * max(t - self.last_t, 0.0)
        self.last_t = t
        for desc, idx in self.groups:
            jm = dynamics.inverse_dynamics(desc, self.mass, self.hold[idx], v[idx],
                                           np.zeros((len(idx), 3)))
            self.command[idx] = velocity_command(jm.alpha, jm.dalpha, jm.tau, alpha[idx],
                                                 dTheta[idx], self.gains)
        return self.command.copy()
