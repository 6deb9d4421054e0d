"""
The hand camera: pinhole with the plumb_bob distortion model (ROS camera_info conventions).

A point X = (X, Y, Z) in the optical frame (x right, y down, z forward, m) projects to

    x = X / Z, y = Y / Z                                  (normalized, undistorted)
    r^2 = x^2 + y^2,  L = 1 + k1 r^2 + k2 r^4 + k3 r^6
    x_d = x L + 2 p1 x y + p2 (r^2 + 2 x^2)
    y_d = y L + p1 (r^2 + 2 y^2) + 2 p2 x y              (plumb_bob, D = [k1, k2, p1, p2, k3])
    [u, v, 1]^T = K [x_d, y_d, 1]^T                       (pixels; pixel centres at integers)

Undistortion inverts the distortion by Newton's method (quadratic convergence; 1e-14 in a few
steps).

Calibration files are the ROS camera_info YAML that camera_calibration_parsers reads and writes.
The default camera (``default()``, ``config/hand_camera.yaml``) resembles the paper's: 640x480 and
f = 500 px, i.e. the paper's "0.4 mm per pixel" at 200 mm (section 6.1). The paper's ball
(R_B = 19 mm) then spans 127 px at 150 mm and 32 px at 600 mm, the range the detector is
specified for.
"""
from dataclasses import dataclass, field
import os

import numpy as np
from robotenis_kinematics import files
import yaml

DEFAULT_K = ((500.0, 0.0, 319.5), (0.0, 500.0, 239.5), (0.0, 0.0, 1.0))
DEFAULT_D = (-0.10, 0.05, 4e-4, -3e-4, 0.0)   # mild barrel distortion of a small C-mount lens
NEWTON_STEPS = 12


class CameraError(ValueError):
    """A camera description that cannot be used; the message names the offending field."""


@dataclass(frozen=True, eq=False)
class Camera:
    """Intrinsics K (3x3), plumb_bob D = [k1, k2, p1, p2, k3], image size in pixels."""

    K: np.ndarray
    D: np.ndarray
    width: int
    height: int
    name: str = 'hand_camera'
    R: np.ndarray = field(default_factory=lambda: np.eye(3))

    def __post_init__(self):
        K = _matrix(self.K, (3, 3), 'camera_matrix')
        if not (K[0, 0] > 0 and K[1, 1] > 0 and K[2, 2] == 1
                and K[1, 0] == K[2, 0] == K[2, 1] == 0):
            raise CameraError('camera_matrix: expected [[fx, s, cx], [0, fy, cy], [0, 0, 1]] '
                              f'with fx, fy > 0, got {K.tolist()}')
        D = np.asarray(self.D, dtype=float).ravel()
        if D.shape == (4,):
            D = np.append(D, 0.0)
        if D.shape != (5,) or not np.all(np.isfinite(D)):
            raise CameraError('distortion_coefficients: expected 5 finite numbers '
                              f'[k1, k2, p1, p2, k3], got {self.D!r}')
        for key in ('width', 'height'):
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value <= 0:
                raise CameraError(f'image_{key}: expected a positive integer, got {value!r}')
        object.__setattr__(self, 'K', K)
        object.__setattr__(self, 'D', D)
        object.__setattr__(self, 'R', _matrix(self.R, (3, 3), 'rectification_matrix'))
        object.__setattr__(self, 'width', int(self.width))
        object.__setattr__(self, 'height', int(self.height))

    fx = property(lambda self: self.K[0, 0])
    fy = property(lambda self: self.K[1, 1])
    cx = property(lambda self: self.K[0, 2])
    cy = property(lambda self: self.K[1, 2])

    @property
    def P(self):
        """Return camera_info's 3x4 projection matrix [K | 0] (monocular, unrectified camera)."""
        return np.hstack([self.K, np.zeros((3, 1))])

    # --- normalized <-> pixel -------------------------------------------------------------
    def to_pixels(self, xy):
        """Map normalized coordinates (..., 2) to pixels (..., 2) through K (no distortion)."""
        xy = np.asarray(xy, dtype=float)
        K = self.K
        out = np.empty(xy.shape)
        out[..., 0] = K[0, 0] * xy[..., 0] + K[0, 1] * xy[..., 1] + K[0, 2]
        out[..., 1] = K[1, 1] * xy[..., 1] + K[1, 2]
        return out

    def to_normalized(self, uv):
        """Pixels (..., 2) to normalized coordinates (..., 2) through K^-1 (no distortion)."""
        uv = np.asarray(uv, dtype=float)
        K = self.K
        out = np.empty(uv.shape)
        out[..., 1] = (uv[..., 1] - K[1, 2]) / K[1, 1]
        out[..., 0] = (uv[..., 0] - K[0, 2] - K[0, 1] * out[..., 1]) / K[0, 0]
        return out

    # --- plumb_bob --------------------------------------------------------------------------
    def distort(self, xy):
        """Undistorted normalized points (..., 2) to distorted normalized points (plumb_bob)."""
        xy = np.asarray(xy, dtype=float)
        return distort(xy, self.D)

    def undistort(self, xy_d):
        """Distorted normalized points (..., 2) to undistorted ones (Newton; NaN if it fails)."""
        return undistort(np.asarray(xy_d, dtype=float), self.D)

    def distort_pixels(self, uv):
        """Ideal (undistorted) pixels (..., 2) to the pixels the lens actually images them at."""
        return self.to_pixels(self.distort(self.to_normalized(uv)))

    def undistort_pixels(self, uv):
        """Image pixels (..., 2) to ideal pixel positions (K applied to the undistorted point)."""
        return self.to_pixels(self.undistort(self.to_normalized(uv)))

    def pixel_rays(self, uv):
        """Image pixels (..., 2) to undistorted normalized points (x, y) with the ray (x, y, 1)."""
        return self.undistort(self.to_normalized(uv))

    def apparent_radius(self, centre, radius):
        """
        Return a sphere's apparent radius (px): fx R / sqrt(|C|^2 - R^2), the touching cone's.

        ``centre`` (3,) optical frame and ``radius`` in m; the centre must lie outside the sphere.
        """
        c = np.asarray(centre, dtype=float)
        return self.fx * radius / np.sqrt(max(c @ c - radius * radius, 1e-12))

    def project(self, points):
        """Optical-frame points (..., 3), m, to distorted pixels (..., 2); Z must be positive."""
        points = np.asarray(points, dtype=float)
        if points.shape[-1] != 3:
            raise CameraError(f'project: expected points of shape (..., 3), got {points.shape}')
        Z = points[..., 2]
        if np.any(Z <= 0):
            raise CameraError('project: a point is not in front of the camera (Z <= 0)')
        return self.to_pixels(self.distort(points[..., :2] / Z[..., None]))

    def contains(self, uv, margin=0.0):
        """Mask of pixel positions inside the image, ``margin`` pixels away from its border."""
        uv = np.asarray(uv, dtype=float)
        return ((uv[..., 0] >= -0.5 + margin) & (uv[..., 0] <= self.width - 0.5 - margin)
                & (uv[..., 1] >= -0.5 + margin) & (uv[..., 1] <= self.height - 0.5 - margin))

    # --- camera_info --------------------------------------------------------------------------
    def to_yaml_dict(self):
        """Return the camera_calibration_parsers YAML layout as plain Python types."""
        def block(a):
            a = np.atleast_2d(a)
            return {'rows': a.shape[0], 'cols': a.shape[1], 'data': [float(v) for v in a.ravel()]}
        return {'image_width': self.width, 'image_height': self.height, 'camera_name': self.name,
                'camera_matrix': block(self.K), 'distortion_model': 'plumb_bob',
                'distortion_coefficients': block(self.D[None, :]),
                'rectification_matrix': block(self.R), 'projection_matrix': block(self.P)}

    def camera_info_fields(self):
        """
        Return the sensor_msgs/CameraInfo field values as plain types.

        The fields: height, width, distortion_model, d, k, r, p.
        """
        return {'height': self.height, 'width': self.width, 'distortion_model': 'plumb_bob',
                'd': [float(v) for v in self.D], 'k': [float(v) for v in self.K.ravel()],
                'r': [float(v) for v in self.R.ravel()], 'p': [float(v) for v in self.P.ravel()]}


