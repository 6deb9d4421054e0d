"""
When the ball stands still in the image: the fast method corrected by the accurate one.

The sphere_detector node measures every frame with its fast method (the conic method seeded by
the last frame). Once the ball's outline has moved less than ``motion_px`` between frames for
``frames`` frames in a row (the robot at rest: RestSwitch), the frames are summed, and the
accurate method (the model fit) runs on their mean image on the first frame and each time their
number reaches a power of two from FIRST_MEAN (8) on: log2(n) - 1 fits for n >= 8 frames at rest
instead of n (MeanCorrection). Each frame k then gives

    p_k = f_k + (a(M_j) - mean(f_1 .. f_j))

f_k its fast detection, a(M_j) the accurate method on the mean image M_j of the j frames summed
at the last fit, mean(f_1 .. f_j) their fast detections' mean: the accurate method's position of
the ball at rest, with the frame's own noise and any slow drift from the fast one. The fast
detections' mean, not the fast method on M_j, is subtracted: the fast method's own
noise-dependent bias cancels in f_k - mean(f) (the conic on M_j was up to 0.06 mm off in depth at
0.38 m). Averaged over a rest on the hand camera's own scene, p_k had the mean and about the
spread of a mean of per-frame fits (four balls at 0.25-0.40 m, offline) for a tenth of the fits:
each fit starts from the last, so the noise levels of the first, one-frame fit weight them all; on
scenes the model misfits the two differ (benchmarks/vision.py, section 5 "at rest"). (A
fit of a mean image from a cold start is weighted by its own, lower, noise and lands near the fit
of a noise-free render, from which the per-frame fits' mean was 0.06-0.14 mm farther in depth at
those poses.) RestCorrection is the sphere_detector node's step per frame. A mean image is only of
one ball position: if the fast detection leaves the summed frames' mean by more than ``motion_px``,
the sum starts again from that frame, and its first fit starts from the fast detection. With a
camera response gamma != 1 the mean of encoded grey levels is fitted, a second-order error of
(noise / level)^2, negligible at the noise of a camera.

The outline, not only its centre, must stand still (``outline_px``: its centre and apparent
radius): a ball moving along the line of sight keeps its centre while its radius changes. Judged
by the centre alone, the last rest of a demo session (a move toward the camera at 0.37 m) was
taken as at rest in mid-move: its mean images mixed the ball at several depths, and its fits read
10.4 mm off in depth on the first frame (seeded by the last fit, 40 mm away), then 3.5, 2.1 and
1.2 mm on 8, 16 and 32 frames; the rest came out 1.2 mm off.

The fits at 2 and 4 frames are skipped: they would only correct frames 2-7 of a rest, which a
session lets go by while it settles (the demo's 0.3 s settle is 36 frames at 120 Hz). On the 16
rests of benchmarks/vision.py section 5 (36 frames settling, 30 averaged) the averages came out
the same to 0.003 mm with 4 fits a rest instead of 6 (149 against 230 ms of CPU); fits at powers
of four (1, 4, 16) instead moved a rest at 0.45 m by 0.32 mm: the last 30 frames then take their
correction from a 16-frame mean instead of a 32-frame one, and depth noise grows as the range
squared.
"""
from dataclasses import replace

import numpy as np
from robotenis_vision.detection import DetectionError

FIRST_MEAN = 8                  # frames at rest of the first fit on a mean image after the first
MOTION_PX, STILL_FRAMES = 0.3, 3    # the node's defaults: rest_motion_px, rest_frames


def outline_px(camera, position, radius):
    """Return the outline in the image of the sphere at ``position`` (m): (u, v, r) px."""
    return np.append(camera.project(position), camera.apparent_radius(position, radius))


class RestSwitch:
    """Count the frames the ball has stood still for; say when the accurate method is due."""

    def __init__(self, motion_px, frames):
        if not motion_px > 0 or frames < 1:
            raise ValueError('rest: motion_px must be positive and frames at least 1, '
                             f'got {motion_px!r}, {frames!r}')
        self.motion_px, self.frames = float(motion_px), int(frames)
        self.still, self.last_outline = 0, None

    def update(self, outline):
        """Record the ball's outline (``outline_px``) in a new frame; return whether it rests."""
        outline = np.asarray(outline, dtype=float)
        moved = (np.inf if self.last_outline is None
                 else float(np.linalg.norm(outline - self.last_outline)))
        self.last_outline = outline
        self.still = self.still + 1 if moved < self.motion_px else 0
        return self.still >= self.frames

    def lost(self):
        """Record a frame without a detection: the count starts again."""
        self.still, self.last_outline = 0, None


