"""
An independent renderer for the tests: the sphere's outline projected by OpenCV, filled at 16x.

The outline is the circle where rays from the optical centre touch the sphere; OpenCV's
projectPoints (its own plumb_bob implementation) gives its pixels; cv2.fillPoly draws the polygon
(2,000 vertices) at 32 times the resolution with sub-pixel vertices; INTER_AREA brings it back
(exact box filter). fillPoly fills every fine pixel the outline touches, half a fine pixel beyond
the exact edge on average, so the vertices are first moved inward by half a fine pixel; then a
Gaussian blur and Gaussian noise. The ball is uniformly bright, the background flat: what the
camera_model renderer adds (shading, texture, distortion maps) is absent, so the two share nothing.
``on_background`` puts the ball over a background image instead: a checkerboard, a texture.
"""
import cv2
import numpy as np

SCALE = 32
SHIFT = 4                       # fillPoly fixed-point bits: 1/16 of a fine pixel


def outline_points(C, R, n=2000):
    """Points (n, 3) where rays from the origin touch sphere (C, R), via two tangent vectors."""
    C = np.asarray(C, dtype=float)
    d = np.linalg.norm(C)
    u = C / d
    a = np.cross(u, [0.0, 0.0, 1.0] if abs(u[2]) < 0.9 else [1.0, 0.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(u, a)
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)[:, None]
    foot = d - R * R / d          # distance of the touching circle's plane from the origin
    radius = R * np.sqrt(d * d - R * R) / d
    return foot * u + radius * (np.cos(t) * a + np.sin(t) * b)


def project(camera, X):
    uv, _ = cv2.projectPoints(np.asarray(X, dtype=np.float64).reshape(-1, 1, 3), np.zeros(3),
                              np.zeros(3), camera.K, camera.D)
    return uv.reshape(-1, 2)


def render(camera, C, R, rng=None, ball=200.0, background=80.0, blur_sigma=0.8, noise_sigma=0.0):
    """uint8 image (height, width) of a uniform ball on a flat background."""
    uv = project(camera, outline_points(C, R))
    lo = np.floor(uv.min(axis=0)).astype(int) - 8
    hi = np.ceil(uv.max(axis=0)).astype(int) + 8
    lo, hi = np.maximum(lo, 0), np.minimum(hi, [camera.width, camera.height])
    w, h = hi - lo
    # pixel (i, j) centre at i; in the fine box, pixel centres at
    # SCALE * (i - lo) + (SCALE - 1) / 2
    fine = (uv - lo + 0.5) * SCALE - 0.5
    tangent = np.roll(fine, -1, axis=0) - np.roll(fine, 1, axis=0)
    inward = (np.stack([-tangent[:, 1], tangent[:, 0]], axis=1)
              / np.linalg.norm(tangent, axis=1)[:, None])
    if np.mean(np.sum(inward * (fine.mean(axis=0) - fine), axis=1)) < 0:
        inward = -inward
    fine = fine + 0.5 * inward
    mask = np.zeros((h * SCALE, w * SCALE), np.uint8)
    cv2.fillPoly(mask, [np.round(fine * (1 << SHIFT)).astype(np.int32)], 255, lineType=cv2.LINE_8,
                 shift=SHIFT)
    cover = cv2.resize(mask.astype(np.float32) / 255.0, (w, h), interpolation=cv2.INTER_AREA)
    image = np.full((camera.height, camera.width), background, np.float32)
    image[lo[1]:hi[1], lo[0]:hi[0]] = background + (ball - background) * cover
    if blur_sigma > 0:
        image = cv2.GaussianBlur(image, (0, 0), blur_sigma)
    if noise_sigma > 0:
        image += noise_sigma * rng.standard_normal(image.shape).astype(np.float32)
    return np.clip(np.rint(image), 0, 255).astype(np.uint8)


def on_background(camera, C, R, background, rng, ball=130.0, blur_sigma=0.8, noise_sigma=2.0):
    """uint8 image of a uniform ball over ``background`` (float image, grey levels), then blur."""
    cover = render(camera, C, R, ball=255.0, background=0.0, blur_sigma=0.0) / 255.0
    image = cv2.GaussianBlur(background * (1 - cover) + ball * cover, (0, 0), blur_sigma)
    image += noise_sigma * rng.standard_normal(image.shape)
    return np.clip(np.rint(image), 0, 255).astype(np.uint8)


def checkerboard(camera, square, low=40.0, high=210.0):
    """Float image of a checkerboard of ``square`` px squares."""
    v, u = np.mgrid[0:camera.height, 0:camera.width]
    return np.where((u // square + v // square) % 2 == 0, low, high).astype(float)
