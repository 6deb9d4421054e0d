"""
Where the ball is: fixed on its rod for calibration, or flying a chaotic path for tracking.

The chaotic path is the Lorenz attractor, integrated once on a fine grid, scaled into a box in
front of the robot and re-timed so that its fastest point moves at ``max_speed`` (the paper's
tracking tests: 500 to 1500 mm/s). It is deterministic for a seed, smooth (continuous
acceleration) and never repeats over a test's 5,000 samples.
"""
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class FixedBall:
    """The calibration ball on its transparent rod (base frame, m)."""

    position: tuple

    def at(self, t):
        return np.broadcast_to(np.asarray(self.position, dtype=float), np.shape(t) + (3,)).copy()


class ChaoticBall:
    """A ball on a scaled Lorenz trajectory; ``at(t)`` gives positions (..., 3), base frame, m."""

    def __init__(self, centre, half_size, max_speed, seed=0, duration=120.0, dt=1e-3):
        rng = np.random.default_rng(seed)
        state = np.array([1.0, 1.0, 20.0]) + rng.normal(scale=1.0, size=3)
        s = 0.01                       # Lorenz time step (attractor units)
        n = int(duration / dt) + 1
        path = np.empty((n + 2000, 3))
        for k in range(len(path)):     # RK2 is plenty: the path only has to be smooth and chaotic
            path[k] = state
            mid = state + 0.5 * s * _lorenz(state)
            state = state + s * _lorenz(mid)
        path = path[2000:]             # drop the approach to the attractor
        lo, hi = path.min(axis=0), path.max(axis=0)
        unit = (path - (lo + hi) / 2) / ((hi - lo) / 2)   # into [-1, 1]^3
        self._points = np.asarray(centre, dtype=float) + unit * np.asarray(half_size, dtype=float)
        step = np.linalg.norm(np.diff(self._points, axis=0), axis=1)   # path length per sample
        self._dt = float(step.max() / max_speed)       # re-time: the fastest segment at max_speed
        self.max_speed = max_speed

    @property
    def duration(self):
        return self._dt * (len(self._points) - 1)

    def at(self, t):
        """Return the position at time t (s), linear between samples; wraps after ``duration``."""
        x = (np.asarray(t, dtype=float) % self.duration) / self._dt
        i = np.minimum(np.floor(x).astype(int), len(self._points) - 2)
        w = (x - i)[..., None]
        return (1 - w) * self._points[i] + w * self._points[i + 1]


def _lorenz(v, sigma=10.0, rho=28.0, beta=8.0 / 3.0):
    x, y, z = v
    return np.array([sigma * (y - x), x * (rho - z) - y, x * y - beta * z])
