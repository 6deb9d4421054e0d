"""
The simulator's truth: the real geometry and the effects no robot description declares.

Read by the simulator only. A truth file is YAML::

    geometry: {legs: ..., camera: ..., sphere_radius: ...}  # robot description schema: the TRUE
                                           # geometry (or a description file: a path relative to
                                           # the truth file, or package://PACKAGE/PATH in a
                                           # package's share)
    camera_translation: [0.12, 0.0, 0.04]  # optical centre in the effector frame, m
    sphere_position: [0.70, 0.0, 1.35]     # centre of the fixed calibration ball, base frame, m
    effects:                               # all optional, none on by default
      joint_scale: [s1, s2, s3]            # gear ratio error: reading = (1 + s_i) (motor - theta0)
      backlash: [w1, w2, w3]               # rad: the arm lags the motor by w_i / 2 against the
                                           # last motion
      gravity_compliance: [c1, c2, c3]     # rad/(N m): the arm sags by c_i tau_g,i under gravity
                                           # torque
      base_geometry: {dH: [...], dphi: [...]}  # m, rad: motor axes off the declared H_i, phi_i
      hand_eye_rotation: [rx, ry, rz]      # rad, rotation vector: true camera mount = declared
                                           # R exp([r])
      # and three no calibration library names (the residual loop must not name them):
      joint_eccentricity: {order: 5, amplitude: [...], phase: [...]}  # rad: reading + a_i
                                           # sin(n motor_i + p_i), an eccentric gear
      camera_depth_scale: 0.004            # the camera reads the range (1 + e) z
      lens_residue: 0.002                  # radial distortion the camera's model lacks: the
                                           # measured x, y are (1 + k (u^2 + v^2)) x, y

The geometry defaults to the calibration paper's Table 1 calibrated column
(``truth_default.yaml``), so that nominal and truth differ as on the real robot.
"""
from dataclasses import dataclass, field
import os

import numpy as np
from robotenis_kinematics import delta, description, effects as model_effects
from robotenis_kinematics.description import DescriptionError
import yaml

EFFECTS = ('joint_scale', 'backlash', 'gravity_compliance', 'base_geometry', 'hand_eye_rotation',
           'joint_eccentricity', 'camera_depth_scale', 'lens_residue')
# the effects between an arm and its resolver's reading, which JointReadings applies
JOINT_EFFECTS = ('joint_scale', 'backlash', 'gravity_compliance', 'joint_eccentricity')
SCALAR_EFFECTS = ('camera_depth_scale', 'lens_residue')
G = model_effects.G
rotation_vector_matrix = model_effects.rotation_vector_matrix


@dataclass(frozen=True)
class GravityLoad:
    """
    Static gravity load of the real robot (kg): what each arm carries, what the platform weighs.

    arm: arm mass at half the arm plus half a forearm at the elbow (m_a / 2 + m_b / 2);
    platform: platform, camera and the other halves of the three forearms (m_c + 3 m_b / 2).
    The real masses differ a little from the nominal ones the calibration assumes
    (robotenis_kinematics.effects.NOMINAL_GRAVITY_LOAD): the arm is 1.02 kg, the platform 1.10 kg.
    """

    arm: float = 0.5 * 1.02 + 0.5 * 1.315
    platform: float = 1.10 + 1.5 * 1.315


