"""
Images of the fixed ball by Mitsuba 3, a physically based renderer this project did not write.

A benchmark and test tool (benchmarks/vision.py, the committed set of
src/robotenis_vision/test/data/mitsuba): nothing of the product imports it. Mitsuba is imported
only inside the functions that render (``_mitsuba``), so the geometry and the scene lists can be
used without it. Requirements: benchmarks/requirements.txt (``./robotenis bench vision`` installs
them).

Frames. The world is the camera's optical frame (x right, y down, z forward, m); a point (X, Y, Z)
images at u = fx X / Z + cx, v = fy Y / Z + cy with pixel (0, 0) centred at u = v = 0, no lens
distortion. Mitsuba's camera space is x left, y up, z forward, and its film puts pixel i's centre
at i + 0.5: ``SENSOR_TO_WORLD`` (180 degrees about z) and ``sensor_parameters`` translate.
``check_projection``, ``check_outline`` and ``check_defocus`` render emissive spheres and compare
them with the exact geometry (``--verify``; agreement about 0.001 px).

Scenes (``draw_scene_list``: plain YAML-able dicts, seeded): the paper's ball (R_B = 19 mm) at
0.15-0.6 m, from the image centre toward a corner up to 10 px from the border; a diffuse or glossy
(rough plastic, GGX) ball; a point, area or environment light, frontal, side or back (by the angle
between ball-to-light and ball-to-camera: 0-35, 65-100, 115-160 degrees), or a constant
environment; a background plane at 1.5-3 times the ball's depth, dark, mid-grey, a gradient, a
checkerboard of 5-50 px squares or a random texture; a pinhole (1 in 4) or a thin lens blurring the
ball by a disc of 0.5-2 px radius; Rec. 709 luminance, a gain putting the ball's 95th percentile at
170-220 grey levels, a linear (70 %) or gamma-2.2 response, Gaussian sensor noise of 1-3 grey
levels, 8 bits. The 15 light x background classes come in shuffled rounds (scenes 0-14 hold each
once).

Rendering (``render``): the ball's window (its outline's box, ``WINDOW_MARGIN_PX`` around it) at
the scene's samples per pixel (64), the rest of the frame at ``FRAME_SPP`` (16): everything
measured lies in the window, and a frame costs about a third of a full one (22 CPU s at 64 spp).
The sampler is multijitter (stratified); the renderer's own noise is 0.5-4 grey levels at 64 spp,
on top of the sensor noise. ``render_repeat`` renders the window again with fresh sampling and
sensor noise under the first render's exposure: repeated frames of one scene. ``cached`` keeps
renders in a folder.

Pitfalls (measured while writing this): the outline's centre is not the projected ball centre
(4.4 px near a corner at 0.15 m: the truth gives both); brightness is normalised, not physical
(back-lit balls come out dark on a bright background); low-contrast sectors of the outline are real
(the truth's ``contrast.edge_sectors``); glossy balls may saturate at highlights and grazing rims;
Mitsuba's ``thinlens`` has no principal point offset (defocus needs cx = (W - 1) / 2,
cy = (H - 1) / 2), and ``checkerboard`` swaps its colours between eval and eval_1 (a bitmap is used
instead).
"""
import argparse
from dataclasses import asdict, dataclass
import hashlib
import itertools
import json
import math
from pathlib import Path
import platform
import time

import cv2
import numpy as np
from robotenis_kinematics import files
import yaml

BALL_RADIUS_M = 0.019
VARIANT = 'scalar_rgb'
LIGHTS = ('point', 'area', 'env')
BACKGROUNDS = ('dark', 'grey', 'gradient', 'checker', 'noise')
MATERIALS = ('diffuse', 'glossy')
DIRECTIONS = {'point': ('frontal', 'side', 'back'), 'area': ('frontal', 'side', 'back'),
              'env': ('frontal', 'side', 'back', 'ambient')}
LIGHT_ANGLES_DEG = {'frontal': (0.0, 35.0), 'side': (65.0, 100.0), 'back': (115.0, 160.0)}
AREA_BACK_ANGLES_DEG = (105.0, 140.0)   # an area light straight behind the ball would be in view
LUMA_REC709 = np.array([0.2126, 0.7152, 0.0722])
BALL_MARGIN_PX = 10.0          # the ball's outline keeps this far from the image border
PLANE_MARGIN = 1.15            # the background plane covers the view by this factor
INTEGRATOR = {'type': 'path', 'max_depth': 4}
FRAME_SPP = 16                 # samples per pixel outside the ball's window
WINDOW_MARGIN_PX = 24          # the window: the outline's box and this much around it
EMPTY_SEED = 7919              # the frames without the ball: their own sampling and noise


@dataclass(frozen=True)
class Camera:
    """Pinhole intrinsics (px) and image size of an undistorted camera."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int

    @property
    def K(self):
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def project(self, points):
        """Project optical-frame points (n, 3) or (3,) to pixels (n, 2)."""
        p = np.atleast_2d(np.asarray(points, dtype=float))
        return np.stack([self.fx * p[:, 0] / p[:, 2] + self.cx,
                         self.fy * p[:, 1] / p[:, 2] + self.cy], axis=-1)

    def backproject(self, u, v, z):
        """Return the optical-frame point at depth z that images at pixel (u, v)."""
        return np.array([(u - self.cx) / self.fx * z, (v - self.cy) / self.fy * z, z])

    def in_image(self, uv):
        """Return the mask of pixel positions on the image (pixel edges included)."""
        return ((uv[:, 0] >= -0.5) & (uv[:, 0] <= self.width - 0.5)
                & (uv[:, 1] >= -0.5) & (uv[:, 1] <= self.height - 0.5))


PROJECT_CAMERA = Camera(fx=500.0, fy=500.0, cx=319.5, cy=239.5, width=640, height=480)
SENSOR_TO_WORLD = np.diag([-1.0, -1.0, 1.0, 1.0])


# --- camera mapping and the exact outline (numpy only) ----------------------------------------

def sensor_parameters(cam):
    """
    Return Mitsuba perspective-sensor parameters that reproduce the pinhole ``cam``.

    Mitsuba maps a camera-space direction to film coordinates
    s = (0.5 + X / (2 Z tan(fov / 2)), 0.5 + (W / H) Y / (2 Z tan(fov / 2))) - offset (X, Y
    optical), and pixel i spans s W in [i, i + 1): fx = W / (2 tan(fov_x / 2)) and
    cx = (0.5 - offset_x) W - 0.5, likewise in y with the same focal length (square pixels only).
    """
    if not math.isclose(cam.fx, cam.fy, rel_tol=1e-12):
        raise ValueError("Mitsuba's perspective sensor needs fx == fy")
    return {'fov': math.degrees(2.0 * math.atan(cam.width / (2.0 * cam.fx))), 'fov_axis': 'x',
            'principal_point_offset_x': 0.5 - (cam.cx + 0.5) / cam.width,
            'principal_point_offset_y': 0.5 - (cam.cy + 0.5) / cam.height}


def sphere_conic(center, radius, K):
    """
    Return the conic Q of a sphere's outline: pixel p = (u, v, 1) is inside if p^T Q p > 0.

    The tangent cone from the camera centre is d^T (c c^T - (|c|^2 - r^2) I) d = 0 for directions
    d; with d = K^-1 p it is the image conic.
    """
    c = np.asarray(center, dtype=float)
    Kinv = np.linalg.inv(K)
    return Kinv.T @ (np.outer(c, c) - (c @ c - radius ** 2) * np.eye(3)) @ Kinv


def conic_ellipse(Q):
    """Return centre, shape matrix S ((p - c)^T S (p - c) <= 1 inside), axes, area of a conic."""
    E = -Q
    A, b, c = E[:2, :2], E[:2, 2], E[2, 2]
    centre = -np.linalg.solve(A, b)
    S = A / -(c + b @ centre)
    eigval, eigvec = np.linalg.eigh(S)
    major = eigvec[:, 0]
    return {'center_px': centre, 'shape': S, 'semi_axes_px': 1.0 / np.sqrt(eigval[::-1]),
            'angle_deg': math.degrees(math.atan2(major[1], major[0])) % 180.0,
            'area_px2': math.pi / math.sqrt(np.linalg.det(S))}


def ball_ellipse(cam, center, radius=BALL_RADIUS_M):
    """Return the exact image ellipse of a sphere seen by ``cam``."""
    return conic_ellipse(sphere_conic(center, radius, cam.K))


def ellipse_half_extents(ellipse):
    """Return the half width and half height (px) of the ellipse's bounding box."""
    return np.sqrt(np.diag(np.linalg.inv(ellipse['shape'])))


