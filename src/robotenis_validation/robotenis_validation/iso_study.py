"""
Static tests of section 6.1 on the simulated robot: circle plate, repeatability, distance accuracy.

The control element is a plate of 25 black circles (40 mm diameter, 100 mm apart) set in five
vertical planes 100 mm apart, facing the camera (which looks along base +x): a 400 mm cube of the
workspace. To measure a circle the robot moves the camera 200 mm in front of it and servoes until
the circle is centred to under one pixel (0.4 mm at 200 mm, section 6.1); the circle's position is
then the forward kinematics of the resolver readings corrected by the averaged visual measurement,
C_est = FK(Theta) + R s (the camera's offset on the effector is a constant that cancels in every
distance). The averaged visual measurement has the paper's Table 3 noise.

* Repeatability (Table 4): the ISO 9283 five-point loop in a diagonal plane of the cube, 25 times,
  at 1.0 and 2.0 m/s, on the dynamic simulation (robotenis_sim.motors, the motion controller at
  1 kHz); the visual data at the focus point after each loop, RP = l_bar + 3 S (appendix).
* Distance accuracy (Figures 9 and 10): every circle of every plane, n times, with a given robot
  description in the controller; AD of each pair of neighbouring circles against their 100 mm, and
  for each circle the mean AD of its pairs. Quasi-static: at rest the controller holds the readings
  on the commanded joint angles within a resolver count (the system test checks this), so a visit
  is the quantised, noisy readings of the commanded angles, and the true robot is where the truth's
  geometry and joint effects put it.

Only the scoring looks at the truth: the robot's side of every visit uses the description under
test.
"""
from dataclasses import dataclass

import numpy as np

from robotenis_control import controller as ctl
from robotenis_kinematics import delta, effects as fx, synthetic
from robotenis_sim import motors
from robotenis_sim.camera_model import render_circles
from robotenis_sim.truth import JointReadings
from robotenis_validation import iso9283
from robotenis_vision.circle import measure_circle

GRID, PITCH, DIAMETER = 5, 0.100, 0.040        # the plate: 5 x 5 circles (m)
PLANE_SPACING, STANDOFF = 0.100, 0.200          # m
PIXEL = 0.4e-3                                  # m per pixel at 200 mm (section 6.1)
CUBE_CENTRE = np.array([0.0, 0.0, 0.9])         # centre of the effector's 400 mm cube (m)
MAX_SERVO_STEPS = 10


@dataclass(frozen=True)
class Plate:
    """
    Circle centres (planes, GRID, GRID, 3) in the base frame.

    Plane k at depth x_k, row r (z), column c (y).
    """

    centres: np.ndarray

    @classmethod
    def in_front_of(cls, cube_centre, camera_offset):
        """
        Place the five planes so that the camera, 200 mm in front, keeps the effector in the cube.

        ``camera_offset`` is where the user believes the optical centre is on the effector plus the
        200 mm along the optical axis: plates are set by eye, they need not be exact.
        """
        k = np.arange(GRID) - GRID // 2
        x = cube_centre[0] + camera_offset[0] + PLANE_SPACING * k
        y = cube_centre[1] + camera_offset[1] + PITCH * k
        z = cube_centre[2] + camera_offset[2] + PITCH * k
        X, Z, Y = np.meshgrid(x, z, y, indexing='ij')
        return cls(np.stack([X, Y, Z], axis=-1))


def neighbour_pairs():
    """List the index pairs ((r, c), (r', c')) of a plate's horizontal and vertical neighbours."""
    pairs = []
    for r in range(GRID):
        for c in range(GRID):
            if c + 1 < GRID:
                pairs.append(((r, c), (r, c + 1)))
            if r + 1 < GRID:
                pairs.append(((r, c), (r + 1, c)))
    return pairs


