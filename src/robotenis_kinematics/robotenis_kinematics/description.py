"""
The robot description: one YAML file that every tool reads and writes.

Schema (SI units, REP-103)::

    legs:                  # three maps, leg i = 1, 2, 3 in order
      - {phi: 0.0, H: 0.21, a: 0.5, b: 1.0, h: 0.05, theta0: 0.0}
    camera:
      frame_id: camera_optical
      rotation: [[0, 0, 1], [1, 0, 0], [0, 1, 0]]  # columns: optical x, y, z in the effector frame
    sphere_radius: 0.019        # m: the paper's R_B = 19 mm (38 mm across)
    effects: []            # optional: effects found by calibration (robotenis_kinematics.effects)
    report: {}             # optional: free-form, written by calibration, ignored by the model

The frame is the paper's Sigma_0: origin at the centre of the base, x toward motor 1 (phi_1 = 0),
z down into the workspace (so gravity is +z), y completing a right-handed frame. Per leg
(calibration paper, Figure 2): ``phi`` the angle of motor axis A_i in the xy plane (rad), ``H`` the
distance from the origin to A_i, ``a`` the arm, ``b`` the forearm, ``h`` the distance from the
effector centre P to the ball joint C_i (m), ``theta0`` the arm angle at the resolvers' home (rad,
positive down).
"""
from dataclasses import dataclass, field
import math
import os

import numpy as np
from robotenis_kinematics import effects as effect_models
from robotenis_kinematics import files
from robotenis_kinematics.errors import DescriptionError
import yaml

LEG_KEYS = ('phi', 'H', 'a', 'b', 'h', 'theta0')


@dataclass
class RobotDescription:
    """
    Geometry of the three legs, the camera mounting and the calibration sphere.

    Attributes are numpy arrays of shape (3,) per leg parameter, so that ``d.a[i]`` is a_(i+1).
    """

    phi: np.ndarray
    H: np.ndarray
    a: np.ndarray
    b: np.ndarray
    h: np.ndarray
    theta0: np.ndarray
    camera_rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    camera_frame_id: str = 'camera_optical'
    sphere_radius: float = 0.019
    effects: list = field(default_factory=list)
    report: dict = field(default_factory=dict)

    def copy(self, **changes):
        """Return a deep copy with some fields replaced."""
        fields = {k: np.array(getattr(self, k), dtype=float) for k in LEG_KEYS}
        fields.update(camera_rotation=np.array(self.camera_rotation, dtype=float),
                      camera_frame_id=self.camera_frame_id,
                      sphere_radius=float(self.sphere_radius),
                      effects=[dict(e) for e in self.effects], report=dict(self.report))
        fields.update(changes)
        return RobotDescription(**fields)

    def to_dict(self):
        """Return the YAML schema as plain Python types."""
        legs = [{k: float(getattr(self, k)[i]) for k in LEG_KEYS} for i in range(3)]
        out = {
            'legs': legs,
            'camera': {'frame_id': self.camera_frame_id,
                       'rotation': [[float(v) for v in row] for row in self.camera_rotation]},
            'sphere_radius': float(self.sphere_radius),
        }
        if self.effects:
            out['effects'] = _plain(self.effects)
        if self.report:
            out['report'] = _plain(self.report)
        return out


