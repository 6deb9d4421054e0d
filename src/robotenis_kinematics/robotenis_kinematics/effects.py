"""
Effects beyond the paper's geometry: the residual loop's candidates, and what fk applies.

A calibrated robot description carries them in its ``effects`` list, each a map with ``name``,
its parameter (three numbers, one per joint or per axis) and that parameter's standard
deviation::

    - {name: joint_scale, scale: [k1, k2, k3], scale_std: [...]}
    - {name: backlash, width: [w1, w2, w3], width_std: [...]}
    - {name: gravity_compliance, compliance: [c1, c2, c3], compliance_std: [...],
       gravity_load: {arm: 1.1575, platform: 3.0225}}
    - {name: hand_eye_rotation, rotation_vector: [rx, ry, rz], rotation_vector_std: [...]}
    - {name: base_geometry, phi: [...], phi_std: [...], H: [...], H_std: [...]}

The joint effects turn resolver increments Theta into arm angles (model of the residual loop):

    theta = theta0 + (1 + k) Theta - (w / 2) dir + c tau_g(P, theta0 + Theta)

with dir the sign of the joint's last motion (the arm lags the motor by half the backlash width)
and tau_g the gravity torque on the arm (positive down) of a robot with the declared gravity load.
The hand-eye rotation r turns the camera's measured increments: Pi_true = exp([r]x) Pi.
base_geometry is applied in the legs' phi and H themselves; its entry records what was identified.
"""
import numpy as np

from robotenis_kinematics import delta
from robotenis_kinematics.errors import DescriptionError

G = 9.81
# Nominal static gravity load (kg): each arm carries half its own mass (m_a = 1.0) and half a
# forearm (m_b = 1.315) at the elbow; the platform (with camera, 1.05) carries the other forearm
# halves.
NOMINAL_GRAVITY_LOAD = {'arm': 0.5 * 1.0 + 0.5 * 1.315, 'platform': 1.05 + 1.5 * 1.315}

# effect -> (YAML key of its parameter, unit used to scale it in the observability analysis)
PARAMETERS = {
    'joint_scale': ('scale', 1e-3),               # dimensionless: 1e-3 = 1 mrad per rad travelled
    'backlash': ('width', 1e-3),                  # rad
    'gravity_compliance': ('compliance', 1e-5),   # rad/(N m): 50 N m then sag 0.5 mrad
    'hand_eye_rotation': ('rotation_vector', 1e-3),  # rad
}
BASE_GEOMETRY_KEYS = ('phi', 'H')
MODELS = tuple(PARAMETERS) + ('base_geometry',)


def _three(value, key):
    arr = np.asarray(value, dtype=float) if isinstance(value, list) else None
    if arr is None or arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise DescriptionError(f'{key}: expected three finite numbers, got {value!r}')
    return arr


def validate(effect, where):
    """Check one effect map; raises DescriptionError naming the key."""
    name = effect.get('name')
    if name not in MODELS:
        known = ', '.join(MODELS)
        raise DescriptionError(f'{where}.name: unknown effect {name!r} (known: {known})')
    keys = BASE_GEOMETRY_KEYS if name == 'base_geometry' else (PARAMETERS[name][0],)
    for key in keys:
        if key not in effect and name != 'base_geometry':
            raise DescriptionError(f'{where}.{key}: missing key')
        if key in effect:
            _three(effect[key], f'{where}.{key}')
    if name == 'gravity_compliance':
        load = effect.get('gravity_load', NOMINAL_GRAVITY_LOAD)
        for part in ('arm', 'platform'):
            if not isinstance(load, dict) or not isinstance(load.get(part), (int, float)):
                raise DescriptionError(f'{where}.gravity_load.{part}: expected a number (kg)')


def parameters(desc):
    """Return a description's effect parameters as {name: array of 3} (base_geometry excluded)."""
    return {e['name']: np.asarray(e[PARAMETERS[e['name']][0]], dtype=float)
            for e in desc.effects if e['name'] in PARAMETERS}


def gravity_load(desc):
    """Return the gravity load (kg) of the description's compliance effect, or the nominal one."""
    for e in desc.effects:
        if e['name'] == 'gravity_compliance':
            return e.get('gravity_load', NOMINAL_GRAVITY_LOAD)
    return NOMINAL_GRAVITY_LOAD