class StaticRobot:
    """
    The truth's robot at rest, commanded through a robot description, seen by the hand camera.

    ``rest(P)`` commands the effector position P with the description (its IK and joint effects),
    returns the held readings Theta and the averaged visual measurement s of a circle at C.
    """

    def __init__(self, truth, desc, rng, noise=synthetic.NoiseModel(),
                 resolution=motors.ResolverParameters().resolution, camera=None, frames=1):
        self.truth, self.desc, self.rng, self.noise, self.q = truth, desc, rng, noise, resolution
        self.camera, self.frames = camera, frames
        self.last_theta = desc.theta0.copy()
        self.direction = np.ones(3)

    def rest(self, P, C, plane=None):
        theta = delta.inverse(self.desc, P)
        step = np.sign(theta - self.last_theta)
        self.direction = np.where(step != 0, step, self.direction)
        self.last_theta = theta
        Theta = fx.increments_for(self.desc, theta, self.direction, P)
        noisy = Theta + self.rng.normal(scale=self.noise.sigma_resolver, size=3)
        Theta = np.round(noisy / self.q) * self.q
        arm = self.truth.arm_angles(self.truth.motor_from_reading(Theta), self.direction)
        return Theta, self.see(delta.forward(self.truth.geometry, arm), C, plane)

    def see(self, P_true, C, plane=None):
        """
        Return the averaged visual measurement (optical frame, m) of the circle centre C.

        The robot is at P_true. Without a camera: the truth plus the averaged measurement's noise
        (Table 3). With one: the mean over ``frames`` images of the plate's circles (``plane``,
        (n, 3) base frame) rendered through the true camera mounting and measured by
        robotenis_vision.circle.
        """
        R = self.truth.camera_rotation
        s = R.T @ (C - P_true - self.truth.camera_translation)
        if self.camera is None:
            return s + self.rng.normal(scale=self.noise.sigma_camera)
        points = np.reshape(plane if plane is not None else C, (-1, 3))
        centres = (points - P_true - self.truth.camera_translation) @ R
        near = centres[np.abs(centres[:, 0]) < 2 * PITCH + np.abs(s[0])]
        normals = np.tile(-R.T @ R[:, 2], (len(near), 1))   # the plate faces the camera
        radii = np.full(len(near), DIAMETER / 2)
        return np.mean([measure_circle(render_circles(self.camera, near, normals, radii, self.rng),
                                       self.camera, DIAMETER)
                        for _ in range(self.frames)], axis=0)

    def position(self, Theta, s):
        """
        Return C_est = FK(Theta) + R s with the description's kinematics and effects.

        The constant offset is dropped.
        """
        fk = fx.model_joint_angles(self.desc, fx.parameters(self.desc), Theta, self.direction,
                                   delta.forward(self.desc, self.desc.theta0 + Theta),
                                   fx.gravity_load(self.desc))[0]
        return delta.forward(self.desc, fk) + self.desc.camera_rotation @ s


def servo(robot, C, P_guess, plane=None):
    """Move in front of circle C, correct until it is centred to under a pixel; return C_est."""
    P, target = np.array(P_guess, dtype=float), np.array([0.0, 0.0, STANDOFF])
    for _ in range(MAX_SERVO_STEPS):
        Theta, s = robot.rest(P, C, plane)
        if np.hypot(s[0], s[1]) < PIXEL:
            return robot.position(Theta, s)
        P = P + robot.desc.camera_rotation @ (s - target)
    raise RuntimeError(f'servoing on the circle at {C} did not centre it '
                       f'in {MAX_SERVO_STEPS} steps')


def distance_accuracy(truth, desc, plate, camera_offset_guess, repetitions, rng,
                      say=lambda text: None, camera=None, frames=1):
    """
    Compute the AD per circle (planes, GRID, GRID) in m.

    A circle's AD is the mean over its neighbour pairs of |D_bar - D_c|. Each repetition visits
    every circle of every plane in order (as the robot would, plane by plane). With a ``camera``
    (robotenis_vision.camera.Camera) the circles are rendered and measured, ``frames`` images per
    visit; otherwise the averaged measurement is simulated with Table 3's noise.
    """
    robot = StaticRobot(truth, desc, rng, camera=camera, frames=frames)
    shape = plate.centres.shape[:3]
    C_est = np.empty((repetitions,) + shape + (3,))
    for j in range(repetitions):
        for index in np.ndindex(*shape):
            C = plate.centres[index]
            C_est[(j,) + index] = servo(robot, C, C - camera_offset_guess,
                                        plate.centres[index[0]].reshape(-1, 3))
        say(f'distance accuracy: repetition {j + 1}/{repetitions}')
    AD = np.zeros(shape)
    count = np.zeros(shape)
    for k in range(shape[0]):
        for a, b in neighbour_pairs():
            value = iso9283.distance_accuracy(C_est[:, k, a[0], a[1]], C_est[:, k, b[0], b[1]],
                                              plate.centres[k, a[0], a[1]],
                                              plate.centres[k, b[0], b[1]])
            for r, c in (a, b):
                AD[k, r, c] += value
                count[k, r, c] += 1
    return AD / count


