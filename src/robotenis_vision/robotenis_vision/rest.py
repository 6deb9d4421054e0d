"""
When the ball stands still in the image: the fast method corrected by the accurate one.

The sphere_detector node measures every frame with its fast method (the conic method seeded by
the last frame). Once the ball's image has moved less than ``motion_px`` between frames for
``frames`` frames in a row (the robot at rest: RestSwitch), the frames are summed, and the
accurate method (the model fit) runs on their mean image each time their number reaches a power
of two: log2(n) + 1 fits for n frames at rest instead of n (MeanCorrection). Each frame k then
gives

    p_k = f_k + (a(M_j) - mean(f_1 .. f_j))

f_k its fast detection, a(M_j) the accurate method on the mean image M_j of the j frames summed
at the last fit, mean(f_1 .. f_j) their fast detections' mean: the accurate method's position of
the ball at rest, with the frame's own noise and any slow drift from the fast one. Averaged over
a rest, p_k carries the accurate fit's bias on an image of noise sigma / sqrt(j), which tends to
its bias on a noise-free render (the bias robotenis_validation.study gives the studies), where a
mean of per-frame fits carried their bias on single noisy frames, which depends on the sensor's
noise (0.06-0.14 mm apart in depth at 0.25-0.4 m, the simulated camera). The fast detections'
mean, not the fast method on M_j, is subtracted: the fast method's own noise-dependent bias
cancels in f_k - mean(f). A mean image is only of one ball position: if the fast detection
leaves the summed frames' mean by more than ``motion_px``, the sum starts again from that frame.
With a camera response gamma != 1 the mean of encoded grey levels is fitted, a second-order error
of (noise / level)^2, negligible at the noise of a camera.
"""
import numpy as np


class RestSwitch:
    """Count the frames the ball has stood still for; say when the accurate method is due."""

    def __init__(self, motion_px, frames):
        if not motion_px > 0 or frames < 1:
            raise ValueError('rest: motion_px must be positive and frames at least 1, '
                             f'got {motion_px!r}, {frames!r}')
        self.motion_px, self.frames = float(motion_px), int(frames)
        self.still, self.last_px = 0, None

    def update(self, px):
        """Record the ball's image centre (px) in a new frame; return whether it is at rest."""
        px = np.asarray(px, dtype=float)
        moved = np.inf if self.last_px is None else float(np.linalg.norm(px - self.last_px))
        self.last_px = px
        self.still = self.still + 1 if moved < self.motion_px else 0
        return self.still >= self.frames

    def lost(self):
        """Record a frame without a detection: the count starts again."""
        self.still, self.last_px = 0, None


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
        self.delta = None
        self.restart()

    def restart(self):
        """Start a new sum (the correction of the last fit stays until the next fit)."""
        self.sum, self.n = None, 0
        self.fast_sum, self.px_sum = np.zeros(3), np.zeros(2)

    def reset(self):
        """Forget the sum and the correction: the ball moved or was lost."""
        self.restart()
        self.delta = None

    def add(self, image, fast_position, px):
        """
        Add a frame (mono image) and its fast detection (m, optical; px its image centre).

        Return True when the accurate method is due: the frames summed are a power of two.
        """
        px = np.asarray(px, dtype=float)
        if self.n and np.linalg.norm(px - self.px_sum / self.n) > self.motion_px:
            self.restart()
        if self.sum is None:
            self.sum = np.zeros(np.shape(image), dtype=np.float32)
        np.add(self.sum, image, out=self.sum)
        self.n += 1
        self.fast_sum += fast_position
        self.px_sum += px
        return self.n & (self.n - 1) == 0

    def mean_image(self):
        """Return the mean of the frames summed (float32)."""
        return self.sum / np.float32(self.n)

    def fitted(self, accurate_position):
        """Keep the correction from the accurate method's position on ``mean_image()``."""
        self.delta = np.asarray(accurate_position, dtype=float) - self.fast_sum / self.n

    def corrected(self, fast_position):
        """Return the fast position plus the latest correction, or None before the first fit."""
        return None if self.delta is None else np.asarray(fast_position, dtype=float) + self.delta