def _plain(obj):
    """Convert numpy scalars and arrays inside dicts and lists to plain Python for YAML."""
    if isinstance(obj, dict):
        return {str(k): _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _plain(obj.tolist())
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


def _number(value, key):
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise DescriptionError(f'{key}: expected a number, got {type(value).__name__} {value!r}')
    if not math.isfinite(value):
        raise DescriptionError(f'{key}: must be finite, got {value!r}')
    return float(value)


def _require(mapping, key, where):
    if not isinstance(mapping, dict):
        raise DescriptionError(f'{where}: expected a map, got {type(mapping).__name__}')
    if key not in mapping:
        raise DescriptionError(f"{where + '.' if where else ''}{key}: missing key")
    return mapping[key]


def from_dict(data):
    """
    Build a RobotDescription from the parsed YAML, checking every key.

    Raises
    ------
    DescriptionError
        naming the key that is missing, of the wrong type or not finite.

    """
    if not isinstance(data, dict):
        raise DescriptionError('robot description: expected a map at the top level,'
                               f' got {type(data).__name__}')
    legs = _require(data, 'legs', '')
    if not isinstance(legs, list) or len(legs) != 3:
        raise DescriptionError(f'legs: expected a list of three maps, got {legs!r:.80}')
    values = {k: np.empty(3) for k in LEG_KEYS}
    for i, leg in enumerate(legs):
        for k in LEG_KEYS:
            values[k][i] = _number(_require(leg, k, f'legs[{i}]'), f'legs[{i}].{k}')
    for k in ('a', 'b'):
        if np.any(values[k] <= 0):
            raise DescriptionError(f'legs[{int(np.argmin(values[k]))}].{k}: must be positive')
    camera = _require(data, 'camera', '')
    frame_id = _require(camera, 'frame_id', 'camera')
    if not isinstance(frame_id, str) or not frame_id:
        raise DescriptionError(f'camera.frame_id: expected a non-empty string, got {frame_id!r}')
    rows = _require(camera, 'rotation', 'camera')
    if (not isinstance(rows, list) or len(rows) != 3
            or any(not isinstance(r, list) or len(r) != 3 for r in rows)):
        raise DescriptionError('camera.rotation: expected 3 rows of 3 numbers')
    R = np.array([[_number(v, f'camera.rotation[{r}][{c}]') for c, v in enumerate(row)]
                  for r, row in enumerate(rows)])
    if not np.allclose(R.T @ R, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
        raise DescriptionError('camera.rotation: not a rotation matrix (R^T R != I or det R != 1)')
    radius = _number(_require(data, 'sphere_radius', ''), 'sphere_radius')
    if radius <= 0:
        raise DescriptionError('sphere_radius: must be positive')
    effects = data.get('effects') or []
    if (not isinstance(effects, list)
            or any(not isinstance(e, dict) or 'name' not in e for e in effects)):
        raise DescriptionError("effects: expected a list of maps, each with a 'name'")
    for i, e in enumerate(effects):
        effect_models.validate(e, f'effects[{i}]')   # each effect model checks its own keys
        if any(other['name'] == e['name'] for other in effects[:i]):
            raise DescriptionError(f"effects[{i}].name: {e['name']} is listed twice")
    report = data.get('report') or {}
    if not isinstance(report, dict):
        raise DescriptionError('report: expected a map')
    return RobotDescription(camera_rotation=R, camera_frame_id=frame_id, sphere_radius=radius,
                            effects=effects, report=report, **values)


def load(path):
    """Read a robot description YAML file."""
    try:
        with open(path) as f:
            data = yaml.safe_load(f)
    except OSError as e:
        raise DescriptionError(f'{path}: cannot read ({e.strerror})') from e
    except yaml.YAMLError as e:
        raise DescriptionError(f'{path}: not valid YAML ({e})') from e
    try:
        return from_dict(data)
    except DescriptionError as e:
        raise DescriptionError(f'{path}: {e}') from None


def loads(text):
    """Parse a robot description from a YAML string (as carried on /robot_description)."""
    try:
        return from_dict(yaml.safe_load(text))
    except yaml.YAMLError as e:
        raise DescriptionError(f'robot description: not valid YAML ({e})') from e


def dumps(desc):
    """Return the description as YAML text."""
    return yaml.safe_dump(desc.to_dict(), sort_keys=False, default_flow_style=None)


def save(desc, path):
    """Write atomically: temp file in the same folder, then rename, so nothing is half written."""
    files.write_atomic(path, dumps(desc))


def config_path(name):
    """Path of a YAML file shipped in this package's config folder (source or install tree)."""
    here = os.path.dirname(os.path.abspath(__file__))
    for folder in (os.path.join(here, '..', 'config'), _share_config()):
        if folder and os.path.exists(os.path.join(folder, name)):
            return os.path.normpath(os.path.join(folder, name))
    raise FileNotFoundError(f'robotenis_kinematics config file {name!r} not found')


def _share_config():
    try:
        from ament_index_python.packages import get_package_share_directory
        return os.path.join(get_package_share_directory('robotenis_kinematics'), 'config')
    except Exception:  # not built or ament_index not importable: the source tree is enough
        return None


def nominal():
    """Return the nominal RoboTenis description (Table 1 nominal column; camera facing base +x)."""
    return load(config_path('nominal.yaml'))