def five_points(cube_centre, half=0.8 * 0.2):
    """
    Return the ISO 9283 loop in the cube's diagonal plane.

    The centre (focus point) and the rectangle's corners.
    """
    # the plane through the cube's x-z diagonal
    u, v = np.array([1.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0])
    corners = [cube_centre + half * (su * u + sv * v)
               for su, sv in ((1, 1), (1, -1), (-1, -1), (-1, 1))]
    return np.array([cube_centre] + corners)


def repeatability(truth, mass, desc, speed, loops, rng, settle=0.3, say=lambda text: None):
    """
    Return the visual data at the focus point after each five-point loop, (loops, 3) m.

    On the dynamic simulation: the truth's robot (geometry, masses, joint effects) under the
    motion controller with ``desc``; the circle sits 200 mm in front of the camera at the focus
    point.
    """
    sim = motors.SimulatedMotors(truth.geometry, mass, rng=rng, joint_effects=JointReadings(truth))
    control = ctl.MotionController(desc, max_speed=speed, max_acceleration=4 * 9.81)
    points = five_points(CUBE_CENTRE)
    robot = StaticRobot(truth, desc, rng)
    t, samples, C = 0.0, [], None

    def run_until_rest():
        nonlocal t
        rest_since = None
        while rest_since is None or t - rest_since < settle:
            Theta, dTheta = sim.read()
            ref, _ = control.update(t, Theta, dTheta)
            sim.set_command(ref)
            sim.step()
            t += sim.dt
            rest_since = (rest_since or t) if not control.moving else None

    control.update(t, sim.read()[0])
    for loop in range(loops + 1):
        for P in points[1:] if loop else []:
            control.add_goal(P, t)
        control.add_goal(points[0], t)
        run_until_rest()
        P_true = sim.effector()[0]
        if C is None:
            # the circle is set where the camera looks at the first visit of the focus point
            C = P_true + truth.camera_translation + STANDOFF * truth.camera_rotation[:, 2]
        elif loop:
            samples.append(robot.see(P_true, C))
            say(f'repeatability at {speed} m/s: loop {loop}/{loops}')
    return np.array(samples)


def repeatability_figures(samples):
    """(range of x, y, z (3,) m, RP m) of the visual data, as Table 4 lists them."""
    return np.ptp(samples, axis=0), iso9283.repeatability(samples)


def plot_maps(maps, plate, path):
    """
    Plot error maps like Figures 9 and 10: one row per model, one panel per plane.

    AD in mm on 0-2 mm. ``maps`` is {model name: AD (planes, GRID, GRID) in m}; each row's title
    gives its mean.
    """
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    planes = plate.centres.shape[0]
    fig, axes = plt.subplots(len(maps), planes, figsize=(3 * planes, 3 * len(maps)), squeeze=False)
    extent_of = lambda k: [plate.centres[k, 0, 0, 1] * 1e3,  # noqa: E731
                           plate.centres[k, 0, -1, 1] * 1e3,
                           plate.centres[k, -1, 0, 2] * 1e3,
                           plate.centres[k, 0, 0, 2] * 1e3]
    for row, (name, AD) in enumerate(maps.items()):
        for k in range(planes):
            ax = axes[row, k]
            image = ax.imshow(AD[k] * 1e3, vmin=0, vmax=2, cmap='jet', interpolation='bilinear',
                              extent=extent_of(k), origin='upper')
            plane = f'plate at x = {plate.centres[k, 0, 0, 0] * 1e3:.0f} mm'
            ax.set_title(f'{name}\n{plane}' if k == 0 else plane, fontsize=9)
            ax.set_xlabel('y (mm)', fontsize=8)
            if k == 0:
                ax.set_ylabel('z (mm, down)', fontsize=8)
        axes[row, -1].text(1.05, 0.5, f'mean {AD.mean() * 1e3:.3f} mm',
                           transform=axes[row, -1].transAxes, rotation=90, va='center')
    fig.colorbar(image, ax=axes.ravel().tolist(), label='distance accuracy AD (mm)', shrink=0.6)
    fig.savefig(path, dpi=80)
    plt.close(fig)
