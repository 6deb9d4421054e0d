"""
The simulated motors: the robot's rigid-body dynamics driven by velocity-command drives.

State: the TRUE arm angles alpha (absolute, rad) and rates. Every control period (1 ms) the drives
hold the last velocity command and apply tau = K_V (alphad_ref - alphad) (dynamics paper, eq. 10),
continuously, as a drive's inner loop runs much faster than the 1 kHz controller; the torque is
clipped to what the servo and gearbox deliver. The equations of motion are the Lagrangian model of
robotenis_control.dynamics (eqs. 1-9) in the independent coordinates alpha, integrated with
classical RK4 (global error O(dt^4)); ``substeps`` splits the period.

The resolvers report Theta = theta_motor - theta0, quantised to the counts of a resolver-to-digital
converter on the motor shaft seen through the gearbox, with white noise before quantisation. The
increments are alpha - theta0 unless a ``joint_effects`` callable says otherwise (gear error,
backlash, compliance: the truth's effects, applied between the true joint and the reading).

Until the first velocity command the holding brakes are on and the robot does not move.
"""
from dataclasses import dataclass
import math

import numpy as np

from robotenis_control.dynamics import forward_dynamics, MassParameters, SingleRobotDynamics
from robotenis_kinematics import delta


@dataclass(frozen=True)
class DriveParameters:
    """
    K_V (N m s/rad, joint side, eq. 10) and the peak joint torque (N m) of servo + 10:1 gearbox.

    K_V = 60 gives the velocity loop a bandwidth K_V / I of about 200 rad/s on the ~0.3 kg m^2 a
    joint sees (arm, rotor, forearm and a third of the platform).
    """

    K_V: float = 60.0
    torque_limit: float = 300.0


@dataclass(frozen=True)
class ResolverParameters:
    """
    Resolver counts per motor revolution, gear ratio, and the reading's noise (rad, joint side).

    16384 counts (14-bit converter) through a 10:1 gearbox: one count is 2 pi / 163840 = 3.8e-5 rad
    at the joint, 0.019 mm at the end of a 0.5 m arm (calibration paper, section 6.1: the encoders
    cannot guarantee better than 0.02 mm). The noise, 2e-5 rad, is the one calibration assumes
    (robotenis_kinematics.synthetic.NoiseModel.sigma_resolver).
    """

    counts_per_rev: int = 16384
    gear_ratio: float = 10.0
    noise: float = 2e-5

    @property
    def resolution(self):
        """One count at the joint (rad)."""
        return 2 * math.pi / (self.counts_per_rev * self.gear_ratio)


def rk4_step(f, t, alpha, dalpha, dt):
    """
    Take one classical Runge-Kutta step of alphadd = f(t, alpha, alphad) (lists of 3 floats).

    Returns (alpha, alphad) at t + dt; local error O(dt^5), global O(dt^4).
    """
    def add(x, k, s):
        return [x[0] + s * k[0], x[1] + s * k[1], x[2] + s * k[2]]

    k1v, k1a = dalpha, f(t, alpha, dalpha)
    k2v = add(dalpha, k1a, dt / 2)
    k2a = f(t + dt / 2, add(alpha, k1v, dt / 2), k2v)
    k3v = add(dalpha, k2a, dt / 2)
    k3a = f(t + dt / 2, add(alpha, k2v, dt / 2), k3v)
    k4v = add(dalpha, k3a, dt)
    k4a = f(t + dt, add(alpha, k3v, dt), k4v)
    s = dt / 6
    return ([alpha[j] + s * (k1v[j] + 2 * k2v[j] + 2 * k3v[j] + k4v[j]) for j in range(3)],
            [dalpha[j] + s * (k1a[j] + 2 * k2a[j] + 2 * k3a[j] + k4a[j]) for j in range(3)])