def ellipse_window(ellipse, margin, cam):
    """
    Return the pixel window (x0, y0, width, height) holding the ellipse and ``margin`` px.

    ValueError if that does not fit in the image.
    """
    c, h = ellipse['center_px'], ellipse_half_extents(ellipse) + margin
    x0, y0 = int(math.floor(c[0] - h[0])), int(math.floor(c[1] - h[1]))
    x1, y1 = int(math.ceil(c[0] + h[0])), int(math.ceil(c[1] + h[1]))
    if x0 < 0 or y0 < 0 or x1 >= cam.width or y1 >= cam.height:
        raise ValueError("the sphere's outline is not inside the image")
    return x0, y0, x1 - x0 + 1, y1 - y0 + 1


def ball_window(cam, center, radius=BALL_RADIUS_M, margin=WINDOW_MARGIN_PX):
    """Return the window the ball is rendered in at full quality, clipped to the image."""
    ellipse = ball_ellipse(cam, center, radius)
    c, h = ellipse['center_px'], ellipse_half_extents(ellipse) + margin
    x0, y0 = max(int(math.floor(c[0] - h[0])), 0), max(int(math.floor(c[1] - h[1])), 0)
    x1 = min(int(math.ceil(c[0] + h[0])), cam.width - 1)
    y1 = min(int(math.ceil(c[1] + h[1])), cam.height - 1)
    return x0, y0, x1 - x0 + 1, y1 - y0 + 1


def ellipse_rho(ellipse, u, v):
    """Return the normalised ellipse radius: 1 on the outline, below 1 inside."""
    du, dv = u - ellipse['center_px'][0], v - ellipse['center_px'][1]
    S = ellipse['shape']
    return np.sqrt(S[0, 0] * du * du + 2.0 * S[0, 1] * du * dv + S[1, 1] * dv * dv)


def coverage_image(ellipse, window, supersample=16):
    """
    Return the fraction of each pixel of ``window`` (x0, y0, w, h) inside the ellipse.

    From a regular supersample x supersample grid per pixel; pixel (i, j) covers
    [i - 0.5, i + 0.5] x [j - 0.5, j + 0.5].
    """
    x0, y0, w, h = window
    sub = (np.arange(supersample) + 0.5) / supersample - 0.5
    u = (x0 + np.arange(w))[:, None] + sub[None, :]
    v = (y0 + np.arange(h))[:, None] + sub[None, :]
    inside = ellipse_rho(ellipse, u.reshape(1, 1, w, supersample),
                         v.reshape(h, supersample, 1, 1)) <= 1.0
    return inside.mean(axis=(1, 3))


def thin_lens_blur_radius_px(fx, aperture, focus, depth):
    """Return the radius (px) of the thin lens's blur disc for a point at ``depth``."""
    return fx * aperture * abs(1.0 / depth - 1.0 / focus)


# --- drawing scenes (numpy only) -------------------------------------------------------------

def _unit(v):
    return v / np.linalg.norm(v)


def _orthonormal_basis(w):
    """Return unit vectors e1, e2 with (e1, e2, w) a right-handed orthonormal frame."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(w[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = _unit(np.cross(helper, w))
    return e1, np.cross(w, e1)


def _direction_at(w, angle_deg, azimuth):
    """Return the unit vector at ``angle_deg`` from unit w, turned by ``azimuth`` (rad) about w."""
    e1, e2 = _orthonormal_basis(w)
    a = math.radians(angle_deg)
    return math.cos(a) * w + math.sin(a) * (math.cos(azimuth) * e1 + math.sin(azimuth) * e2)


def _max_image_offset(cam, z, corner):
    """
    Find the largest fraction of the way to ``corner`` a ball at depth z may be placed at.

    Its outline keeps BALL_MARGIN_PX inside the image (bisection).
    """
    centre = np.array([cam.cx, cam.cy])

    def fits(t):
        u, v = centre + t * (corner - centre)
        ell = ball_ellipse(cam, cam.backproject(u, v, z))
        c, h = ell['center_px'], ellipse_half_extents(ell) + BALL_MARGIN_PX
        return (c[0] - h[0] >= -0.5 and c[0] + h[0] <= cam.width - 0.5
                and c[1] - h[1] >= -0.5 and c[1] + h[1] <= cam.height - 0.5)

    lo, hi = 0.0, 1.0
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if fits(mid) else (lo, mid)
    return lo


def draw_ball(rng, cam):
    """Draw a ball at depth 0.15-0.6 m between the image centre and a random corner."""
    z = rng.uniform(0.15, 0.6)
    corners = [(-0.5, -0.5), (cam.width - 0.5, -0.5), (-0.5, cam.height - 0.5),
               (cam.width - 0.5, cam.height - 0.5)]
    corner = np.array(corners[rng.integers(4)])
    t = rng.uniform(0.0, 1.0) * _max_image_offset(cam, z, corner)
    uv = np.array([cam.cx, cam.cy]) + t * (corner - np.array([cam.cx, cam.cy]))
    return {'center_m': cam.backproject(uv[0], uv[1], z).tolist(), 'radius_m': BALL_RADIUS_M,
            'corner_fraction': float(t)}


def draw_material(rng, kind):
    """Draw a diffuse (albedo 0.5-0.8) or rough-plastic glossy ball material."""
    material = {'type': kind, 'albedo': float(rng.uniform(0.5, 0.8))}
    if kind == 'glossy':
        material.update(alpha=float(rng.uniform(0.05, 0.3)), int_ior=1.5)
    return material


def draw_background(rng, kind, ball_z):
    """Draw a background plane facing the camera at 1.5-3 times the ball's depth."""
    ratio = float(rng.uniform(1.5, 3.0))
    bg = {'type': kind, 'depth_ratio': ratio, 'depth_m': ratio * ball_z}
    if kind == 'dark':
        bg['albedo'] = float(rng.uniform(0.02, 0.06))
    elif kind == 'grey':
        bg['albedo'] = float(rng.uniform(0.15, 0.35))
    elif kind == 'gradient':
        bg.update(albedo_low=float(rng.uniform(0.03, 0.2)),
                  albedo_high=float(rng.uniform(0.45, 0.8)),
                  angle_deg=float(rng.uniform(0.0, 360.0)))
    elif kind == 'checker':
        square = float(rng.uniform(5.0, 50.0))
        bg.update(albedo_low=float(rng.uniform(0.03, 0.15)),
                  albedo_high=float(rng.uniform(0.45, 0.8)),
                  square_px=square, phase_px=rng.uniform(0.0, 2.0 * square, 2).tolist())
    elif kind == 'noise':
        bg.update(albedo_low=float(rng.uniform(0.03, 0.15)),
                  albedo_high=float(rng.uniform(0.5, 0.8)),
                  scale_px=float(rng.uniform(2.0, 15.0)), texture_seed=int(rng.integers(2 ** 31)))
    else:
        raise ValueError(f'unknown background {kind!r}')
    return bg