@dataclass
class Truth:
    """The real robot: geometry (with base_geometry applied), camera mount, ball, effects."""

    geometry: object
    camera_translation: np.ndarray
    sphere_position: np.ndarray
    effects: dict = field(default_factory=dict)
    gravity_load: GravityLoad = GravityLoad()

    @property
    def camera_rotation(self):
        """Return the true camera mount: the declared rotation turned by any hand_eye_rotation."""
        r = np.asarray(self.effects.get('hand_eye_rotation', np.zeros(3)), dtype=float)
        return rotation_vector_matrix(r) @ self.geometry.camera_rotation

    def gravity_torque(self, P, theta):
        """Return the gravity torque (..., 3) on the arms at rest (N m, positive = arm down)."""
        load = {'arm': self.gravity_load.arm, 'platform': self.gravity_load.platform}
        return model_effects.gravity_torque(self.geometry, P, theta, load)

    def arm_angles(self, motor, direction, P=None):
        """
        Return the true arm angles (..., 3) for motor angles after motion in ``direction``.

        ``motor`` is absolute, rad. ``direction`` is the sign (+1/-1) of each motor's last motion;
        backlash leaves the arm behind the motor by half its width. Compliance needs the pose: it
        is solved by fixed point (the sag is small, so two passes converge to well below a
        resolver count).
        """
        theta = (np.asarray(motor, dtype=float)
                 - 0.5 * np.asarray(self.effects.get('backlash', np.zeros(3))) * direction)
        c = np.asarray(self.effects.get('gravity_compliance', np.zeros(3)), dtype=float)
        if not np.any(c):
            return theta
        sagged = theta
        for _ in range(3):
            P = delta.forward(self.geometry, sagged)
            sagged = theta + c * self.gravity_torque(P, sagged)
        return sagged

    def increments(self, arm, direction, P):
        """
        Return resolver increments, unquantised and noise-free, for TRUE arm angles at effector P.

        The exact inverse of ``arm_angles`` followed by ``reading``: the sag is c_i tau_g,i at the
        sagged pose itself, and the motor leads the arm by half the backlash in ``direction``.
        """
        theta = np.asarray(arm, dtype=float)
        c = np.asarray(self.effects.get('gravity_compliance', np.zeros(3)), dtype=float)
        if np.any(c):
            theta = theta - c * self.gravity_torque(P, theta)
        motor = theta + 0.5 * np.asarray(self.effects.get('backlash', np.zeros(3))) * direction
        return self.reading(motor)

    def reading(self, motor):
        """Return the drives' increments for motor angles (absolute): gear and eccentricity."""
        s = np.asarray(self.effects.get('joint_scale', np.zeros(3)), dtype=float)
        motor = np.asarray(motor, dtype=float)
        return (1 + s) * (motor - self.geometry.theta0) + self._eccentricity(motor)

    def motor_from_reading(self, Theta):
        """Return motor angles (absolute) for resolver increments: the inverse of ``reading``."""
        s = np.asarray(self.effects.get('joint_scale', np.zeros(3)), dtype=float)
        Theta = np.asarray(Theta, dtype=float)
        motor = self.geometry.theta0 + Theta / (1 + s)
        for _ in range(4 if 'joint_eccentricity' in self.effects else 0):
            # the error's slope n a is 2e-3 or less: each pass contracts it that much
            motor = self.geometry.theta0 + (Theta - self._eccentricity(motor)) / (1 + s)
        return motor

    def _eccentricity(self, motor):
        e = self.effects.get('joint_eccentricity')
        if e is None:
            return 0.0
        return e['amplitude'] * np.sin(e['order'] * motor + e['phase'])

    def camera_reading(self, sphere):
        """Return the sphere centres (..., 3) the camera measures for the true ones: its errors."""
        sphere = np.array(sphere, dtype=float)
        k = self.effects.get('lens_residue', 0.0)
        if k:
            rho2 = (sphere[..., 0] ** 2 + sphere[..., 1] ** 2) / sphere[..., 2] ** 2
            sphere[..., :2] *= (1 + k * rho2)[..., None]
        sphere[..., 2] *= 1 + self.effects.get('camera_depth_scale', 0.0)
        return sphere


def _vector(value, key, n=3):
    arr = np.asarray(value, dtype=float) if isinstance(value, list) else None
    if arr is None or arr.shape != (n,) or not np.all(np.isfinite(arr)):
        raise DescriptionError(f'{key}: expected {n} finite numbers, got {value!r}')
    return arr


def geometry_file(name, folder):
    """Return the path of a geometry file: package://PACKAGE/PATH, or relative to ``folder``."""
    if name.startswith('package://'):
        from ament_index_python.packages import get_package_share_directory
        package, _, rest = name[len('package://'):].partition('/')
        return os.path.join(get_package_share_directory(package), rest)
    return os.path.join(folder, name)


