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

and the two generic effects, for what no named effect explains, each a family of terms with one
parameter per joint or per optical axis::

    - {name: joint_harmonics, terms: {cos5: [...], sin5: [...]}, terms_std: {...}}
    - {name: camera_field, reference_range: 0.35, terms: {w: [...], xx: [...]}, terms_std: {...}}

The joint effects turn resolver increments Theta into arm angles (model of the residual loop):

    theta = theta0 + (1 + k) Theta - (w / 2) dir + c tau_g(P, theta0 + Theta)

                                        + sum_n (c_n cos(n Theta) + s_n sin(n Theta))

with dir the sign of the joint's last motion (the arm lags the motor by half the backlash width),
tau_g the gravity torque on the arm (positive down) of a robot with the declared gravity load;
the joint harmonics are errors that repeat with the joint's angle (an eccentric gear or
resolver), in the reading itself so that they stay linear in their coefficients and apart from
theta0 (their phase is in c_n, s_n). The camera-side effects correct the measured sphere centre s
(optical frame) before it becomes an increment, Pi = -R s (R the declared camera rotation): the
camera field is a polynomial error of the measurement, s_measured = s + sum_m f_m phi_m(s), with
monomials phi_m in x = s_x / z_ref, y = s_y / z_ref and w = s_z / z_ref - 1 (z_ref =
``reference_range``), so Pi_true = -R (s - sum_m f_m phi_m(s)). In these coordinates every
linear error of the measurement (a scale along an axis, a small rotation, a shear) is exactly of
degree 1. A scale of every measurement, s -> (1 + e) s, is the one field the robot's geometry
cannot tell from its own scale (a robot e larger seen by a camera e shorter; the ball's known
radius is the datum that fixes it): it is the direction x, y, w -> e z_ref along x, y, z, so one
of those three coefficients is held at zero (``UNSEEN``): the y term's y coefficient, so that a
depth-only scale -- what an error of the focal length makes of a sphere's position, Z = f R / r
wrong and X, Y right -- is the w term's z coefficient alone and leaves the geometry's scale
untouched (holding the w term's z coefficient instead turned it into a lateral scale and a
robot 0.4 % too large: 5.5 mm of kinematic error against the truth, measured). The hand-eye
rotation r then turns the increments: Pi_true = exp([r]x) Pi. base_geometry is applied in the
legs' phi and H themselves; its entry records what was identified.
"""
import re

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
GENERIC = ('joint_harmonics', 'camera_field')
MODELS = tuple(PARAMETERS) + ('base_geometry',) + GENERIC
JOINT_NAMED = ('joint_scale', 'backlash', 'gravity_compliance')
# Generic terms in a model: 'joint_cos5' is joint_harmonics' cos5, 'camera_xw' camera_field's xw
JOINT_TERM = re.compile(r'^joint_(cos|sin)([1-9][0-9]*)$')
CAMERA_TERM = re.compile(r'^camera_([xyw]+)$')
TERM_UNIT = 1e-4          # rad or m: the observability scale of a generic term
UNSEEN = ('camera_y2',)   # parameters held at zero: the field's part the geometry absorbs
CAMERA_REFERENCE_RANGE = 0.35    # m: the camera field's z_ref, mid-range of the planned poses


def is_effect(name):
    """Return whether ``name`` is an effect a model can carry: named, or a generic term."""
    return name in PARAMETERS or bool(JOINT_TERM.match(name) or CAMERA_TERM.match(name))


def is_joint_effect(name):
    """Return whether an effect acts between the joint and its reading (FK applies it)."""
    return name in JOINT_NAMED or bool(JOINT_TERM.match(name))


def is_camera_term(name):
    """Return whether ``name`` is a camera-field term."""
    return bool(CAMERA_TERM.match(name))


def joint_term_names(orders):
    """Return the term names of the joint harmonics of the given orders n."""
    return tuple(f'joint_{kind}{n}' for n in orders for kind in ('cos', 'sin'))


def camera_term_names(degree):
    """Return the camera-field monomials up to ``degree`` in x, y, w (no constant term)."""
    names = []
    for d in range(1, degree + 1):
        names += [''.join(m) for m in _monomials('xyw', d)]
    return tuple(f'camera_{m}' for m in names)


def _monomials(letters, degree):
    if degree == 0:
        return [()]
    return [(letters[i],) + rest for i in range(len(letters))
            for rest in _monomials(letters[i:], degree - 1)]


def camera_basis(name, sphere):
    """Return the monomial phi_m of a camera-field term at sphere centres (K, 3): (K,)."""
    x, y, z = np.asarray(sphere, dtype=float).T
    values = {'x': x / CAMERA_REFERENCE_RANGE, 'y': y / CAMERA_REFERENCE_RANGE,
              'w': z / CAMERA_REFERENCE_RANGE - 1}
    out = np.ones(len(z))
    for letter in CAMERA_TERM.match(name).group(1):
        out = out * values[letter]
    return out


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
    if name in GENERIC:
        _validate_generic(effect, where)
        return
    keys = BASE_GEOMETRY_KEYS if name == 'base_geometry' else (PARAMETERS[name][0],)
    for key in keys:
        if key not in effect and name != 'base_geometry':
            raise DescriptionError(f'{where}.{key}: missing key')
        if key in effect:
            _three(effect[key], f'{where}.{key}')
    if name == 'gravity_compliance':
        load = effect.get('gravity_load', NOMINAL_GRAVITY_LOAD)
        for part in ('arm', 'platform'):
            value = load.get(part) if isinstance(load, dict) else None
            if isinstance(value, bool) or not isinstance(value, (int, float)) \
                    or not np.isfinite(value) or value < 0:
                raise DescriptionError(f'{where}.gravity_load.{part}: expected a finite mass '
                                       f'(kg), got {value!r}')


def _validate_generic(effect, where):
    terms = effect.get('terms')
    if not isinstance(terms, dict) or not terms:
        raise DescriptionError(f'{where}.terms: expected a map of terms to three numbers')
    pattern = JOINT_TERM if effect['name'] == 'joint_harmonics' else CAMERA_TERM
    prefix = 'joint_' if effect['name'] == 'joint_harmonics' else 'camera_'
    for term, value in terms.items():
        if not pattern.match(prefix + str(term)):
            raise DescriptionError(f'{where}.terms.{term}: not a term of {effect["name"]}')
        _three(value, f'{where}.terms.{term}')
    if effect['name'] == 'camera_field':
        reference = effect.get('reference_range')
        if reference != CAMERA_REFERENCE_RANGE:
            raise DescriptionError(f'{where}.reference_range: expected '
                                   f'{CAMERA_REFERENCE_RANGE} m, got {reference!r}')


def parameters(desc):
    """
    Return a description's effect parameters as {name: array of 3} (base_geometry excluded).

    A generic effect gives one entry per term ('joint_cos5', 'camera_w').
    """
    out = {}
    for e in desc.effects:
        if e['name'] in PARAMETERS:
            out[e['name']] = np.asarray(e[PARAMETERS[e['name']][0]], dtype=float)
        elif e['name'] in GENERIC:
            prefix = 'joint_' if e['name'] == 'joint_harmonics' else 'camera_'
            out.update({prefix + t: np.asarray(v, dtype=float) for t, v in e['terms'].items()})
    return out


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
    for name in fx:
        term = JOINT_TERM.match(name)
        if term:
            wave = np.cos if term.group(1) == 'cos' else np.sin
            derivative[name] = wave(int(term.group(2)) * Theta)
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
    (for compliance). With h the joint harmonics,
    Theta = (theta - theta0 + w/2 dir - c tau_g(P, theta0 + Theta) - h(Theta)) / (1 + k),
    solved by fixed point: the sag and the harmonics change by 1e-3 of a step or less, so three
    passes are exact.
    """
    fx = parameters(desc)
    k = fx.get('joint_scale', np.zeros(3))
    lead = theta - desc.theta0 + 0.5 * fx.get('backlash', np.zeros(3)) * direction
    Theta = lead / (1 + k)
    implicit = {name: v for name, v in fx.items()
                if name == 'gravity_compliance' or JOINT_TERM.match(name)}
    for _ in range(3 if implicit else 0):
        _, derivative = model_joint_angles(desc, implicit, Theta, direction, P, gravity_load(desc))
        shift = sum(implicit[name] * d for name, d in derivative.items())
        Theta = (lead - shift) / (1 + k)
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