def distort(xy, D):
    """plumb_bob distortion of normalized points (..., 2) with D = [k1, k2, p1, p2, k3]."""
    k1, k2, p1, p2, k3 = D
    x, y = xy[..., 0], xy[..., 1]
    r2 = x * x + y * y
    L = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xy2 = 2 * x * y
    out = np.empty(xy.shape)
    out[..., 0] = x * L + p1 * xy2 + p2 * (r2 + 2 * x * x)
    out[..., 1] = y * L + p1 * (r2 + 2 * y * y) + p2 * xy2
    return out


def distortion_jacobian(xy, D):
    """d(x_d, y_d)/d(x, y) of the plumb_bob model: (..., 2, 2)."""
    k1, k2, p1, p2, k3 = D
    x, y = xy[..., 0], xy[..., 1]
    r2 = x * x + y * y
    L = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    dL = k1 + r2 * (2 * k2 + 3 * k3 * r2)          # dL / d(r^2)
    J = np.empty(xy.shape[:-1] + (2, 2))
    J[..., 0, 0] = L + 2 * x * x * dL + 2 * p1 * y + 6 * p2 * x
    J[..., 0, 1] = 2 * x * y * dL + 2 * p1 * x + 2 * p2 * y
    J[..., 1, 0] = 2 * x * y * dL + 2 * p1 * x + 2 * p2 * y
    J[..., 1, 1] = L + 2 * y * y * dL + 6 * p1 * y + 2 * p2 * x
    return J