class SimulatedMotors:
    """
    The true robot with its drives and resolvers, stepped one control period at a time.

    Parameters
    ----------
    geometry : RobotDescription-like (phi, H, a, b, h, theta0 arrays), the TRUE geometry.
    mass : robotenis_control.dynamics.MassParameters, the TRUE masses.
    Theta_start : resolver increments (rad) of the initial rest position; home by default.
    joint_effects : callable (alpha, alphad) -> resolver increments before quantisation and noise
        (rad), or None (alpha - theta0); e.g. robotenis_sim.truth.JointReadings.

    """

    def __init__(self, geometry, mass, drives=DriveParameters(), resolver=ResolverParameters(),
                 dt=1e-3, substeps=1, rng=None, Theta_start=(0.0, 0.0, 0.0), joint_effects=None):
        if dt <= 0 or substeps < 1:
            raise ValueError(f'dt must be > 0 and substeps >= 1 (got dt={dt}, '
                             f'substeps={substeps})')
        self.model = SingleRobotDynamics(geometry, mass)
        self.theta0 = np.asarray(geometry.theta0, dtype=float)
        self.drives, self.resolver = drives, resolver
        self.dt, self.substeps = float(dt), int(substeps)
        self.rng = rng if rng is not None else np.random.default_rng()
        self.joint_effects = joint_effects
        self.t = 0.0
        self.alpha = [float(v) for v in self.theta0 + np.asarray(Theta_start, dtype=float)]
        self._theta0 = self.theta0.tolist()
        self.dalpha = [0.0, 0.0, 0.0]
        self.command = [0.0, 0.0, 0.0]
        self.brakes = True
        self._last_reading = self._quantised(self._increments())

    def set_command(self, dalpha_ref):
        """Latch the drives' velocity command (rad/s, joint side); the first frees the brakes."""
        ref = [float(v) for v in dalpha_ref]
        if len(ref) != 3 or not all(math.isfinite(v) for v in ref):
            raise ValueError(f'velocity command: expected three finite values, got {dalpha_ref!r}')
        self.command = ref
        self.brakes = False

    def torque(self, dalpha):
        """Drive torques (eq. 10) for the latched command, clipped to the torque limit (N m)."""
        K, lim = self.drives.K_V, self.drives.torque_limit
        return [min(max(K * (self.command[j] - dalpha[j]), -lim), lim) for j in range(3)]

    def _accelerations(self, t, alpha, dalpha):
        return self.model.accelerations(alpha, dalpha, self.torque(dalpha))[0]

    def step(self):
        """Advance one control period (dt), unless the brakes hold the robot."""
        if not self.brakes:
            h = self.dt / self.substeps
            for k in range(self.substeps):
                self.alpha, self.dalpha = rk4_step(self._accelerations, self.t + k * h,
                                                   self.alpha, self.dalpha, h)
        self.t += self.dt

    def _increments(self):
        """Return the increments (list of 3 floats) before quantisation and noise."""
        if self.joint_effects is None:
            return [a - t0 for a, t0 in zip(self.alpha, self._theta0)]
        return np.asarray(self.joint_effects(np.asarray(self.alpha), np.asarray(self.dalpha)),
                          dtype=float).tolist()

    def _quantised(self, Theta):
        q = self.resolver.resolution
        return [round(v / q) * q if math.isfinite(v) else v for v in Theta]

    def read(self):
        """
        Read the resolvers: (Theta, dTheta), arrays of 3.

        Theta: resolver increments (rad, quantised and noisy); dTheta: the drives' speed estimate,
        the difference of the last two readings over dt (rad/s). In floats: rounding half to even
        as numpy's, so the same readings as with arrays.
        """
        increments = self._increments()
        if self.resolver.noise > 0:
            noise = self.rng.normal(scale=self.resolver.noise, size=3).tolist()
            increments = [v + n for v, n in zip(increments, noise)]
        else:
            increments = [v + 0.0 for v in increments]
        Theta = self._quantised(increments)
        dt, last = self.dt, self._last_reading
        dTheta = [(v - w) / dt for v, w in zip(Theta, last)]
        self._last_reading = Theta
        return np.array(Theta), np.array(dTheta)

    def effector(self):
        """Return the TRUE effector position and velocity (m, m/s, base frame): scoring only."""
        _, P, dP = self.model.accelerations(self.alpha, self.dalpha, [0.0, 0.0, 0.0])
        return np.array(P), np.array(dP)