class MeanCorrection:
    """
    Sum a ball's frames at rest; keep the accurate method's correction of the fast one.

    ``add`` a frame with its fast detection; when it returns True, run the accurate method on
    ``mean_image()`` and give its position to ``fitted``; ``corrected`` returns a fast position
    plus the latest correction (None before the first fit).
    """

    def __init__(self, motion_px):
        if not motion_px > 0:
            raise ValueError(f'mean correction: motion_px must be positive, got {motion_px!r}')
        self.motion_px = float(motion_px)
        self.delta, self.n_fit = None, 0
        self.restart()

    def restart(self):
        """Start a new sum (the correction of the last fit stays until the next fit)."""
        self.sum, self.n = None, 0
        self.fast_sum, self.outline_sum = np.zeros(3), 0.0

    def reset(self):
        """Forget the sum and the correction: the ball moved or was lost."""
        self.restart()
        self.delta = None

    def add(self, image, fast_position, outline):
        """
        Add a frame (mono image) and its fast detection (m, optical; its ``outline_px``).

        Return True when the accurate method is due: the first frame, and a power of two of
        frames summed from FIRST_MEAN on.
        """
        outline = np.asarray(outline, dtype=float)
        if self.n and np.linalg.norm(outline - self.outline_sum / self.n) > self.motion_px:
            self.restart()
        if self.sum is None:
            self.sum = np.zeros(np.shape(image), dtype=np.float32)
        np.add(self.sum, image, out=self.sum)
        self.n += 1
        self.fast_sum += fast_position
        self.outline_sum = self.outline_sum + outline
        return self.n == 1 or (self.n >= FIRST_MEAN and self.n & (self.n - 1) == 0)

    def mean_image(self):
        """Return the mean of the frames summed (float32)."""
        return self.sum / np.float32(self.n)

    def fitted(self, accurate_position):
        """Keep the correction from the accurate method's position on ``mean_image()``."""
        self.delta = np.asarray(accurate_position, dtype=float) - self.fast_sum / self.n
        self.n_fit = self.n

    def corrected(self, fast_position):
        """Return the fast position plus the latest correction, or None before the first fit."""
        return None if self.delta is None else np.asarray(fast_position, dtype=float) + self.delta


class RestCorrection:
    """
    One frame's step at rest, as the sphere_detector node takes it: RestSwitch and MeanCorrection.

    ``accurate(image, seed)`` runs the accurate method on an image from a seed Detection and
    returns its Detection or raises DetectionError; ``label`` names it in the corrected
    detections' method ('conic+model mean'). It must measure the ball it is seeded with, never
    search for one (detector.detect(search=False)): a fit of another ball would move every frame
    of the rest. ``every_frame``: the accurate method on every frame at rest instead (its own
    detection published), as the node measured before MeanCorrection: log2(n) - 1 fits become n.
    ``seen(image, det, noise)``: called when a rest ends whose last fit succeeded, with the mean
    image of its frames, that fit's Detection and the mean image's pixel noise (the fit's
    'noise', scaled from the frames it had to all the rest's): the node adds it to its
    background plate (robotenis_vision.plate).
    """

    def __init__(self, motion_px, frames, accurate, label, every_frame=False, seen=None):
        self.switch = RestSwitch(motion_px, frames)
        self.mean = MeanCorrection(motion_px)
        self.accurate, self.label, self.every_frame = accurate, label, every_frame
        self.seen = seen
        self.last = None                # the accurate method's last Detection

    def ended(self):
        """Close a rest (the ball moved or was lost): its mean image goes to ``seen``."""
        noise = self.last.extra.get('noise') if self.last is not None else None
        if self.seen and noise and self.mean.n:      # (every_frame sums no frames)
            self.seen(self.mean.mean_image(), self.last,
                      noise * np.sqrt(self.mean.n_fit / self.mean.n))
        self.mean.reset()
        self.last = None

    def lost(self):
        """Record a frame without a detection."""
        self.switch.lost()
        self.ended()

    def update(self, image, det, outline):
        """
        Return the Detection to publish for a frame, from its fast Detection det and its outline.

        ``outline``: det's ``outline_px``. Or None: the frame is dropped. And the accurate method's
        failure on this frame (a message) or None. The accurate method starts from its own last
        detection while the ball stays still and its frames' sum goes on, else from det. On mean
        images, if it fails the last correction stays; every frame (``every_frame``), its failure
        drops that frame. Before any correction, None is returned with the reason: at rest the
        ball is the accurate method's, and a ball it refuses is not trusted (the fast method's
        cold search can take a pattern for the ball and follow it: on a list kept out of
        benchmarks/vision.py, seed 37, a rest whose every fit refused the conic's ball would have
        published it, 0.4 m off, for the whole rest).
        """
        if not self.switch.update(outline):
            self.ended()
            return det, None
        if self.every_frame:
            try:
                self.last = self.accurate(image, self.last or det)
                return self.last, None
            except DetectionError as e:
                self.last = None
                return None, f'at rest: {e}'
        failure = None
        if self.mean.add(image, det.position, outline):
            seed = det if self.mean.n == 1 else self.last or det    # a new sum: the ball moved
            try:
                self.last = self.accurate(self.mean.mean_image(), seed)
                self.mean.fitted(self.last.position)
            except DetectionError as e:
                self.last, failure = None, f'on the mean of {self.mean.n} frames at rest: {e}'
        position = self.mean.corrected(det.position)
        if position is None:
            return None, failure or (f'at rest: no {self.label} correction yet (no fit of this '
                                     'rest has succeeded)')
        return replace(det, position=position, method=f'{det.method}+{self.label} mean'), failure