def _area_light_points(light, n=7):
    """Return a grid of n x n points (n^2, 3) over an area light's rectangle."""
    to_world = np.asarray(light['to_world'])
    s = np.linspace(-1.0, 1.0, n)
    local = np.array([[a, b, 0.0, 1.0] for a in s for b in s])
    return (local @ to_world.T)[:, :3]


def _area_light_transform(position, target, half_size):
    """Return the 4x4 to_world of a rectangle at ``position`` whose +z normal faces ``target``."""
    ez = _unit(target - position)
    ex, ey = _orthonormal_basis(ez)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = ex * half_size[0], ey * half_size[1], ez, position
    return m


def _light_ok(light, cam, ball, plane_z):
    """
    Check a light's place: clear of the ball, in front of the background, out of view.

    At least half its distance to the ball away from the plane (the plane's hot spot stays within
    about 4x the ball's irradiance); an area light out of the camera's view.
    """
    pts = _area_light_points(light) if light['type'] == 'area' else np.array([light['position_m']])
    if (np.any(plane_z - pts[:, 2] < 0.5 * light['distance_m'])
            or np.any(np.linalg.norm(pts - ball, axis=1) < BALL_RADIUS_M + 0.01)):
        return False
    if light['type'] != 'area':
        return True
    front = pts[pts[:, 2] > 1e-3]
    return not (len(front) and np.any(cam.in_image(cam.project(front))))


def draw_light(rng, kind, direction, cam, ball_center, plane_z, tries=500):
    """
    Draw a point, area or environment light lighting the ball from ``direction``.

    The main light gives an irradiance of about 1 at the ball; point and area lights get a weak
    constant-environment fill (``fill``, relative irradiance); area lights from the back are
    two-sided panels, so that they light the background too. None if no place was found.
    """
    ball = np.asarray(ball_center, dtype=float)
    to_camera = _unit(-ball)
    if kind == 'env':
        if direction == 'ambient':
            return {'type': 'env', 'direction': direction, 'profile': 'constant'}
        angle = float(rng.uniform(*LIGHT_ANGLES_DEG[direction]))
        bright = _direction_at(to_camera, angle, rng.uniform(0.0, 2.0 * math.pi))
        return {'type': 'env', 'direction': direction, 'profile': 'gradient', 'angle_deg': angle,
                'bright_direction': bright.tolist(), 'low': float(rng.uniform(0.02, 0.2)),
                'exponent': float(rng.uniform(1.0, 4.0))}
    angles = (AREA_BACK_ANGLES_DEG if (kind, direction) == ('area', 'back')
              else LIGHT_ANGLES_DEG[direction])
    for _ in range(tries):
        angle = float(rng.uniform(*angles))
        dist = float(rng.uniform(0.5, 2.5) * np.linalg.norm(ball))
        position = ball + dist * _direction_at(to_camera, angle, rng.uniform(0.0, 2.0 * math.pi))
        light = {'type': kind, 'direction': direction, 'angle_deg': angle, 'distance_m': dist,
                 'position_m': position.tolist(), 'fill': float(rng.uniform(0.02, 0.15))}
        if kind == 'point':
            light['intensity'] = dist ** 2
        else:
            half = rng.uniform(0.02, 0.08, 2)
            light.update(half_size_m=half.tolist(), radiance=dist ** 2 / (4.0 * half[0] * half[1]),
                         to_world=_area_light_transform(position, ball, half).tolist(),
                         two_sided=direction == 'back')
        if _light_ok(light, cam, ball, plane_z):
            return light
    return None


def draw_blur(rng, cam, ball_z, plane_z):
    """Draw a pinhole (1 in 4) or a thin lens blurring the ball by a 0.5-2 px disc radius."""
    if rng.random() < 0.25:
        return {'model': 'pinhole', 'radius_px': 0.0, 'background_radius_px': 0.0}
    radius = float(rng.uniform(0.5, 2.0))
    aperture = float(rng.uniform(0.0005, 0.003))
    delta = radius / (cam.fx * aperture)
    behind = rng.random() < 0.5 or 1.0 / ball_z - delta < 0.2
    focus = 1.0 / (1.0 / ball_z + (delta if behind else -delta))
    return {'model': 'thinlens', 'radius_px': radius, 'aperture_radius_m': aperture,
            'focus_distance_m': focus,
            'background_radius_px': thin_lens_blur_radius_px(cam.fx, aperture, focus, plane_z)}


def draw_scene(rng, index, light, direction, background, spp, cam=PROJECT_CAMERA):
    """Draw one random scene of the given light type, direction and background classes."""
    material = draw_material(rng, MATERIALS[int(rng.integers(len(MATERIALS)))])
    while True:
        ball = draw_ball(rng, cam)
        bg = draw_background(rng, background, ball['center_m'][2])
        lamp = draw_light(rng, light, direction, cam, ball['center_m'], bg['depth_m'])
        if lamp is not None:
            break
    gamma = 2.2 if rng.random() < 0.3 else 1.0
    return {
        'id': f'{index:03d}', 'seed': int(rng.integers(2 ** 31)), 'spp': int(spp),
        'camera': asdict(cam), 'ball': ball, 'material': material, 'light': lamp,
        'background': bg, 'blur': draw_blur(rng, cam, ball['center_m'][2], bg['depth_m']),
        'noise': {'sigma_grey': float(rng.uniform(1.0, 3.0))},
        'exposure': {'target_grey': float(rng.uniform(170.0, 220.0)), 'percentile': 95.0,
                     'max_grey': 245.0, 'gamma': gamma,
                     'ball_clip_fraction': 0.02 if material['type'] == 'glossy' else 0.0},
    }


