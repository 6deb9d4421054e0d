"""
The hand camera's picture of the ball, with known ground truth (no rclpy).

``render(camera, C, R, rng)`` draws the sphere of radius R centred at C (optical frame: x right,
y down, z forward, m) as the camera (robotenis_vision.camera.Camera: K, plumb_bob D) sees it:

* exact outline: a pixel ray d (undistorted through the camera's plumb_bob model) meets the sphere
  when the angle between d and C is below the half-angle beta of the tangent cone,
  sin(beta) = R/|C|. The outline is that cone's section, a conic, bent by the distortion;
* a pixel integrates the lens's image over its area: near the outline the ball is drawn on 2 x 2
  sub-pixels (those the outline crosses sampled by 8 x 8 rays each, the undistortion linearised
  across the pixel), blurred on them and averaged;
* shading at the surface point met by each ray: ambient + Lambertian diffuse for a light
  direction (frontal, side or behind the ball) + a Blinn-Phong specular highlight; values above
  255 saturate as on a real sensor;
* a background (``Background.pattern``): a linear gradient plus a smooth random texture (flat when
  both are zero), a checkerboard, or a random texture, with a defocus of its own (it lies at
  another depth);
* a Gaussian blur (the lens's, beyond the pixel's area) and a defocus (the uniform disc of a thin
  lens, ``defocus_px`` its radius), a response curve (``gamma``: grey = 255 (I / 255)^(1 /
  gamma)), then Gaussian sensor noise and rounding to 8 bits.

Speed (one 640x480 frame in a few ms): everything that depends only on the camera (the
undistorted ray of every pixel), on the background and on the blur is computed once and cached; a
frame starts as one of a few finished noisy backgrounds (uint8), and only a box around the ball is
rendered, blurred and given fresh noise (outside it the noise repeats from frame to frame: nothing
is measured there); a ball that has not moved since the last frame only gets fresh noise
(``_Still``).
``sphere_in_optical`` places the ball in the optical frame from the effector position and the
camera mounting (the hand_camera node).
"""
from dataclasses import dataclass
import functools

import cv2
import numpy as np
from robotenis_vision.camera import Camera

FINE = 2                      # sub-pixels per pixel side where the ball is drawn
SUPERSAMPLE = 8               # rays per sub-pixel side near the outline
LIMB_BAND_PX = 4.0            # inside the outline: sub-pixels shaded by their area, not centre
BANK = 8                      # finished background frames, one drawn per image


@dataclass(frozen=True)
class Lighting:
    """Light on the ball, in grey levels; ``direction`` points toward the light, optical frame."""

    direction: tuple = (-0.6, -0.7, -0.35)   # upper left, a little from the camera's side
    ambient: float = 30.0
    diffuse: float = 190.0
    specular: float = 90.0
    shininess: float = 30.0


@dataclass(frozen=True)
class Background:
    """
    The scene behind the ball, in grey levels, ``low`` to ``high``.

    ``pattern``: 'gradient', a linear gradient along ``angle`` (rad) across the image; 'checker',
    squares of ``square_px`` alternating low and high with edges at u, v = phase + k square_px;
    'noise', white noise low-passed by a Gaussian of ``scale_px`` px mapped to low..high
    (mean +- 2 standard deviations, clipped). Every pattern gets the smooth random ``texture`` on
    top, and ``defocus_px`` blurs the whole background by a disc of that radius.
    """

    low: float = 70.0
    high: float = 150.0
    angle: float = 0.4
    texture: float = 6.0          # standard deviation of the texture, grey levels
    texture_scale: float = 3.0    # its correlation length, px
    seed: int = 1
    pattern: str = 'gradient'
    square_px: float = 20.0
    scale_px: float = 5.0
    phase_px: tuple = (0.0, 0.0)
    defocus_px: float = 0.0

    def __post_init__(self):
        if self.pattern not in PATTERNS:
            raise ValueError(f"background pattern: one of {', '.join(PATTERNS)}, "
                             f'got {self.pattern!r}')
        if not (self.square_px > 0 and self.scale_px > 0) or self.defocus_px < 0:
            raise ValueError('background: square_px and scale_px must be positive and '
                             f'defocus_px not negative, got {self.square_px}, {self.scale_px}, '
                             f'{self.defocus_px}')


