"""
The plain baseline: threshold, OpenCV's fitEllipse, back-project the centre, depth from the size.

Near the ball (the same rough circle the other methods start from), pixels farther from the local
background level (the median of the region's border) than a threshold (3 robust sigma of the
border, at least 15 grey levels) are the ball, bright side and dark side alike (a plain Otsu
threshold splits the dark side from everything else); the outer contour of the blob at the ball's
place is fitted with cv2.fitEllipse; the ellipse centre is undistorted and back-projected; the
distance along that ray follows from the mean semi-axis r (px) as Z = f R / r. It ignores the
shading (a darker side is cut off), the ellipse's offset from the projected centre and the blur:
what the other methods fix.
"""
import cv2
import numpy as np

from robotenis_vision import edges
from robotenis_vision.detection import Detection, DetectionError, RANGE


def detect(img_f32, camera, R):
    """Measure a detector.Detection by the baseline; DetectionError if no blob is found."""
    try:
        centre, r = edges.rough_circle(img_f32, camera.fx * R / RANGE[1], camera.fx * R / RANGE[0])
    except edges.EdgeError as e:
        raise DetectionError(str(e)) from None
    contour, offset = _blob(img_f32, centre, r)
    if contour is None or len(contour) < 5:
        raise DetectionError('baseline: no thresholded blob at the ball')
    (u, v), (d1, d2), _ = cv2.fitEllipse(contour.astype(np.float32))
    uv = np.array([u, v]) + offset
    r_px = 0.25 * (d1 + d2)
    x, y = camera.pixel_rays(uv)
    Z = camera.fx * R / r_px
    position = Z * np.array([x, y, 1.0])
    # Quantisation of a pixel contour: about 0.3 px per point, averaged over the contour.
    s = 0.3 / np.sqrt(len(contour))
    cov = np.diag([(Z / camera.fx * s) ** 2, (Z / camera.fy * s) ** 2, (Z / r_px * s) ** 2])
    # ideal pixels, as the others
    edge = camera.undistort_pixels(contour[:, 0, :].astype(float) + offset)
    return Detection(position, cov, edge, float('nan'), 'baseline')


def _blob(img_f32, centre, r):
    """
    Outer contour (in ROI coordinates) of the thresholded blob under the rough centre.

    Returned with the ROI offset.
    """
    h, w = img_f32.shape
    half = int(np.ceil(1.6 * r)) + 4
    u0, v0 = max(int(centre[0]) - half, 0), max(int(centre[1]) - half, 0)
    u1, v1 = min(int(centre[0]) + half + 1, w), min(int(centre[1]) + half + 1, h)
    roi = img_f32[v0:v1, u0:u1]
    border = np.concatenate([roi[0], roi[-1], roi[1:-1, 0], roi[1:-1, -1]])
    level = np.median(border)
    threshold = max(15.0, 3 * 1.4826 * np.median(np.abs(border - level)))
    mask = (np.abs(roi - level) > threshold).astype(np.uint8)
    mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, np.ones((3, 3), np.uint8))
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    if not contours:
        return None, None
    local = (float(centre[0] - u0), float(centre[1] - v0))
    inside = [c for c in contours if cv2.pointPolygonTest(c, local, False) >= 0]
    best = max(inside or contours, key=cv2.contourArea)
    return best, np.array([u0, v0], dtype=float)