def draw_scene_list(count, seed, spp=64, cam=PROJECT_CAMERA):
    """
    Draw ``count`` random scenes.

    The 15 light x background classes come in shuffled rounds (scenes 0-14 hold each once, so do
    15-29, ...), and each light type cycles through its direction classes in a shuffled order.
    """
    rng = np.random.default_rng(seed)
    combos = list(itertools.product(LIGHTS, BACKGROUNDS))
    order = []
    while len(order) < count:
        order.extend(combos[i] for i in rng.permutation(len(combos)))
    next_direction = {k: itertools.cycle(rng.permutation(DIRECTIONS[k]).tolist()) for k in LIGHTS}
    return [draw_scene(rng, i, light, next(next_direction[light]), bg, spp, cam)
            for i, (light, bg) in enumerate(order[:count])]


# --- background textures (numpy only) ----------------------------------------------------------

def plane_half_size(cam, depth):
    """Return the half side (m) of a square plane at ``depth`` covering the view with margin."""
    reach_px = max(cam.cx + 0.5, cam.width - 0.5 - cam.cx, cam.cy + 0.5,
                   cam.height - 0.5 - cam.cy)
    return PLANE_MARGIN * reach_px * depth / min(cam.fx, cam.fy)


def background_texture(bg, cam):
    """
    Return the albedo texture of a textured background plane, its centre (m) and half side (m).

    Rows along +y, columns along +x. Checker squares are one texel each, with square edges imaged
    at u = cx + phase_px[0] + k square_px (likewise v). The gradient runs from albedo_low to
    albedo_high over the image diagonal along angle_deg (0 = +u, 90 = +v), centred on the principal
    point. The noise is white noise low-passed by a Gaussian of scale_px, mapped to
    albedo_low..albedo_high (+- 2 sigma, clipped). Gradient and noise texels are 0.5 px.
    """
    depth = bg['depth_m']
    half = plane_half_size(cam, depth)
    lo, hi = bg['albedo_low'], bg['albedo_high']
    if bg['type'] == 'checker':
        square = bg['square_px'] * depth / cam.fx
        n = 2 * int(math.ceil((half + 2.0 * square) / square))
        i, j = np.indices((n, n))
        albedo = np.where((i + j) % 2 == 0, lo, hi)
        offset = np.asarray(bg['phase_px']) * depth / cam.fx
        return albedo, (offset[0], offset[1]), n * square / 2.0
    texel = 0.5 * depth / cam.fx
    n = int(math.ceil(2.0 * half / texel))
    px = ((np.arange(n) + 0.5) * texel - half) * cam.fx / depth
    if bg['type'] == 'gradient':
        a = math.radians(bg['angle_deg'])
        s = math.cos(a) * px[None, :] + math.sin(a) * px[:, None]
        albedo = lo + (hi - lo) * np.clip(0.5 + s / math.hypot(cam.width, cam.height), 0.0, 1.0)
    elif bg['type'] == 'noise':
        white = np.random.default_rng(bg['texture_seed']).standard_normal((n, n))
        smooth = cv2.GaussianBlur(white.astype(np.float32), (0, 0), sigmaX=bg['scale_px'] / 0.5)
        albedo = lo + (hi - lo) * np.clip(0.5 + 0.25 * smooth / smooth.std(), 0.0, 1.0)
    else:
        raise ValueError(f"background {bg['type']!r} has no texture")
    return albedo, (0.0, 0.0), half


def gradient_envmap(light, height=64):
    """Return a latitude-longitude radiance map (H, 2H, 3): 1 at the +y pole falling to ``low``."""
    theta = (np.arange(height) + 0.5) / height * math.pi
    row = light['low'] + (1.0 - light['low']) * ((1.0 + np.cos(theta)) / 2.0) ** light['exponent']
    return np.repeat(np.repeat(row[:, None, None], 2 * height, axis=1), 3,
                     axis=2).astype(np.float32)


def frame_with_y(direction):
    """Return the 4x4 rotation taking local +y to ``direction``."""
    y = _unit(np.asarray(direction, dtype=float))
    z, x = _orthonormal_basis(y)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2] = x, y, z
    return m


# --- the Mitsuba scene -------------------------------------------------------------------------

def _mitsuba():
    import mitsuba as mi
    if mi.variant() != VARIANT:
        mi.set_variant(VARIANT)
    return mi


def _transform(mi, matrix):
    return mi.ScalarTransform4f(np.asarray(matrix, dtype=float).tolist())


def _rgb(value):
    return {'type': 'rgb', 'value': [float(value)] * 3}


def sensor_dict(mi, cam, blur, spp, crop=None):
    """
    Return the Mitsuba sensor matching ``cam``: pinhole (``perspective``) or ``thinlens``.

    A box reconstruction filter makes each pixel the mean over its own area; ``crop``
    (x0, y0, w, h) renders that window of the same projection.
    """
    film = {'type': 'hdrfilm', 'width': cam.width, 'height': cam.height,
            'rfilter': {'type': 'box'}, 'pixel_format': 'rgb', 'component_format': 'float32'}
    if crop is not None:
        film.update(crop_offset_x=crop[0], crop_offset_y=crop[1], crop_width=crop[2],
                    crop_height=crop[3])
    sensor = {'type': 'perspective', **sensor_parameters(cam), 'film': film,
              'to_world': _transform(mi, SENSOR_TO_WORLD),
              'sampler': {'type': 'multijitter', 'sample_count': int(spp)}}
    if blur['model'] == 'thinlens':
        offsets = (sensor.pop('principal_point_offset_x'), sensor.pop('principal_point_offset_y'))
        if max(map(abs, offsets)) > 1e-9:
            raise ValueError("Mitsuba's thinlens sensor has no principal point offset: "
                             'needs cx = (W - 1) / 2 and cy = (H - 1) / 2')
        sensor.update(type='thinlens', aperture_radius=blur['aperture_radius_m'],
                      focus_distance=blur['focus_distance_m'])
    return sensor


def material_dict(material):
    """Return the Mitsuba BSDF of the ball."""
    if material['type'] == 'diffuse':
        return {'type': 'diffuse', 'reflectance': _rgb(material['albedo'])}
    return {'type': 'roughplastic', 'distribution': 'ggx', 'alpha': material['alpha'],
            'int_ior': material['int_ior'], 'diffuse_reflectance': _rgb(material['albedo'])}