PATTERNS = ('gradient', 'checker', 'noise')


@dataclass(frozen=True)
class Optics:
    """What the lens and the sensor do to the scene: Gaussian blur, defocus disc, response."""

    blur_sigma: float
    defocus_px: float
    gamma: float


def render(camera, sphere_centre_optical, radius, rng, lighting=Lighting(),
           background=Background(), blur_sigma=0.8, noise_sigma=2.0, defocus_px=0.0, gamma=1.0):
    """Render a mono8 image (height, width) of the sphere; the background only if out of view."""
    C = np.asarray(sphere_centre_optical, dtype=float)
    if C.shape != (3,) or not np.all(np.isfinite(C)):
        raise ValueError('sphere_centre_optical: expected 3 finite numbers, '
                         f'got {sphere_centre_optical!r}')
    if not radius > 0:
        raise ValueError(f'radius: must be positive, got {radius!r}')
    if blur_sigma < 0 or noise_sigma < 0 or defocus_px < 0:
        raise ValueError('blur_sigma, noise_sigma and defocus_px must not be negative, '
                         f'got {blur_sigma}, {noise_sigma}, {defocus_px}')
    if not gamma > 0:
        raise ValueError(f'gamma: must be positive, got {gamma!r}')
    optics = Optics(float(blur_sigma), float(defocus_px), float(gamma))
    bank = _background_bank(_camera_key(camera), background, optics, float(noise_sigma))
    frame = bank[rng.integers(len(bank))].copy()
    box = _sphere_box(camera, C, radius)
    if box is not None:
        _draw_sphere(frame, camera, C, float(radius), lighting, background, optics,
                     float(noise_sigma), rng, box)
    return frame


def sphere_outline(camera, sphere_centre_optical, radius, n=360):
    """Return the sphere's exact outline, n points (n, 2) in distorted pixels, in order."""
    return camera.project(tangent_circle(sphere_centre_optical, radius, n))


def tangent_circle(C, R, n):
    """Return the points (n, 3) where camera rays touch the sphere: its apparent outline."""
    C = np.asarray(C, dtype=float)
    d2 = C @ C
    if d2 <= R * R:
        raise ValueError('the optical centre is inside the sphere')
    centre = C * (1 - R * R / d2)
    rho = R * np.sqrt(d2 - R * R) / np.sqrt(d2)
    e1 = np.cross(C, [1.0, 0.0, 0.0] if abs(C[0]) < 0.9 * np.sqrt(d2) else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(C / np.sqrt(d2), e1)
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)[:, None]
    return centre + rho * (np.cos(t) * e1 + np.sin(t) * e2)


# --- cached per camera / background ----------------------------------------------------------

def _camera_key(camera):
    return (camera.K.tobytes(), camera.D.tobytes(), camera.width, camera.height)


@functools.lru_cache(maxsize=4)
def _ray_maps(key):
    """Return each pixel centre's undistorted normalized (x, y) and its derivatives along u, v."""
    K, D, width, height = (np.frombuffer(key[0]).reshape(3, 3), np.frombuffer(key[1]), key[2],
                           key[3])
    camera = Camera(K, D, width, height)
    u, v = np.meshgrid(np.arange(width, dtype=float), np.arange(height, dtype=float))
    xy = camera.pixel_rays(np.stack([u, v], axis=-1))
    if np.any(~np.isfinite(xy)):
        raise ValueError('camera: the distortion cannot be inverted over the whole image')
    dxy_dv, dxy_du = np.gradient(xy, axis=(0, 1))
    return xy, dxy_du, dxy_dv