def camera_increments(fx, Pi, R, at=None):
    """
    Return the increments the camera-side effects of ``fx`` give for the measured ones (K, 3).

    The camera field's error is removed from the sphere centre s = -R^T Pi, then the hand-eye
    rotation turns the result (see the module docstring); R is the declared camera rotation.
    The field is evaluated at the increments ``at`` (default Pi).
    """
    terms = [name for name in fx if CAMERA_TERM.match(name)]
    if terms:
        sphere = -np.asarray(Pi if at is None else at, dtype=float) @ np.asarray(R)
        error = sum(np.outer(camera_basis(name, sphere), fx[name]) for name in terms)
        Pi = Pi + error @ np.asarray(R).T
    if 'hand_eye_rotation' not in fx:
        return Pi
    return Pi @ rotation_vector_matrix(fx['hand_eye_rotation']).T


def joint_angles(desc, Theta):
    """
    Return the arm angles (N, 3) for resolver increments (N, 3) visited in this order.

    Every joint effect the description holds is applied (``arm_angles``), with each joint's
    motion direction from the order of Theta.
    """
    Theta = np.asarray(Theta, dtype=float).reshape(-1, 3)
    return arm_angles(desc, parameters(desc), Theta, motion_direction(Theta))


def arm_angles(desc, fx, Theta, direction):
    """
    Return the arm angles (N, 3) for readings Theta (N, 3) under the joint effects of ``fx``.

    ``direction`` (N, 3): each joint's motion into each pose. Compliance depends on the pose, so
    it is iterated with FK (the sag is tiny: two passes agree to far below a resolver count);
    effects of the camera side in ``fx`` are ignored.
    """
    joint_fx = {k: v for k, v in fx.items() if is_joint_effect(k) and k != 'gravity_compliance'}
    theta, _ = model_joint_angles(desc, joint_fx, Theta, direction, None)
    if 'gravity_compliance' not in fx:
        return theta
    sagged = theta
    for _ in range(2):
        P = delta.forward(desc, sagged)
        torque = gravity_torque(desc, P, theta, gravity_load(desc))
        sagged = theta + fx['gravity_compliance'] * torque
    return sagged
