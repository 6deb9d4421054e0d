"""
When the ball stands still in the image: the switch between the fast and the accurate method.

The sphere_detector node measures every frame with its fast method (the conic method seeded by
the last frame); once the ball's image has moved less than ``motion_px`` between frames for
``frames`` frames in a row (the robot at rest), the accurate one (the model fit) refines each
frame's detection, starting from it. A frame that could not be measured starts the count again.
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
