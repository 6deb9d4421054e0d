"""
The seed of the next frame's detection: the ball where its last two detections say it will be.

A detection seeded by the frame before measures the outline where the ball was and falls back to a
search of the whole image when it is not there (robotenis_vision.detector): while the robot moves,
the ball's image moves several pixels a frame, the seed misses it and most of the detector's time
went to those searches. The seed is therefore moved on at the ball's velocity from the last two
detections (constant velocity, in the optical frame), to the new frame's time.
"""
from dataclasses import replace

import numpy as np


class Seed:
    """The last two detections and their times (s); ``at(t)`` the seed for a frame at time t."""

    def __init__(self):
        self.lost()

    def lost(self):
        """Forget the ball: the next frame is searched."""
        self.track = []

    def update(self, det, t):
        """Record a detection of the frame at time t (s)."""
        self.track = self.track[-1:] + [(float(t), det)]

    def at(self, t):
        """Return the last detection moved to time t at the ball's velocity, or None if lost."""
        if not self.track:
            return None
        t1, last = self.track[-1]
        if len(self.track) < 2 or not t > t1:
            return last
        t0, before = self.track[0]
        if not t1 > t0:
            return last
        velocity = (np.asarray(last.position) - np.asarray(before.position)) / (t1 - t0)
        return replace(last, position=np.asarray(last.position) + velocity * (t - t1))