@functools.lru_cache(maxsize=8)
def _raw_background(key, background):
    """Return the background before the lens: pattern plus texture (float32, height x width)."""
    width, height = key[2], key[3]
    rng = np.random.default_rng(background.seed)
    u, v = np.meshgrid(np.arange(width), np.arange(height))
    low, high = background.low, background.high
    if background.pattern == 'gradient':
        s = (u * np.cos(background.angle) + v * np.sin(background.angle))
        level = low + (high - low) * (s - s.min()) / max(s.max() - s.min(), 1)
    elif background.pattern == 'checker':
        level = low + (high - low) * _checker(width, height, background.square_px,
                                              background.phase_px)
    else:
        white = rng.standard_normal((height, width))
        smooth = cv2.GaussianBlur(white, (0, 0), background.scale_px)
        level = low + (high - low) * np.clip(0.5 + 0.25 * smooth / smooth.std(), 0.0, 1.0)
    texture = rng.standard_normal((height, width))
    if background.texture_scale > 0:
        texture = cv2.GaussianBlur(texture, (0, 0), background.texture_scale)
    texture *= background.texture / max(texture.std(), 1e-12)
    raw = (level + texture).astype(np.float32)
    return _defocus(raw, background.defocus_px) if background.defocus_px > 0 else raw


