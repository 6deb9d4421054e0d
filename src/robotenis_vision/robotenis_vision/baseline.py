"""
The strong plain baseline: a midpoint threshold, the largest round contour, OpenCV's fitEllipse.

What a careful user of OpenCV would write (issue 13's baseline), given where the ball is (the same
search as the other methods: robotenis_vision.search): near the ball, the image, lightly
smoothed, is thresholded midway between the background's level (the median of a ring 1.3-1.7
radii out) and the ball's (the median distance from it within 0.6 of its radius), on both sides
of the background's level: a ball lit from the side is brighter than its background on one side
and darker on the other (one level would cut it in half), and the band where it matches its
background splits its blob (the convex hull of the blobs centred within its radius closes it).
That contour, if round (4 pi area / perimeter^2 of at least MIN_ROUNDNESS), is fitted with
cv2.fitEllipse. The ellipse's centre, undistorted, is the direction of the ball; the tangent
cone's half-angle b follows from the minor semi-axis (the one across the radial direction: tan b
= minor cos(theta) / f at the angle theta off the optical axis), and the range from the radius,
R / sin(b) (the contour runs through the centres of the blob's boundary pixels, half a pixel
inside its edge: added back). It ignores what the other methods model: the shading, the blur, and
the offset between the ellipse's centre and the image of the ball's centre.
"""
import cv2
import numpy as np

from robotenis_vision.detection import Detection, DetectionError

MIN_ROUNDNESS = 0.7
MIN_AREA_PX = 30


def _roi_contour(img_f32, centre, r):
    """Return the round contour of the ball's blobs of the midpoint threshold (image px)."""
    h, w = img_f32.shape
    half = int(np.ceil(2.0 * r)) + 4
    u0, v0 = max(int(centre[0]) - half, 0), max(int(centre[1]) - half, 0)
    u1, v1 = min(int(centre[0]) + half + 1, w), min(int(centre[1]) + half + 1, h)
    if u1 - u0 < half or v1 - v0 < half:
        raise DetectionError('baseline: the ball is not in the image')
    roi = cv2.GaussianBlur(np.ascontiguousarray(img_f32[v0:v1, u0:u1]), (0, 0), 1.0)
    vv, uu = np.mgrid[v0:v1, u0:u1]
    dist = np.hypot(uu - centre[0], vv - centre[1]) / r
    if not np.any(dist > 1.3):
        raise DetectionError('baseline: no background around the ball in the image')
    ring = np.median(roi[(dist > 1.3) & (dist < 1.7)])
    contrast = np.abs(roi - ring)
    step = np.median(contrast[dist < 0.6])
    if step < 5:
        raise DetectionError('baseline: the ball does not stand out of its background')
    mask = contrast > 0.5 * step
    contours, _ = cv2.findContours(mask.astype(np.uint8), cv2.RETR_EXTERNAL,
                                   cv2.CHAIN_APPROX_NONE)
    pieces = [cnt for cnt in contours if cv2.contourArea(cnt) >= MIN_AREA_PX
              and np.hypot(*(cnt[:, 0, :].mean(axis=0) + [u0, v0] - centre)) < r]
    if not pieces:
        raise DetectionError('baseline: no thresholded blob at the ball')
    filled = np.zeros(mask.shape, np.uint8)
    cv2.fillConvexPoly(filled, cv2.convexHull(np.vstack(pieces)), 1)
    best = max(cv2.findContours(filled, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)[0],
               key=cv2.contourArea)
    area, perimeter = cv2.contourArea(best), cv2.arcLength(best, True)
    if len(best) < 5 or perimeter <= 0 or 4 * np.pi * area / perimeter ** 2 < MIN_ROUNDNESS:
        raise DetectionError('baseline: no round thresholded blob at the ball')
    x, y, bw, bh = cv2.boundingRect(best)
    if u0 + x <= 0 or v0 + y <= 0 or u0 + x + bw >= w or v0 + y + bh >= h:
        raise DetectionError('baseline: the blob touches the image border')
    return best[:, 0, :].astype(float) + [u0, v0]


def detect(img_f32, camera, R, centre, r):
    """
    Measure a detection.Detection by the baseline near the ball at pixel ``centre``, radius r px.

    DetectionError if no round blob is found there.
    """
    contour = _roi_contour(img_f32, centre, r)
    (u, v), axes, _ = cv2.fitEllipse(contour.astype(np.float32))
    # the contour runs through the centres of the blob's boundary pixels: half a pixel inside
    minor = 0.5 * min(axes) + 0.5
    ray = np.append(camera.pixel_rays(np.array([u, v])), 1.0)
    ray /= np.linalg.norm(ray)
    half_angle = np.arctan(minor * ray[2] / camera.fx)
    position = R / np.sin(half_angle) * ray
    # quantisation of a pixel contour: about 0.3 px per point, averaged over the contour
    s = 0.3 / np.sqrt(len(contour))
    Z = position[2]
    cov = np.diag([(Z / camera.fx * s) ** 2, (Z / camera.fy * s) ** 2, (Z / minor * s) ** 2])
    edge = camera.undistort_pixels(contour)
    return Detection(position, cov, edge, float('nan'), 'baseline')