def background_dict(mi, bg, cam):
    """Return the Mitsuba rectangle of the background plane, facing the camera (normal -z)."""
    if bg['type'] in ('dark', 'grey'):
        centre, half = (0.0, 0.0), plane_half_size(cam, bg['depth_m'])
        reflectance = _rgb(bg['albedo'])
    else:
        albedo, centre, half = background_texture(bg, cam)
        # the rectangle's v runs along world -y and bitmap row 0 sits at v = 0: rows along -y
        reflectance = {'type': 'bitmap', 'raw': True, 'wrap_mode': 'clamp',
                       'filter_type': 'nearest' if bg['type'] == 'checker' else 'bilinear',
                       'bitmap': mi.Bitmap(np.ascontiguousarray(albedo[::-1], dtype=np.float32))}
    to_world = np.diag([half, -half, -1.0, 1.0])     # 180 degrees about x, scaled, at its depth
    to_world[:3, 3] = [centre[0], centre[1], bg['depth_m']]
    return {'type': 'rectangle', 'to_world': _transform(mi, to_world),
            'bsdf': {'type': 'diffuse', 'reflectance': reflectance}}


def light_dicts(mi, light):
    """Return the Mitsuba emitters (and emitting shapes) of the light, keyed by name."""
    if light['type'] == 'env':
        if light['profile'] == 'constant':
            return {'env': {'type': 'constant', 'radiance': _rgb(1.0)}}
        return {'env': {'type': 'envmap', 'bitmap': mi.Bitmap(gradient_envmap(light)),
                        'to_world': _transform(mi, frame_with_y(light['bright_direction']))}}
    fill = {'fill': {'type': 'constant', 'radiance': _rgb(light['fill'] / math.pi)}}
    if light['type'] == 'point':
        return {'lamp': {'type': 'point', 'position': light['position_m'],
                         'intensity': _rgb(light['intensity'])}, **fill}
    front = np.asarray(light['to_world'])
    panels = {'lamp': _emitting_rectangle(mi, front, light['radiance'])}
    if light['two_sided']:
        # the panel turned over and 1 mm behind the front one, as seen from the ball
        back = front @ np.diag([1.0, -1.0, -1.0, 1.0])
        back[:3, 3] += 0.001 * back[:3, 2]
        panels['lamp_back'] = _emitting_rectangle(mi, back, light['radiance'])
    return panels | fill


def _emitting_rectangle(mi, to_world, radiance):
    return {'type': 'rectangle', 'to_world': _transform(mi, to_world),
            'emitter': {'type': 'area', 'radiance': _rgb(radiance)}}


def mitsuba_scene_dict(mi, scene):
    """Return the ``mi.load_dict`` description of a drawn scene, without its sensor."""
    cam = Camera(**scene['camera'])
    ball = scene['ball']
    return {'type': 'scene', 'integrator': dict(INTEGRATOR),
            'sensor': sensor_dict(mi, cam, scene['blur'], FRAME_SPP),
            'ball': {'type': 'sphere', 'center': ball['center_m'], 'radius': ball['radius_m'],
                     'bsdf': material_dict(scene['material'])},
            'background': background_dict(mi, scene['background'], cam),
            **light_dicts(mi, scene['light'])}


def _luminance(mi, scene, sensor, spp, seed):
    image = np.array(mi.render(scene, sensor=sensor, spp=int(spp), seed=int(seed)))
    return image[..., :3] @ LUMA_REC709


def render_luminance(scene, window=None, window_seed=None):
    """
    Render a drawn scene's linear luminance (H, W): the frame, the ball's window at full quality.

    The frame at FRAME_SPP samples per pixel, the window (x0, y0, w, h; default ``ball_window``)
    at the scene's ``spp``. With ``window_seed`` only the window is rendered (the rest is NaN).
    Returns the luminance and the samples per pixel the window used (multijitter rounds up to a
    product of two near-equal integers).
    """
    mi = _mitsuba()
    cam = Camera(**scene['camera'])
    loaded = mi.load_dict(mitsuba_scene_dict(mi, scene))
    window = window or ball_window(cam, scene['ball']['center_m'], scene['ball']['radius_m'])
    x0, y0, w, h = window
    if window_seed is None:
        luminance = _luminance(mi, loaded, loaded.sensors()[0], FRAME_SPP, scene['seed'])
        seed = scene['seed'] + 1
    else:
        luminance = np.full((cam.height, cam.width), np.nan)
        seed = window_seed
    sensor = mi.load_dict(sensor_dict(mi, cam, scene['blur'], scene['spp'], window))
    luminance[y0:y0 + h, x0:x0 + w] = _luminance(mi, loaded, sensor, scene['spp'], seed)
    return luminance, int(sensor.sampler().sample_count())


def ball_regions(ellipse, shape, blur_px):
    """
    Return pixel masks near the ball's outline, and each pixel's angle around its centre.

    The whole (blurred) disc, the ball's interior, the background ring just outside and the inner
    band just inside the outline; interior, ring and band keep 2 + blur px from the outline, ring
    and band are max(4, r / 4) px wide, r the ellipse's equivalent radius.
    """
    r = math.sqrt(ellipse['area_px2'] / math.pi)
    gap, width = (2.0 + blur_px) / r, max(4.0, 0.25 * r) / r
    v, u = np.indices(shape, dtype=float)
    rho = ellipse_rho(ellipse, u, v)
    return {'disc': rho <= 1.0 + (1.0 + blur_px) / r, 'ball': rho <= 1.0 - gap,
            'ring': (rho >= 1.0 + gap) & (rho <= 1.0 + gap + width),
            'inner': (rho <= 1.0 - gap) & (rho >= 1.0 - gap - width),
            'angle': np.arctan2(v - ellipse['center_px'][1], u - ellipse['center_px'][0])}


def exposure_gain(luminance, regions, exposure):
    """
    Return the gain of the exposure and the rule that set it.

    The smallest of: the gain putting the ``percentile`` of the ball-and-ring pixels at
    ``target_grey``; the one keeping all but max(5, ``ball_clip_fraction`` of the disc) ball pixels
    at or below ``max_grey``; the one keeping the image's 99.9th percentile at or below
    ``max_grey``.
    """
    def gain_for(grey, lum):
        return float((grey / 255.0) ** exposure['gamma'] / lum)

    disc = np.sort(luminance[regions['disc']])
    clipped = max(5, int(exposure['ball_clip_fraction'] * disc.size))
    gains = {
        'target': gain_for(exposure['target_grey'], np.percentile(
            luminance[regions['ball'] | regions['ring']], exposure['percentile'])),
        'ball_highlights': gain_for(exposure['max_grey'], disc[-clipped - 1]),
        'image': gain_for(exposure['max_grey'], np.percentile(luminance, 99.9)),
    }
    limited_by = min(gains, key=gains.get)
    return gains[limited_by], limited_by


def expose(luminance, gain, gamma, noise_sigma, rng):
    """Return the 8-bit grey image: 255 (gain L)^(1 / gamma), Gaussian noise, rounded, clipped."""
    grey = 255.0 * np.clip(gain * luminance, 0.0, 1.0) ** (1.0 / gamma)
    noisy = grey + rng.normal(0.0, noise_sigma, grey.shape)
    return np.clip(np.rint(noisy), 0, 255).astype(np.uint8)