def _scalar(value, key):
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
        raise DescriptionError(f'{key}: expected a finite number, got {value!r}')
    return float(value)


def _eccentricity(value):
    if not isinstance(value, dict):
        raise DescriptionError('effects.joint_eccentricity: expected a map of order, amplitude, '
                               'phase')
    order = value.get('order')
    if isinstance(order, bool) or not isinstance(order, int) or order < 1:
        raise DescriptionError('effects.joint_eccentricity.order: expected a positive integer, '
                               f'got {order!r}')
    return {'order': order,
            'amplitude': _vector(value.get('amplitude'), 'effects.joint_eccentricity.amplitude'),
            'phase': _vector(value.get('phase', [0, 0, 0]), 'effects.joint_eccentricity.phase')}


def from_dict(data, folder='.'):
    """Build a Truth from parsed YAML, its files relative to ``folder``; errors name the key."""
    if not isinstance(data, dict) or 'geometry' not in data:
        raise DescriptionError('truth: geometry: missing key')
    try:
        if isinstance(data['geometry'], str):
            geometry = description.load(geometry_file(data['geometry'], folder))
        else:
            geometry = description.from_dict(data['geometry'])
    except DescriptionError as e:
        raise DescriptionError(f'geometry.{e}') from None
    effects = dict(data.get('effects') or {})
    for name in effects:
        if name not in EFFECTS:
            raise DescriptionError(f'effects.{name}: unknown effect '
                                   f"(known: {', '.join(EFFECTS)})")
    parsed = {}
    for name, value in effects.items():
        if name in SCALAR_EFFECTS:
            parsed[name] = _scalar(value, f'effects.{name}')
        elif name == 'joint_eccentricity':
            parsed[name] = _eccentricity(value)
        elif name == 'base_geometry':
            dH = _vector(value.get('dH', [0, 0, 0]), 'effects.base_geometry.dH')
            dphi = _vector(value.get('dphi', [0, 0, 0]), 'effects.base_geometry.dphi')
            geometry = geometry.copy(H=geometry.H + dH, phi=geometry.phi + dphi)
            parsed[name] = {'dH': dH, 'dphi': dphi}
        else:
            parsed[name] = _vector(value, f'effects.{name}')
    for key in ('camera_translation', 'sphere_position'):
        if key not in data:
            raise DescriptionError(f'{key}: missing key')
    return Truth(geometry, _vector(data['camera_translation'], 'camera_translation'),
                 _vector(data['sphere_position'], 'sphere_position'), parsed)


def load(path=None):
    """Read a truth file; without a path, the default (Table 1 calibrated, no effects)."""
    path = path or default_path()
    with open(path) as f:
        try:
            data = yaml.safe_load(f)
        except yaml.YAMLError as e:
            raise DescriptionError(f'{path}: not valid YAML ({e})') from e
    try:
        return from_dict(data, os.path.dirname(os.path.abspath(path)))
    except DescriptionError as e:
        raise DescriptionError(f'{path}: {e}') from None


def to_dict(truth, **effects):
    """Return the plain data of a truth file for ``truth``, with ``effects`` added."""
    data = {'geometry': truth.geometry.to_dict(),
            'camera_translation': truth.camera_translation.tolist(),
            'sphere_position': truth.sphere_position.tolist(),
            # base_geometry is already in the geometry: carrying it again would apply it twice
            'effects': {**{k: v for k, v in truth.effects.items() if k != 'base_geometry'},
                        **effects}}
    return _plain(data)


def with_effects(truth, **effects):
    """Return a copy of ``truth`` with effects added (as a truth file would give them)."""
    return from_dict(yaml.safe_load(yaml.safe_dump(to_dict(truth, **effects))))


def save(truth, path):
    """Write a truth file (temporary file, then rename)."""
    tmp = f'{path}.tmp'
    with open(tmp, 'w') as f:
        f.write("# The simulator's truth: read by the simulator only.\n")
        yaml.safe_dump(to_dict(truth), f, sort_keys=False)
    os.replace(tmp, path)