def _checker(width, height, square, phase, sub=4):
    """Return the fraction of each pixel on the checkerboard's odd squares (4x4 samples)."""
    g = (np.arange(sub) + 0.5) / sub - 0.5
    u = ((np.arange(width)[:, None] + g - phase[0]) // square).astype(int)
    v = ((np.arange(height)[:, None] + g - phase[1]) // square).astype(int)
    return ((v[:, None, :, None] + u[None, :, None, :]) % 2).mean(axis=(2, 3))


def _disc_kernel(radius, sub=8):
    """Return the uniform disc of ``radius`` px as a normalised kernel (8x8 samples a pixel)."""
    m = int(np.ceil(radius + 0.5))
    g = (np.arange(sub) + 0.5) / sub - 0.5
    x = (np.arange(-m, m + 1)[:, None] + g).ravel()
    inside = (x[:, None] ** 2 + x[None, :] ** 2 <= radius * radius).astype(np.float32)
    n = 2 * m + 1
    kernel = inside.reshape(n, sub, n, sub).mean(axis=(1, 3))
    if kernel.sum() == 0:          # a disc smaller than the samples' spacing: a point
        kernel[m, m] = 1.0
    return kernel / kernel.sum()


def _defocus(image, radius):
    return cv2.filter2D(image, -1, _disc_kernel(radius), borderType=cv2.BORDER_REFLECT)


@functools.lru_cache(maxsize=8)
def _blurred_background(key, background, optics):
    return _respond(_blur(_raw_background(key, background), optics), optics.gamma)


@functools.lru_cache(maxsize=4)
def _background_bank(key, background, optics, noise_sigma):
    """
    Return BANK finished frames (uint8) of the blurred background with independent noise.

    A frame starts as one of them; the box around the ball gets fresh noise of its own, so the
    noise only repeats where nothing is measured.
    """
    rng = np.random.default_rng(12345)
    base = _blurred_background(key, background, optics)
    frames = []
    for _ in range(BANK if noise_sigma > 0 else 1):
        frame = base + noise_sigma * rng.standard_normal(base.shape, dtype=np.float32)
        frames.append(_to_uint8(frame))
    return np.stack(frames)


def _kernel_radius(optics):
    blur = int(np.ceil(4 * optics.blur_sigma)) if optics.blur_sigma > 0 else 0
    return blur + (int(np.ceil(optics.defocus_px + 0.5)) if optics.defocus_px > 0 else 0)


def _blur(image, optics):
    out = image
    if optics.blur_sigma > 0:
        k = 2 * int(np.ceil(4 * optics.blur_sigma)) + 1
        out = cv2.GaussianBlur(out, (k, k), optics.blur_sigma, borderType=cv2.BORDER_REFLECT)
    if optics.defocus_px > 0:
        out = _defocus(out, optics.defocus_px)
    return out.copy() if out is image else out


def _respond(image, gamma):
    """Apply the sensor's response: 255 (I / 255)^(1 / gamma), I clipped to 0..255."""
    if gamma == 1.0:
        return image
    return (255.0 * (np.clip(image, 0.0, 255.0) / 255.0) ** (1.0 / gamma)).astype(np.float32)


def _to_uint8(frame):
    np.clip(frame, 0.0, 255.0, out=frame)
    return cv2.convertScaleAbs(frame)   # rounds to nearest; after the clip the abs() is harmless


# --- the sphere ------------------------------------------------------------------------------

def _in_front(C, R):
    """Return whether the whole tangent cone is in front of the camera (outline: an ellipse)."""
    d = np.linalg.norm(C)
    return d > R and np.arccos(np.clip(C[2] / d, -1, 1)) + np.arcsin(R / d) < np.deg2rad(80)


def _sphere_box(camera, C, R, margin=2):
    """Box the outline + ``margin`` in pixels (u0, u1, v0, v1), end-exclusive; None if unseen."""
    if not _in_front(C, R):
        return None
    outline = sphere_outline(camera, C, R, 96)
    if not np.all(np.isfinite(outline)):
        return None
    lo = np.floor(outline.min(axis=0)).astype(int) - 2 - margin
    hi = np.ceil(outline.max(axis=0)).astype(int) + 3 + margin
    u0, v0 = max(lo[0], 0), max(lo[1], 0)
    u1, v1 = min(hi[0], camera.width), min(hi[1], camera.height)
    if u0 >= u1 or v0 >= v1:
        return None
    # a ball just past the border leaves a box one pixel thick: grown inward to two, since the
    # outline's distance takes differences across the box
    u0, v0 = min(u0, max(u1 - 2, 0)), min(v0, max(v1 - 2, 0))
    u1, v1 = max(u1, min(u0 + 2, camera.width)), max(v1, min(v0 + 2, camera.height))
    return u0, u1, v0, v1


def _shade(x, y, C, R, lighting):
    """
    Return the sphere's brightness along the rays (x, y, 1); a ray that misses shades the limb.

    The ray meets the sphere at t d (d the unit ray, t the nearer root); the normal there is
    (t d - C) / R. Ambient + diffuse max(n.l, 0) + specular max(n.h, 0)^shininess, with
    h the half vector between the light and the direction back to the camera (Blinn-Phong).
    """
    inv = 1.0 / np.sqrt(x * x + y * y + 1.0)
    dx, dy, dz = x * inv, y * inv, inv
    b = dx * C[0] + dy * C[1] + dz * C[2]
    t = b - np.sqrt(np.maximum(b * b - (C @ C - R * R), 0.0))
    nx, ny, nz = t * dx - C[0], t * dy - C[1], t * dz - C[2]
    n_inv = 1.0 / np.sqrt(nx * nx + ny * ny + nz * nz)
    light = np.asarray(lighting.direction, dtype=float)
    lx, ly, lz = light / np.linalg.norm(light)
    lambert = np.maximum((nx * lx + ny * ly + nz * lz) * n_inv, 0.0)
    hx, hy, hz = lx - dx, ly - dy, lz - dz
    h_inv = 1.0 / np.sqrt(hx * hx + hy * hy + hz * hz)
    n_dot_h = np.maximum((nx * hx + ny * hy + nz * hz) * n_inv * h_inv, 0.0)
    highlight = np.where(lambert > 0, n_dot_h ** lighting.shininess, 0.0)
    return lighting.ambient + lighting.diffuse * lambert + lighting.specular * highlight


def _subsample_offsets(n=SUPERSAMPLE):
    """Return n x n offsets in a pixel (-0.5..0.5), the grid turned slightly so no edge aligns."""
    g = (np.arange(n) + 0.5) / n - 0.5
    du, dv = np.meshgrid(g, g)
    a = np.arctan(1.0 / n)
    off = np.stack([du.ravel() * np.cos(a) - dv.ravel() * np.sin(a),
                    du.ravel() * np.sin(a) + dv.ravel() * np.cos(a)], -1)
    return (off + 0.5) % 1.0 - 0.5


# rays of a sub-pixel near the outline, and of its shading (a centred grid, 4 x 4 a pixel: a
# subset of the coverage's would sit off centre, and shift the steep limb's shading by as much),
# in sub-pixels; the sub-pixels' centres in a pixel, row by row
_OFFSETS = _subsample_offsets()
_SHADE_OFFSETS = _subsample_offsets(SUPERSAMPLE // (2 * FINE))
_SUB = np.stack(np.meshgrid(*2 * [(np.arange(FINE) + 0.5) / FINE - 0.5]), -1).reshape(-1, 2)


def _rays(x, y, dxy_du, dxy_dv, mask, offsets):
    """Return the rays (x, y: (n, k)) at ``offsets`` (k, 2: px) in the pixels of ``mask``."""
    du, dv = offsets[:, 0], offsets[:, 1]
    xu, xv = dxy_du[mask], dxy_dv[mask]
    return (x[mask][:, None] + du * xu[:, 0:1] + dv * xv[:, 0:1],
            y[mask][:, None] + du * xu[:, 1:2] + dv * xv[:, 1:2])


def _cone_value(x, y, C, cos2_beta):
    """Return (d.C)^2 - cos^2(beta) |d|^2 |C|^2 for rays d = (x, y, 1); > 0 in the tangent cone."""
    dot = x * C[0] + y * C[1] + C[2]
    return np.where(dot > 0, dot * dot - cos2_beta * (C @ C) * (x * x + y * y + 1.0), -1.0)


def _outline_distance(x, y, dxy_du, dxy_dv, C, cos2_beta):
    """
    Return the cone value q and the signed distance to the outline, -q / |grad q| (outside > 0).

    The gradient is q's along the pixel steps ``dxy_du``, ``dxy_dv`` (..., 2): the distance is
    in those steps.
    """
    q = _cone_value(x, y, C, cos2_beta)
    k = cos2_beta * (C @ C)
    dot = x * C[0] + y * C[1] + C[2]
    q_x, q_y = 2.0 * (dot * C[0] - k * x), 2.0 * (dot * C[1] - k * y)
    q_u = q_x * dxy_du[..., 0] + q_y * dxy_du[..., 1]
    q_v = q_x * dxy_dv[..., 0] + q_y * dxy_dv[..., 1]
    return q, -q / np.maximum(np.hypot(q_u, q_v), 1e-300)


def _sub_pixels(x, y, dxy_du, dxy_dv, C, R, lighting):
    """
    Return the fraction of each sub-pixel the sphere covers, and its mean brightness there.

    (x, y) (n,): the sub-pixels' centre rays, ``dxy_du``, ``dxy_dv`` (n, 2) their steps. Those
    the outline crosses are sampled by SUPERSAMPLE^2 rays; a pixel integrates the light over its
    area, and near the limb the shading bends as a square root (its value at a pixel's centre is
    0.4 grey levels brighter than the pixel's mean 1.5 px inside a frontally lit ball): the
    shading is averaged over rays, and over the covered ones on the outline.
    """
    cos2_beta = 1.0 - R * R / (C @ C)
    q, dist = _outline_distance(x, y, dxy_du, dxy_dv, C, cos2_beta)
    cover = (q > 0).astype(np.float32)
    edge = np.abs(dist) < 0.8          # a sub-pixel's corner is 0.71 of its side from its centre
    sx, sy = _rays(x, y, dxy_du, dxy_dv, edge, _OFFSETS)
    cover[edge] = np.mean(_cone_value(sx, sy, C, cos2_beta) > 0, axis=1)
    lit = cover > 0
    sx, sy = _rays(x, y, dxy_du, dxy_dv, lit, _SHADE_OFFSETS)
    hit = _cone_value(sx, sy, C, cos2_beta) > 0
    count = hit.sum(axis=1)
    shade = np.zeros(cover.shape, np.float32)
    shade[lit] = (np.sum(_shade(sx, sy, C, R, lighting) * hit, axis=1)
                  / np.maximum(count, 1))
    # covered only between the shading rays: the limb at the centre
    none = np.flatnonzero(lit)[count == 0]
    shade[none] = _shade(x[none], y[none], C, R, lighting)
    return cover, shade


def _grow(box, m, camera):
    u0, u1, v0, v1 = box
    return max(u0 - m, 0), min(u1 + m, camera.width), max(v0 - m, 0), min(v1 + m, camera.height)


def _on_sub_pixels(a):
    """Return the pixels of ``a`` (h, w) each repeated over its FINE x FINE sub-pixels."""
    return np.repeat(np.repeat(a, FINE, axis=0), FINE, axis=1)


def _ball_light(camera, C, R, lighting, background, box):
    """
    Return what the ball changes in the scene on FINE x FINE sub-pixels of its box (float32).

    Pixels the outline crosses or within LIMB_BAND_PX inside it are drawn sub-pixel by sub-pixel;
    deeper ones (smooth shading, beyond the blur's reach of the outline) by their centre's value.
    """
    n = FINE
    u0, u1, v0, v1 = box
    xy, dxy_du, dxy_dv = (m[v0:v1, u0:u1] for m in _ray_maps(_camera_key(camera)))
    x, y = xy[..., 0], xy[..., 1]
    raw = _raw_background(_camera_key(camera), background)[v0:v1, u0:u1]
    q, dist = _outline_distance(x, y, dxy_du, dxy_dv, C, 1.0 - R * R / (C @ C))
    band = (dist < 0.75) & (dist > -LIMB_BAND_PX - 0.75)
    deep = (q > 0) & ~band
    delta = np.zeros(raw.shape, np.float32)
    delta[deep] = _shade(x[deep], y[deep], C, R, lighting) - raw[deep]
    fine = _on_sub_pixels(delta)
    sx, sy = _rays(x, y, dxy_du, dxy_dv, band, _SUB)
    steps_u, steps_v = (np.repeat(d[band] / n, len(_SUB), axis=0) for d in (dxy_du, dxy_dv))
    cover, shade = _sub_pixels(sx.ravel(), sy.ravel(), steps_u, steps_v, C, R, lighting)
    rows, cols = np.nonzero(band)
    sub = np.arange(len(_SUB))
    fine[rows[:, None] * n + sub // n, cols[:, None] * n + sub % n] = (
        cover * (shade - np.repeat(raw[band], len(_SUB)))).reshape(-1, len(_SUB))
    return fine


def _lens(fine, optics):
    """
    Return the lens's image on FINE x FINE sub-pixels (float32) integrated over each pixel.

    The blur and the defocus disc are applied FINE times wider on the sub-pixels; the
    sub-pixels' own area (variance 1 / (12 FINE^2) px^2) is taken out of the Gaussian's, so that
    ``blur_sigma`` keeps its meaning, the blur beyond the pixel's area.
    """
    n = FINE
    sigma = np.sqrt(max(optics.blur_sigma ** 2 - 1.0 / (12 * n * n), 0.0))
    fine = _blur(fine, Optics(n * sigma, n * optics.defocus_px, 1.0))
    return fine.reshape(fine.shape[0] // n, n, fine.shape[1] // n, n).mean(axis=(1, 3))


class _Still:
    """
    The last frame's noise-free patch, kept for the next if the ball has not moved.

    Within a nanometre, a few millionths of a pixel: then a frame needs only fresh noise. The
    emulated rests of robotenis_validation draw one position for every frame of a rest. The live
    simulator's robot never holds the ball that still: its servo on noisy resolvers moves it by
    a micrometre or more between frames at rest (98.7 % of 8,000 frames of a demo session).
    """

    TOLERANCE = 1e-9    # m

    def __init__(self):
        self.key, self.C, self.patch = None, None, None

    def get(self, key, C):
        same = (key == self.key and np.max(np.abs(C - self.C)) <= self.TOLERANCE)
        return self.patch if same else None

    def put(self, key, C, patch):
        self.key, self.C, self.patch = key, C.copy(), patch


_STILL = _Still()


def _draw_sphere(frame, camera, C, R, lighting, background, optics, noise_sigma, rng, box):
    """
    Render the ball in its box, blur, add fresh noise and write the result into the frame.

    A pixel integrates the lens's blurred image over its area. The ball and what lies behind it
    are drawn on FINE x FINE sub-pixels, blurred there and each pixel's sub-pixels averaged
    (``_lens``): a Gaussian as narrow as the lens's (0.8 px) sampled once a pixel, applied to
    pixels that already integrate a sharp outline, moves the blurred outline by a few
    thousandths of a pixel with its phase on the grid (0.015-0.02 mm of depth at 0.2-0.4 m on
    noise-free renders of a flat disc), which no camera does. With m the blur's radius, the
    blurred ball reaches m beyond its box, and blurring that needs m more of the background;
    beyond the m, the frame's cached background, blurred a pixel at a time, which differs from
    the sub-pixels' by up to 0.2 grey levels on the default gradient and 1.3 on a checkerboard,
    6 px or more outside the outline, beyond any fit's annulus. Fresh noise goes over the whole
    box grown by 2 m (the frame's own repeats from frame to frame): given over the inner box
    alone, a ring the detector reads carried the same noise in every frame, and the first 60
    scenes of ``bench vision`` read a depth bias of 0.229 % of range against 0.170 %.
    """
    m = _kernel_radius(optics)
    near, far = _grow(box, m, camera), _grow(box, 2 * m, camera)
    camera_key = _camera_key(camera)
    key = (camera_key, R, lighting, background, optics, box)
    out = _STILL.get(key, C)
    if out is None:
        raw = _raw_background(camera_key, background)[far[2]:far[3], far[0]:far[1]]
        fine = _on_sub_pixels(raw)
        top, left = (box[2] - far[2]) * FINE, (box[0] - far[0]) * FINE
        ball = _ball_light(camera, C, R, lighting, background, box)
        fine[top:top + ball.shape[0], left:left + ball.shape[1]] += ball
        inner = (slice(near[2] - far[2], near[3] - far[2]),
                 slice(near[0] - far[0], near[1] - far[0]))
        out = _blurred_background(camera_key, background, optics)[
            far[2]:far[3], far[0]:far[1]].copy()
        out[inner] = _respond(_lens(fine, optics)[inner], optics.gamma)
        _STILL.put(key, C, out)
    # a new array either way: the kept patch must not be clipped in place
    out = out + (noise_sigma * rng.standard_normal(out.shape, dtype=np.float32)
                 if noise_sigma > 0 else 0.0)
    frame[far[2]:far[3], far[0]:far[1]] = _to_uint8(out)


def sphere_in_optical(P, ball, camera_rotation, camera_translation):
    """
    Return the ball centre in the optical frame, from effector position P and ball (base frame, m).

    The optical centre is P + camera_translation (the effector frame is parallel to the base
    frame); the columns of camera_rotation are the optical axes in that frame.
    """
    return np.asarray(camera_rotation, dtype=float).T @ (
        np.asarray(ball, dtype=float) - np.asarray(P, dtype=float)
        - np.asarray(camera_translation, dtype=float))


class FrameClock:
    """
    Which simulator truth samples the hand camera exposes: the first at or after each k / rate.

    Samples come every few milliseconds (sim_motors' truth_decimation), so frames fall on them, 8
    or 12 ms apart at 120 Hz with 4 ms samples, 120 per second on average. The hand camera ticking
    on those samples and sim_motors' visual lockstep each keep one, and agree frame for frame.
    """

    TOLERANCE = 1e-6    # s: stamps travel in whole nanoseconds and times add up in floating point

    def __init__(self, rate):
        if not rate > 0:
            raise ValueError(f'frame rate must be positive, got {rate}')
        self.rate, self.next = float(rate), 0.0

    def due(self, t):
        """Return True if the sample at t (s) is a frame; the next deadline is then past t."""
        if t < self.next - self.TOLERANCE:
            return False
        self.next = (np.floor((t + self.TOLERANCE) * self.rate) + 1) / self.rate
        return True


def render_circles(camera, centres, normals, radii, rng, plate=230.0, ink=25.0, blur_sigma=0.8,
                   noise_sigma=2.0):
    """
    Render a mono8 image of filled discs (an ISO 9283 plate of black circles) in the optical frame.

    centres (k, 3) and unit normals (k, 3) of the discs (m), radii (k,) (m). The plate fills the
    view at brightness ``plate``; a disc is ``ink``. A pixel ray d meets a disc's plane at t d with
    t = (n.c) / (n.d), inside it when |t d - c| < r; pixels within a pixel of a rim are
    supersampled like the sphere's outline. Then blur, noise and 8 bits, over the whole frame.
    """
    centres, normals = (np.atleast_2d(np.asarray(centres, float)),
                        np.atleast_2d(np.asarray(normals, float)))
    radii = np.atleast_1d(np.asarray(radii, float))
    if (centres.shape[1:] != (3,) or normals.shape != centres.shape
            or radii.shape != (len(centres),)):
        raise ValueError('centres (k, 3), normals (k, 3) and radii (k,) must agree, '
                         f'got {centres.shape}, {normals.shape}, {radii.shape}')
    if np.any(radii <= 0) or np.any(np.abs(np.linalg.norm(normals, axis=1) - 1) > 1e-6):
        raise ValueError('radii must be positive and normals unit vectors')
    cover = np.zeros((camera.height, camera.width), np.float32)
    for c, n, r in zip(centres, normals, radii):
        box = _disc_box(camera, c, n, r)
        if box is not None:
            u0, u1, v0, v1 = box
            cover[v0:v1, u0:u1] = np.maximum(cover[v0:v1, u0:u1],
                                             _disc_coverage(camera, c, n, r, box))
    image = _blur(plate + (ink - plate) * cover, Optics(float(blur_sigma), 0.0, 1.0))
    if noise_sigma > 0:
        image += noise_sigma * rng.standard_normal(image.shape, dtype=np.float32)
    return _to_uint8(image)


def _disc_rim(c, n, r, k=64):
    a = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(n, a)
    t = np.linspace(0, 2 * np.pi, k, endpoint=False)[:, None]
    return c + r * (np.cos(t) * a + np.sin(t) * b)


def _disc_box(camera, c, n, r):
    rim = _disc_rim(c, n, r)
    if np.any(rim[:, 2] <= 0.01) or abs(n @ c) < 1e-9:      # behind the camera, or seen edge-on
        return None
    uv = camera.project(rim)
    lo, hi = np.floor(uv.min(axis=0)).astype(int) - 2, np.ceil(uv.max(axis=0)).astype(int) + 3
    u0, v0, u1, v1 = (max(lo[0], 0), max(lo[1], 0), min(hi[0], camera.width),
                      min(hi[1], camera.height))
    return (u0, u1, v0, v1) if u0 < u1 and v0 < v1 else None


def _disc_value(x, y, c, n, r):
    """Return r^2 - |t d - c|^2 for rays d = (x, y, 1): positive inside the disc."""
    t = (n @ c) / (n[0] * x + n[1] * y + n[2])
    return r * r - ((t * x - c[0]) ** 2 + (t * y - c[1]) ** 2 + (t - c[2]) ** 2)


def _disc_coverage(camera, c, n, r, box):
    u0, u1, v0, v1 = box
    xy, dxy_du, dxy_dv = (m[v0:v1, u0:u1] for m in _ray_maps(_camera_key(camera)))
    x, y = xy[..., 0], xy[..., 1]
    q = _disc_value(x, y, c, n, r)
    gq_v, gq_u = np.gradient(q)
    edge = np.abs(q / np.maximum(np.hypot(gq_u, gq_v), 1e-300)) < 0.8
    cover = (q > 0).astype(np.float32)
    sx, sy = _rays(x, y, dxy_du, dxy_dv, edge, _OFFSETS)
    cover[edge] = np.mean(_disc_value(sx, sy, c, n, r) > 0, axis=1)
    return cover