def undistort(xy_d, D, steps=NEWTON_STEPS, tol=1e-14):
    """Invert plumb_bob by Newton's method; points where it does not converge come back as NaN."""
    xy = np.array(xy_d, dtype=float, copy=True)
    if not np.any(D):
        return xy
    for _ in range(steps):
        g = distort(xy, D) - xy_d
        if np.nanmax(np.abs(g), initial=0.0) < tol:
            break
        J = distortion_jacobian(xy, D)
        det = J[..., 0, 0] * J[..., 1, 1] - J[..., 0, 1] * J[..., 1, 0]
        xy[..., 0] -= (J[..., 1, 1] * g[..., 0] - J[..., 0, 1] * g[..., 1]) / det
        xy[..., 1] -= (J[..., 0, 0] * g[..., 1] - J[..., 1, 0] * g[..., 0]) / det
    bad = np.any(np.abs(distort(xy, D) - xy_d) > 1e-9, axis=-1)
    xy[bad] = np.nan
    return xy


def _matrix(value, shape, key):
    try:
        a = np.asarray(value, dtype=float).reshape(shape)
    except (TypeError, ValueError):
        raise CameraError(f'{key}: expected {shape[0]}x{shape[1]} numbers, '
                          f'got {value!r:.80}') from None
    if not np.all(np.isfinite(a)):
        raise CameraError(f'{key}: must be finite')
    return a


def _block(data, key, shape):
    """Read a {rows, cols, data} block of the YAML file, checked against the expected shape."""
    if not isinstance(data, dict) or 'data' not in data:
        raise CameraError(f'{key}: expected a map with rows, cols and data')
    rows, cols = data.get('rows', shape[0]), data.get('cols', shape[1])
    values = data['data']
    if not isinstance(values, list) or len(values) != rows * cols or (rows, cols) != shape:
        raise CameraError(f'{key}: expected {shape[0]}x{shape[1]} values, '
                          f'got rows={rows} cols={cols} and '
                          f'{len(values) if isinstance(values, list) else values!r} values')
    return _matrix(values, shape, key)


def from_yaml_dict(data):
    """Camera from the camera_calibration_parsers YAML layout; errors name the key."""
    if not isinstance(data, dict):
        raise CameraError('camera_info: expected a map at the top level, '
                          f'got {type(data).__name__}')
    for key in ('image_width', 'image_height', 'camera_matrix', 'distortion_coefficients'):
        if key not in data:
            raise CameraError(f'{key}: missing key')
    model = data.get('distortion_model', 'plumb_bob')
    if model != 'plumb_bob':
        raise CameraError(f"distortion_model: only 'plumb_bob' is supported, got {model!r}")
    dist = data['distortion_coefficients']
    n = (len(dist.get('data', []))
         if isinstance(dist, dict) and isinstance(dist.get('data'), list) else 5)
    D = _block(dist, 'distortion_coefficients', (1, n if n in (4, 5) else 5))
    R = _block(data['rectification_matrix'], 'rectification_matrix', (3, 3)) \
        if 'rectification_matrix' in data else np.eye(3)
    return Camera(_block(data['camera_matrix'], 'camera_matrix', (3, 3)), D.ravel(),
                  data['image_width'], data['image_height'],
                  str(data.get('camera_name', 'camera')), R)


def from_camera_info(msg):
    """Camera from a sensor_msgs/CameraInfo message, or a dict of its fields (k, d, width...)."""
    get = (lambda k: msg[k]) if isinstance(msg, dict) else (lambda k: getattr(msg, k))
    model = get('distortion_model') or 'plumb_bob'
    if model != 'plumb_bob':
        raise CameraError(f"distortion_model: only 'plumb_bob' is supported, got {model!r}")
    d = list(get('d'))
    if not d:
        d = [0.0] * 5
    r = list(get('r'))
    return Camera(list(get('k')), d, int(get('width')), int(get('height')),
                  R=r if any(r) else np.eye(3))


def loads(text):
    try:
        return from_yaml_dict(yaml.safe_load(text))
    except yaml.YAMLError as e:
        raise CameraError(f'camera_info: not valid YAML ({e})') from e


def load(path):
    """Read a ROS camera_info YAML file."""
    try:
        with open(path) as f:
            text = f.read()
    except OSError as e:
        raise CameraError(f'{path}: cannot read ({e.strerror})') from e
    try:
        return loads(text)
    except CameraError as e:
        raise CameraError(f'{path}: {e}') from None


def dumps(camera):
    return yaml.safe_dump(camera.to_yaml_dict(), sort_keys=False, default_flow_style=None)


def save(camera, path):
    """Write the camera_info YAML atomically (temporary file in the same folder, then rename)."""
    files.write_atomic(path, dumps(camera))


def default():
    """Return the default hand camera (see the module docstring)."""
    return Camera(np.array(DEFAULT_K), np.array(DEFAULT_D), 640, 480, 'hand_camera')


def default_path():
    """Path of config/hand_camera.yaml in the source tree or the installed share folder."""
    here = os.path.dirname(os.path.abspath(__file__))
    candidates = [os.path.join(here, '..', 'config', 'hand_camera.yaml')]
    try:
        from ament_index_python.packages import get_package_share_directory
        share = get_package_share_directory('robotenis_vision')
        candidates.append(os.path.join(share, 'config', 'hand_camera.yaml'))
    except Exception:  # not built or ament_index not importable: the source tree is enough
        pass
    for path in candidates:
        if os.path.exists(path):
            return os.path.normpath(path)
    raise FileNotFoundError('robotenis_vision config/hand_camera.yaml not found')