def measure_contrast(image, regions, sectors=8):
    """
    Return the ball's mean minus the ring's (grey levels), and the same per angular sector.

    Per sector: the inner band's mean minus the ring's. Sector k spans atan2(v - v0, u - u0) in
    [-180 + 45 k, -135 + 45 k) degrees.
    """
    img = image.astype(float)
    edge = []
    for k in range(sectors):
        lo = -math.pi + 2.0 * math.pi * k / sectors
        sector = (regions['angle'] >= lo) & (regions['angle'] < lo + 2.0 * math.pi / sectors)
        edge.append(float(img[regions['inner'] & sector].mean()
                          - img[regions['ring'] & sector].mean()))
    ball, ring = float(img[regions['ball']].mean()), float(img[regions['ring']].mean())
    return {'ball_mean': ball, 'background_mean': ring, 'value': ball - ring,
            'edge_sectors': edge, 'edge_min_abs': float(min(abs(e) for e in edge))}


def _plain(obj):
    """Return ``obj`` with numpy scalars and arrays as Python floats, ints and lists."""
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple, np.ndarray)):
        return [_plain(v) for v in obj]
    if isinstance(obj, (np.floating, float)):
        return float(obj)
    if isinstance(obj, (np.integer, int)) and not isinstance(obj, bool):
        return int(obj)
    return obj


def make_truth(scene, ellipse, contrast, exposure, image, regions, renderer):
    """Return the truth record written next to each image."""
    cam = Camera(**scene['camera'])
    centre = scene['ball']['center_m']
    saturated = image == 255
    keys = ('id', 'seed', 'spp', 'camera', 'ball', 'material', 'light', 'background', 'blur',
            'noise')
    outline = {k: ellipse[k] for k in ('center_px', 'semi_axes_px', 'angle_deg', 'area_px2')}
    return _plain({
        'image': f"{scene['id']}.png", 'width': cam.width, 'height': cam.height,
        'K': cam.K, 'D': [0.0] * 5, 'distortion_model': 'plumb_bob',
        'ball': {'center_m': centre, 'radius_m': scene['ball']['radius_m'],
                 'center_px': cam.project(centre)[0], 'outline': outline,
                 'equivalent_radius_px': math.sqrt(ellipse['area_px2'] / math.pi)},
        'contrast': contrast,
        'saturated_pixels': {'total': int(saturated.sum()),
                             'on_ball': int((saturated & regions['disc']).sum())},
        'scene': {k: scene[k] for k in keys}
        | {'exposure': scene['exposure'] | exposure, 'redraws': scene.get('redraws', 0)},
        'renderer': renderer,
    })


def render(scene):
    """Render a drawn scene: its 8-bit mono image (H, W) and its truth (a dict)."""
    cam = Camera(**scene['camera'])
    wall, cpu = time.perf_counter(), time.process_time()
    luminance, spp_used = render_luminance(scene)
    mi = _mitsuba()
    renderer = {'name': 'mitsuba', 'version': mi.__version__, 'variant': VARIANT,
                'integrator': INTEGRATOR, 'sampler': 'multijitter', 'spp_used': spp_used,
                'frame_spp': FRAME_SPP,
                'window': list(ball_window(cam, scene['ball']['center_m'],
                                           scene['ball']['radius_m'])),
                'render_time_s': time.perf_counter() - wall,
                'render_cpu_s': time.process_time() - cpu}
    ellipse = ball_ellipse(cam, scene['ball']['center_m'], scene['ball']['radius_m'])
    regions = ball_regions(ellipse, luminance.shape, scene['blur']['radius_px'])
    gain, limited_by = exposure_gain(luminance, regions, scene['exposure'])
    image = expose(luminance, gain, scene['exposure']['gamma'], scene['noise']['sigma_grey'],
                   np.random.default_rng(scene['seed']))
    return image, make_truth(scene, ellipse, measure_contrast(image, regions),
                             {'gain': gain, 'limited_by': limited_by}, image, regions, renderer)


def render_repeat(scene, image, truth, k):
    """
    Render the k-th repeated frame of a scene: its window again, fresh sampling and sensor noise.

    ``image`` and ``truth`` are the scene's first render (``render``): the exposure's gain stays
    (a camera at a fixed exposure); outside the window the frame is the first one.
    """
    x0, y0, w, h = truth['renderer']['window']
    seed = scene['seed'] + 1000 * (k + 1)
    luminance, _ = render_luminance(scene, (x0, y0, w, h), window_seed=seed)
    exposure = truth['scene']['exposure']
    window = expose(luminance[y0:y0 + h, x0:x0 + w], exposure['gain'], exposure['gamma'],
                    scene['noise']['sigma_grey'], np.random.default_rng(seed))
    out = image.copy()
    out[y0:y0 + h, x0:x0 + w] = window
    return out


def render_empty(scene, truth):
    """
    Render a scene without its ball: its 8-bit mono image (H, W), for a detector to refuse.

    ``truth`` is the scene's first render's (``render``): its exposure's gain stays (a camera at
    a fixed exposure, the ball gone from its view); the whole frame at FRAME_SPP.
    """
    mi = _mitsuba()
    described = mitsuba_scene_dict(mi, scene)
    del described['ball']
    loaded = mi.load_dict(described)
    seed = scene['seed'] + EMPTY_SEED
    luminance = _luminance(mi, loaded, loaded.sensors()[0], FRAME_SPP, seed)
    exposure = truth['scene']['exposure']
    return expose(luminance, exposure['gain'], exposure['gamma'], scene['noise']['sigma_grey'],
                  np.random.default_rng(seed))


# --- a cache of renders ------------------------------------------------------------------------

def scene_key(scene, repeat=None):
    """Return the file stem of a render: the scene's id and a hash of what made it."""
    text = json.dumps([_plain(scene), FRAME_SPP, WINDOW_MARGIN_PX, INTEGRATOR, repeat],
                      sort_keys=True)
    return f"{scene['id']}-{hashlib.sha256(text.encode()).hexdigest()[:10]}"


def _png(image):
    ok, data = cv2.imencode('.png', image)
    if not ok:
        raise ValueError('cannot encode the image as PNG')
    return data.tobytes()


def cached(scene, folder):
    """
    Return the scene's image and truth from ``folder``, rendering and storing them if absent.

    Also returns whether it was rendered now.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    stem = scene_key(scene)
    png, truth_path = folder / f'{stem}.png', folder / f'{stem}.yaml'
    if png.exists() and truth_path.exists():
        return (cv2.imread(str(png), cv2.IMREAD_UNCHANGED),
                yaml.safe_load(truth_path.read_text()), False)
    image, truth = render(scene)
    files.write_atomic(truth_path, yaml.safe_dump(truth, sort_keys=False).encode())
    files.write_atomic(png, _png(image))
    return image, truth, True


def cached_empty(scene, truth, folder):
    """Return the scene's frame without its ball from ``folder`` (rendered if absent); if new."""
    return _cached_frame(Path(folder) / f"{scene_key(scene, 'empty')}.png",
                         lambda: render_empty(scene, truth))