def _plain(obj):
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple, np.ndarray)):
        return [_plain(v) for v in obj]
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    return float(obj) if isinstance(obj, (float, np.floating)) else obj


def default_path():
    here = os.path.dirname(os.path.abspath(__file__))
    return os.path.normpath(os.path.join(here, '..', 'config', 'truth_default.yaml'))


class JointReadings:
    """
    The hook between the simulated arms and the resolvers: ``(alpha, alphad) -> increments``.

    Tracks each joint's motion direction (the sign of its last speed above ``min_speed`` rad/s,
    for backlash) and applies the truth's joint effects; without effects the increments are
    alpha - theta0. On a reversal the reading steps by the backlash width at once (the gap is not
    simulated as a state); 0.02 rad/s (1 cm/s at the elbow) keeps the controller's dither at rest
    from flipping it. Backlash and gear error alone (no compliance, no eccentricity) are computed
    in floats, the simulator reading every 1 ms: the operations of ``Truth.increments``, in its
    order, so the same increments (4 us against 14 us).
    """

    PLAIN = {'backlash', 'joint_scale'}      # the joint effects the float path computes

    def __init__(self, truth, min_speed=0.02):
        self.truth, self.min_speed = truth, min_speed
        self.direction = np.ones(3)
        self._plain = set(truth.effects) & set(JOINT_EFFECTS) <= self.PLAIN
        fx = truth.effects
        self._half_backlash = (0.5 * np.asarray(fx.get('backlash', np.zeros(3)))).tolist()
        self._gain = (1 + np.asarray(fx.get('joint_scale', np.zeros(3)), dtype=float)).tolist()
        self._theta0 = np.asarray(truth.geometry.theta0, dtype=float).tolist()

    def __call__(self, alpha, dalpha):
        if self._plain:
            return np.array(self._plain_increments(np.asarray(alpha, dtype=float).tolist(),
                                                   np.asarray(dalpha, dtype=float).tolist()))
        moving = np.abs(dalpha) > self.min_speed
        self.direction = np.where(moving, np.sign(dalpha), self.direction)
        P = (delta.forward(self.truth.geometry, alpha)
             if 'gravity_compliance' in self.truth.effects else None)
        return self.truth.increments(alpha, self.direction, P)

    def _plain_increments(self, alpha, dalpha):
        direction = self.direction.tolist()
        for j, v in enumerate(dalpha):
            if abs(v) > self.min_speed:
                direction[j] = 1.0 if v > 0 else -1.0
        self.direction = np.array(direction)
        return [g * ((a + b * d) - t0) + 0.0 for a, b, d, g, t0
                in zip(alpha, self._half_backlash, direction, self._gain, self._theta0)]


def reading_sides(Theta, width, start=1.0):
    """
    Return the backlash side (n, 3) JointReadings had at each of its successive readings (n, 3).

    For scorers, who need the truth's sides where the calibration has only its own estimate.
    JointReadings steps a reading by the whole width ``width`` (3,) rad, against its side, at the
    step where the arm reverses, and while an arm moves the side is its motion's; so the side at
    a reading is the sign of the last step between readings longer than half the width (``start``
    before the first, and throughout for a joint without backlash).
    """
    Theta = np.asarray(Theta, dtype=float)
    step = np.diff(Theta, axis=0)
    width = np.broadcast_to(np.asarray(width, dtype=float), (Theta.shape[1],))
    jumps = (np.abs(step) > 0.5 * width) & (width > 0)
    index = np.arange(1, len(Theta))[:, None]
    last = np.maximum.accumulate(np.vstack([np.zeros((1, Theta.shape[1]), dtype=int),
                                            np.where(jumps, index, 0)]), axis=0)
    signs = np.vstack([np.full((1, Theta.shape[1]), float(start)), np.sign(step)])
    return np.take_along_axis(signs, last, axis=0)