def gravity_torque(desc, P, theta, load=None):
    """
    Return the gravity torque on each arm at rest (..., 3), N m, positive pulling the arm down.

    By virtual work, tau = m_arm g a cos(theta) + J_R^T (m_platform g z): the arm's load at the
    elbow and the platform's weight carried through the Jacobian (z is down, so gravity is +z).
    """
    load = NOMINAL_GRAVITY_LOAD if load is None else load
    J = delta.jacobian(desc, P, theta)
    return load['arm'] * G * desc.a * np.cos(theta) + load['platform'] * G * J[..., 2, :]


def motion_direction(Theta):
    """
    Sign (+1/-1) of each joint's last motion before each reading, from the visit order (K, 3).

    The robot starts at home (Theta = 0); a joint that did not move keeps its previous sign.
    """
    Theta = np.asarray(Theta, dtype=float)
    step = np.sign(np.diff(Theta, axis=0, prepend=np.zeros((1, 3))))
    out = np.empty_like(step)
    last = np.ones(3)
    for k, s in enumerate(step):
        last = np.where(s != 0, s, last)
        out[k] = last
    return out


def model_joint_angles(desc, fx, Theta, direction, P, load=None):
    """
    Arm angles (K, 3) under the joint effects in ``fx``, and d theta / d(effect parameter).

    Returns (theta, {effect name: (K, 3)}): the derivative of theta_ik with respect to joint i's
    parameter of each joint effect in ``fx`` (see the module docstring for the model).
    """
    base = desc.theta0 + Theta
    derivative = {}
    if 'joint_scale' in fx:
        derivative['joint_scale'] = Theta
    if 'backlash' in fx:
        derivative['backlash'] = -0.5 * direction
    if 'gravity_compliance' in fx:
        derivative['gravity_compliance'] = gravity_torque(desc, P, base, load)
    theta = base + sum(fx[name] * d for name, d in derivative.items())
    return theta, derivative


def increments_for(desc, theta, direction, P):
    """
    Return the resolver increments Theta (..., 3) that give the arm angles theta.

    This inverts ``model_joint_angles`` under the description's joint effects, for commanding a
    robot with a calibrated model.

    ``direction`` is the sign of each joint's motion into this pose and P the effector position
    (for compliance). Theta = (theta - theta0 + w/2 dir - c tau_g(P, theta0 + Theta)) / (1 + k),
    solved by fixed point: the sag changes by c dtau/dtheta ~ 1e-3 of a step, so three passes are
    exact.
    """
    fx = parameters(desc)
    k = fx.get('joint_scale', np.zeros(3))
    lead = theta - desc.theta0 + 0.5 * fx.get('backlash', np.zeros(3)) * direction
    Theta = lead / (1 + k)
    if 'gravity_compliance' in fx:
        for _ in range(3):
            torque = gravity_torque(desc, P, desc.theta0 + Theta, gravity_load(desc))
            sag = fx['gravity_compliance'] * torque
            Theta = (lead - sag) / (1 + k)
    return Theta


def rotation_vector_matrix(r):
    """Rotation matrix exp([r]x) of a rotation vector r (rad), Rodrigues' formula."""
    r = np.asarray(r, dtype=float)
    angle = np.linalg.norm(r)
    if angle < 1e-15:
        return np.eye(3)
    k = r / angle
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def rotate_increments(fx, Pi):
    """Return the measured increments turned by the hand-eye rotation, if the model has one."""
    if 'hand_eye_rotation' not in fx:
        return Pi
    return Pi @ rotation_vector_matrix(fx['hand_eye_rotation']).T


def joint_angles(desc, Theta):
    """
    Return the arm angles (N, 3) for resolver increments (N, 3) visited in this order.

    Every joint effect the description holds is applied. Compliance depends on the pose, so it is
    iterated with FK (the sag is tiny: two passes agree to far below a resolver count).
    """
    Theta = np.asarray(Theta, dtype=float).reshape(-1, 3)
    fx = parameters(desc)
    direction = motion_direction(Theta)
    joint_fx = {k: v for k, v in fx.items() if k in ('joint_scale', 'backlash')}
    theta, _ = model_joint_angles(desc, joint_fx, Theta, direction, None)
    if 'gravity_compliance' not in fx:
        return theta
    sagged = theta
    for _ in range(2):
        P = delta.forward(desc, sagged)
        torque = gravity_torque(desc, P, theta, gravity_load(desc))
        sagged = theta + fx['gravity_compliance'] * torque
    return sagged