def cached_repeat(scene, image, truth, k, folder):
    """Return the k-th repeated frame of a scene from ``folder`` (rendered if absent); if new."""
    return _cached_frame(Path(folder) / f'{scene_key(scene, k)}.png',
                         lambda: render_repeat(scene, image, truth, k))


def _cached_frame(path, make):
    """Return the PNG at ``path``, or ``make()``'s frame stored there; and whether it is new."""
    if path.exists():
        return cv2.imread(str(path), cv2.IMREAD_UNCHANGED), False
    out = make()
    files.write_atomic(path, _png(out))
    return out, True


# --- checks of the camera mapping against the exact geometry -------------------------------------

def emitter_sphere_luminance(cam, centre, radius, spp, crop=None, blur=None, seed=0):
    """Render a sphere of uniform radiance 1 on black (window ``crop`` or the whole image)."""
    mi = _mitsuba()
    sensor = sensor_dict(mi, cam, blur or {'model': 'pinhole'}, spp, crop)
    scene = mi.load_dict({'type': 'scene', 'integrator': {'type': 'direct'}, 'sensor': sensor,
                          'ball': {'type': 'sphere', 'center': list(map(float, centre)),
                                   'radius': float(radius),
                                   'emitter': {'type': 'area', 'radiance': _rgb(1.0)}}})
    return _luminance(mi, scene, scene.sensors()[0], spp, seed)


def intensity_centroid(image, x0=0, y0=0):
    """Return the intensity-weighted centroid (u, v) of a window whose pixel (0, 0) is (x0, y0)."""
    v, u = np.indices(image.shape)
    total = image.sum()
    return np.array([(image * u).sum() / total + x0, (image * v).sum() / total + y0])


def check_projection(cam, centre, radius=0.002, spp=4096):
    """
    Compare the centroid of a small emissive sphere's render with the exact geometry, px.

    ``exact_residual_px``: against the centroid of the exact pixel coverage of its outline (the
    camera mapping alone); ``pinhole_residual_px``: against the pinhole projection of its centre
    (adds the outline's perspective offset and pixel locking, both geometry).
    """
    ellipse = ball_ellipse(cam, centre, radius)
    window = ellipse_window(ellipse, 3.0, cam)
    image = emitter_sphere_luminance(cam, centre, radius, spp, window)
    centroid = intensity_centroid(image, window[0], window[1])
    exact = intensity_centroid(coverage_image(ellipse, window, 64), window[0], window[1])
    return {'centre_m': list(map(float, centre)),
            'exact_residual_px': float(np.linalg.norm(centroid - exact)),
            'pinhole_residual_px': float(np.linalg.norm(centroid - cam.project(centre)[0]))}


def check_outline(cam, centre, radius=BALL_RADIUS_M, spp=1024):
    """Compare a rendered emissive ball with its exact outline: equivalent radius, coverage."""
    ellipse = ball_ellipse(cam, centre, radius)
    window = ellipse_window(ellipse, 3.0, cam)
    rendered = emitter_sphere_luminance(cam, centre, radius, spp, window)
    exact = coverage_image(ellipse, window)
    return {'centre_m': list(map(float, centre)),
            'radius_error_px': (math.sqrt(float(rendered.sum()) / math.pi)
                                - math.sqrt(ellipse['area_px2'] / math.pi)),
            'pixel_rms_error': float(np.sqrt(np.mean((rendered - exact) ** 2)))}


def check_defocus(cam, centre, blur_px, aperture=0.002, radius=0.0015, spp=4096):
    """
    Check the thin lens: the centroid does not move, the blur disc adds b^2 / 4 to each variance.

    A small emissive sphere, the lens focused in front of it so that its disc radius is blur_px.
    """
    z = float(centre[2])
    focus = 1.0 / (1.0 / z + blur_px / (cam.fx * aperture))
    blur = {'model': 'thinlens', 'aperture_radius_m': aperture, 'focus_distance_m': focus}
    ellipse = ball_ellipse(cam, centre, radius)
    window = ellipse_window(ellipse, 3.0 + blur_px, cam)
    sharp = emitter_sphere_luminance(cam, centre, radius, spp, window)
    blurred = emitter_sphere_luminance(cam, centre, radius, spp, window, blur)

    def moments(image):
        v, u = np.indices(image.shape)
        c = intensity_centroid(image)
        return np.array([(image * (u - c[0]) ** 2).sum(),
                         (image * (v - c[1]) ** 2).sum()]) / image.sum()

    centroid = intensity_centroid(blurred, window[0], window[1])
    return {'centre_m': list(map(float, centre)), 'blur_px': blur_px,
            'centroid_shift_px': float(np.linalg.norm(centroid - ellipse['center_px'])),
            'added_variance_px2': (moments(blurred) - moments(sharp)).tolist(),
            'expected_added_variance_px2': blur_px ** 2 / 4.0}


def verification_report():
    """Return the mapping checks at the image centre, off axis and near the corners."""
    cam = PROJECT_CAMERA
    positions = [(0.0, 0.0, 0.25), (-0.1, -0.07, 0.25), (0.12, -0.09, 0.25), (0.08, 0.05, 0.3),
                 (-0.2, 0.15, 0.5), (0.2, 0.0, 0.6)]
    return _plain({
        'projection': [check_projection(cam, p) for p in positions],
        'outline': [check_outline(cam, p)
                    for p in [(0.0, 0.0, 0.15), (0.1, 0.07, 0.2), (-0.25, -0.18, 0.5)]],
        'defocus': [check_defocus(cam, p, b)
                    for p, b in [((0.0, 0.0, 0.3), 1.0), ((0.12, -0.09, 0.25), 2.0)]],
    })


# --- command line ------------------------------------------------------------------------------

def detectable_scene(scene, min_contrast, tries=5, preview_spp=4):
    """
    Return ``scene``, or a re-draw of its classes whose ball stands out of its background.

    The ball's mean minus the ring's, from a quick preview of the window, must reach
    ``min_contrast`` grey levels; after ``tries`` re-draws the last is kept whatever its contrast.
    The number of re-draws is recorded under ``redraws``.
    """
    rng = np.random.default_rng(scene['seed'])
    redraws = 0
    while redraws < tries and abs(_preview_contrast(scene, preview_spp)) < min_contrast:
        scene = draw_scene(rng, int(scene['id']), scene['light']['type'],
                           scene['light']['direction'], scene['background']['type'],
                           scene['spp'], Camera(**scene['camera']))
        redraws += 1
    return scene | {'redraws': redraws}


def _preview_contrast(scene, spp):
    cam = Camera(**scene['camera'])
    preview = scene | {'spp': spp}
    luminance, _ = render_luminance(preview, window_seed=scene['seed'])
    ellipse = ball_ellipse(cam, scene['ball']['center_m'], scene['ball']['radius_m'])
    regions = ball_regions(ellipse, luminance.shape, scene['blur']['radius_px'])
    seen = np.isfinite(luminance)
    regions = {k: (v & seen if k != 'angle' else v) for k, v in regions.items()}
    image = np.where(seen, luminance, 0.0)
    gain, _ = exposure_gain(image, regions, scene['exposure'])
    grey = 255.0 * np.clip(gain * image, 0, 1) ** (1.0 / scene['exposure']['gamma'])
    return float(grey[regions['ball']].mean() - grey[regions['ring']].mean())