class BatchMotors:
    """
    N true robots of one geometry, stepped together: SimulatedMotors vectorised over robots.

    The same drives (eq. 10, clipped to the torque limit), RK4 over one period on
    dynamics.forward_dynamics, resolvers (counts unless ``quantise`` is False, white noise) and
    brakes until the first command; no joint effects. Arrays have one row per robot: alpha and
    dalpha (N, 3), commands (N, 3). For studies that run hundreds of robots (a scalar step costs
    about 0.5 ms per robot, a batch step a few ms almost whatever N).
    """

    def __init__(self, geometry, mass, Theta_start, drives=DriveParameters(),
                 resolver=ResolverParameters(), dt=1e-3, rng=None, quantise=True):
        self.geometry, self.mass, self.drives, self.resolver = geometry, mass, drives, resolver
        self.dt = float(dt)
        self.rng = rng if rng is not None else np.random.default_rng()
        self.q = resolver.resolution if quantise else None
        self.theta0 = np.asarray(geometry.theta0, dtype=float)
        self.alpha = self.theta0 + np.asarray(Theta_start, dtype=float)
        self.dalpha = np.zeros_like(self.alpha)
        self.command = np.zeros_like(self.alpha)
        self.brakes = True
        self._last_reading = self._quantised(self.alpha - self.theta0)

    def set_command(self, dalpha_ref):
        """Latch the drives' velocity commands (N, 3), rad/s; the first releases the brakes."""
        self.command = np.asarray(dalpha_ref, dtype=float)
        self.brakes = False

    def _quantised(self, Theta):
        return Theta if self.q is None else np.round(Theta / self.q) * self.q

    def _accelerations(self, t, alpha, dalpha):
        alpha, dalpha = np.asarray(alpha).T, np.asarray(dalpha).T
        K, lim = self.drives.K_V, self.drives.torque_limit
        tau = np.clip(K * (self.command - dalpha), -lim, lim)
        return forward_dynamics(self.geometry, self.mass, alpha, dalpha, tau).T

    def step(self):
        """Advance every robot one period, unless the brakes hold them."""
        if not self.brakes:
            alpha, dalpha = rk4_step(self._accelerations, 0.0, self.alpha.T, self.dalpha.T,
                                     self.dt)
            self.alpha, self.dalpha = np.asarray(alpha).T, np.asarray(dalpha).T

    def read(self):
        """Return (Theta, dTheta), each (N, 3), as SimulatedMotors.read does for each robot."""
        noise = self.rng.normal(scale=self.resolver.noise, size=self.alpha.shape)
        Theta = self._quantised(self.alpha - self.theta0 + noise)
        dTheta = (Theta - self._last_reading) / self.dt
        self._last_reading = Theta
        return Theta, dTheta

    def effector(self):
        """Return the TRUE effector positions (N, 3), m: ground truth for scoring only."""
        return delta.forward(self.geometry, self.alpha)


def true_masses(truth):
    """
    Build the real robot's MassParameters from the truth's static gravity load (arm, platform, kg).

    The forearm (1.315 kg) and the camera (0.05 kg) are as in the paper; the arm and platform
    masses follow from arm = m_a/2 + m_b/2 and platform = m_c + m_camera + 3 m_b/2.
    """
    nominal = MassParameters()
    load = truth.gravity_load
    return MassParameters(m_a=2 * load.arm - nominal.m_b,
                          m_c=load.platform - 1.5 * nominal.m_b - nominal.m_camera)
