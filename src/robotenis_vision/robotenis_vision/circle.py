"""
A dark circle of known diameter on a bright plate, measured in the optical frame.

The plate faces the camera: the circle is the ISO 9283 control element of the calibration paper's
section 6.1.

A disc parallel to the image plane images as a circle whose centre is the image of the disc's
centre (no perspective shift). Both come from the disc's ink coverage, which blur and noise do not
bias: with the plate level p (median of a ring around the blob) and the ink level k (median inside
it), each pixel's coverage is w = (p - I) / (p - k) clipped to [0, 1]; the area is sum w (pixels),
the centre the w-weighted centroid. Depth z = f D / d with d = 2 sqrt(area / pi); the centre is
undistorted with the plumb_bob model and back-projected at that depth.
"""
import cv2
import numpy as np

MIN_AREA_PX = 50


class CircleError(ValueError):
    """No circle could be measured; the message says why."""


def _blobs(image):
    """Find the connected dark regions of ``image``: (label image, stats, centroids) of OpenCV."""
    low, high = np.percentile(image, (1, 90))
    if high - low < 20:
        raise CircleError(f'no contrast in the image (levels {low:.0f}-{high:.0f})')
    mask = (image < 0.5 * (low + high)).astype(np.uint8)
    _, labels, stats, centroids = cv2.connectedComponentsWithStats(mask)
    return labels, stats, centroids


def _central_blob(stats, centroids, shape, principal_point):
    """Index of the whole (not cut by the border) blob nearest the principal point."""
    h, w = shape
    best, best_d = None, np.inf
    for i in range(1, len(stats)):
        x, y, bw, bh, area = stats[i]
        if area < MIN_AREA_PX or x <= 0 or y <= 0 or x + bw >= w or y + bh >= h:
            continue
        d = np.hypot(*(centroids[i] - principal_point))
        if d < best_d:
            best, best_d = i, d
    if best is None:
        raise CircleError('no whole dark circle in the image')
    return best


def measure_circle(image, camera, diameter, pad=4):
    """
    Centre (3,) of a dark circle of ``diameter`` (m) in the optical frame (m), from a mono8 image.

    The circle is the whole dark blob nearest the principal point; CircleError when there is none.
    """
    image = np.asarray(image, dtype=np.float64)
    labels, stats, centroids = _blobs(image)
    cx, cy = camera.K[0, 2], camera.K[1, 2]
    i = _central_blob(stats, centroids, image.shape, np.array([cx, cy]))
    x, y, bw, bh, _ = stats[i]
    u0, v0 = max(x - pad, 0), max(y - pad, 0)
    u1, v1 = min(x + bw + pad, image.shape[1]), min(y + bh + pad, image.shape[0])
    window = image[v0:v1, u0:u1]
    inside = labels[v0:v1, u0:u1] == i
    ring = np.ones_like(inside)
    ring[pad:-pad, pad:-pad] = False
    plate, ink = np.median(window[ring & ~inside]), np.median(window[inside])
    w = np.clip((plate - window) / (plate - ink), 0.0, 1.0)
    w[(labels[v0:v1, u0:u1] > 0) & ~inside] = 0.0     # another circle's ink in the window
    area = w.sum()
    vv, uu = np.mgrid[v0:v1, u0:u1]
    centre = np.array([(w * uu).sum(), (w * vv).sum()]) / area
    f = 0.5 * (camera.K[0, 0] + camera.K[1, 1])
    z = f * diameter / (2.0 * np.sqrt(area / np.pi))
    xy = camera.pixel_rays(centre)
    return np.array([xy[0] * z, xy[1] * z, z])