def scene_list(count, seed, spp=64, min_contrast=10.0):
    """Draw ``count`` scenes, each re-drawn until its ball stands out (``detectable_scene``)."""
    scenes = draw_scene_list(count, seed, spp)
    return [detectable_scene(s, min_contrast) if min_contrast > 0 else s for s in scenes]


def cached_scene_list(count, seed, folder, spp=64, min_contrast=10.0):
    """Return ``scene_list``, kept in ``folder`` (its contrast previews render with Mitsuba)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    key = json.dumps([count, seed, spp, min_contrast, FRAME_SPP, WINDOW_MARGIN_PX])
    path = folder / f'scenes-{hashlib.sha256(key.encode()).hexdigest()[:10]}.json'
    if path.exists():
        return json.loads(path.read_text())
    scenes = _plain(scene_list(count, seed, spp, min_contrast))
    files.write_atomic(path, json.dumps(scenes).encode())
    return scenes


TRUTH_KEYS = ('image', 'width', 'height', 'K', 'D', 'distortion_model', 'ball', 'contrast',
              'saturated_pixels', 'scene')


def write_test_set(folder, count, seed, repeat_ids=(), repeats=0, cache=None, empty_ids=None):
    """
    Write a small set for the tests: NNN.png and NNN.yaml (the truth), and repeated windows.

    For the scenes of ``repeat_ids``, ``repeats`` re-renders of the ball's window (fresh sampling
    and sensor noise, the first render's exposure) as NNN-rK.png, the window only: the truth's
    ``renderer.window`` says where it goes. Renders come from ``cache`` when given. With
    ``empty_ids``, only those scenes, each with its frame without the ball (``render_empty``) as
    NNN-empty.png.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    entries = []
    for scene in scene_list(count, seed):
        if empty_ids is not None and scene['id'] not in empty_ids:
            continue
        if cache is None:
            image, truth = render(scene)
        else:
            image, truth, _ = cached(scene, cache)
        kept = {k: truth[k] for k in TRUTH_KEYS}
        kept['renderer'] = {k: truth['renderer'][k] for k in
                            ('name', 'version', 'variant', 'spp_used', 'frame_spp', 'window')}
        files.write_atomic(folder / f"{scene['id']}.png", _png(image))
        files.write_atomic(folder / f"{scene['id']}.yaml",
                           yaml.safe_dump(_plain(kept), sort_keys=False).encode())
        x0, y0, w, h = truth['renderer']['window']
        names = []
        for k in range(repeats if scene['id'] in repeat_ids else 0):
            if cache is None:
                frame = render_repeat(scene, image, truth, k)
            else:
                frame, _ = cached_repeat(scene, image, truth, k, cache)
            names.append(f"{scene['id']}-r{k}.png")
            files.write_atomic(folder / names[-1], _png(frame[y0:y0 + h, x0:x0 + w]))
        entries.append({'id': scene['id'], 'light': scene['light']['type'],
                        'direction': scene['light']['direction'],
                        'background': scene['background']['type'],
                        'material': scene['material']['type'], 'repeats': names})
        if empty_ids is not None:
            empty = (render_empty(scene, truth) if cache is None
                     else cached_empty(scene, truth, cache)[0])
            entries[-1]['empty'] = f"{scene['id']}-empty.png"
            files.write_atomic(folder / entries[-1]['empty'], _png(empty))
    index = {'count': count, 'seed': seed, 'frame_spp': FRAME_SPP, 'images': entries}
    files.write_atomic(folder / 'index.yaml',
                       yaml.safe_dump(_plain(index), sort_keys=False).encode())


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--out', type=Path, help='output folder')
    parser.add_argument('--count', type=int, help='number of images')
    parser.add_argument('--seed', type=int, help='seed of the scene list')
    parser.add_argument('--first', type=int, default=0, help='first scene of the list to write')
    parser.add_argument('--spp', type=int, default=64, help='samples per pixel of the window')
    parser.add_argument('--min-contrast', type=float, default=10.0,
                        help='re-draw scenes whose ball-to-background contrast is below this '
                             '(grey levels, from a preview; 0 keeps all)')
    parser.add_argument('--verify', action='store_true',
                        help='print the camera-mapping checks as YAML instead of rendering')
    parser.add_argument('--test-set', action='store_true',
                        help="write the tests' set (write_test_set) into --out instead")
    parser.add_argument('--repeat', nargs='*', default=[],
                        help='with --test-set: ids of the scenes rendered again')
    parser.add_argument('--repeats', type=int, default=0, help='with --test-set: how often')
    parser.add_argument('--cache', type=Path, default=None,
                        help='with --test-set: take the renders from this cache folder')
    parser.add_argument('--empty', nargs='*', default=None,
                        help='with --test-set: only these scenes, each also without its ball')
    args = parser.parse_args(argv)
    if args.verify:
        print(yaml.safe_dump(verification_report(), sort_keys=False))
        return 0
    if args.test_set:
        if args.out is None or args.count is None or args.seed is None:
            parser.error('--test-set needs --out, --count and --seed')
        write_test_set(args.out, args.count, args.seed, args.repeat, args.repeats, args.cache,
                       args.empty)
        return 0
    if args.out is None or args.count is None or args.seed is None:
        parser.error('--out, --count and --seed are required')
    args.out.mkdir(parents=True, exist_ok=True)
    entries = []
    for scene in scene_list(args.count, args.seed, args.spp, args.min_contrast)[args.first:]:
        image, truth = render(scene)
        files.write_atomic(args.out / f"{scene['id']}.png", _png(image))
        files.write_atomic(args.out / f"{scene['id']}.yaml",
                           yaml.safe_dump(truth, sort_keys=False).encode())
        entries.append({'id': scene['id'], 'light': scene['light']['type'],
                        'direction': scene['light']['direction'],
                        'background': scene['background']['type'],
                        'material': scene['material']['type'],
                        'blur_px': scene['blur']['radius_px'],
                        'contrast': truth['contrast']['value']})
        print(f"{scene['id']}: {entries[-1]['light']}/{entries[-1]['direction']} "
              f"{entries[-1]['background']} {entries[-1]['material']} contrast "
              f"{entries[-1]['contrast']:+.1f} in {truth['renderer']['render_time_s']:.1f} s",
              flush=True)
    index = {'count': args.count, 'seed': args.seed, 'spp': args.spp, 'frame_spp': FRAME_SPP,
             'min_contrast': args.min_contrast, 'camera': asdict(PROJECT_CAMERA),
             'python': platform.python_version(), 'images': entries}
    files.write_atomic(args.out / 'index.yaml',
                       yaml.safe_dump(_plain(index), sort_keys=False).encode())
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
