"""
Cartesian point-to-point trajectories on the 4-5-6-7 polynomial (dynamics paper, section III).

A segment goes in a straight line from P0 to P1 as P(t) = P0 + (P1 - P0) s(t/T), with

    s(u) = 35 u^4 - 84 u^5 + 70 u^6 - 20 u^7,   u in [0, 1]

whose velocity, acceleration and jerk are zero at both ends: accelerations are continuous and the
jerk finite, also where segments are chained rest to rest. The duration T is the shortest that
keeps the speed under v_max and the acceleration under a_max: the peaks of s' and s'' are 35/16
(at u = 1/2) and S2_PEAK (at u = (5 - sqrt 5)/10), so
T = max(35/16 L / v_max, sqrt(S2_PEAK L / a_max)).
"""
from dataclasses import dataclass
from functools import cached_property

import numpy as np

S1_PEAK = 35.0 / 16.0
U_S2_PEAK = (5.0 - np.sqrt(5.0)) / 10.0     # where s''' = 840 u (1 - u) (5u^2 - 5u + 1) vanishes


def s_derivatives(u):
    """Return s, s', s'', s''' of the 4-5-6-7 polynomial at u (array), derivatives along u."""
    return _polynomials(np.asarray(u, dtype=float))


def _polynomials(u):
    """Return s_derivatives at u: an array, or a float (the same operations, the same values)."""
    u2, u3 = u * u, u * u * u
    s = u2 * u2 * (35 - 84 * u + 70 * u2 - 20 * u3)
    s1 = u3 * (140 - 420 * u + 420 * u2 - 140 * u3)
    s2 = u2 * (420 - 1680 * u + 2100 * u2 - 840 * u3)
    s3 = u * (840 - 5040 * u + 8400 * u2 - 4200 * u3)
    return s, s1, s2, s3


S2_PEAK = float(s_derivatives(U_S2_PEAK)[2])


def duration(distance, v_max, a_max):
    """Return the shortest T (s) for ``distance`` m with speed <= v_max m/s, accel <= a_max."""
    if v_max <= 0 or a_max <= 0:
        raise ValueError(f'trajectory limits must be positive: v_max={v_max!r}, a_max={a_max!r}')
    return max(S1_PEAK * distance / v_max, np.sqrt(S2_PEAK * distance / a_max))


@dataclass(frozen=True)
class Segment:
    """One rest-to-rest straight segment from P0 to P1 (m) starting at t0 and lasting T (s)."""

    P0: np.ndarray
    P1: np.ndarray
    t0: float
    T: float

    @property
    def t1(self):
        return self.t0 + self.T

    def sample(self, t):
        """
        Return position, velocity, acceleration and jerk at times t (array (N,) or scalar).

        Each is (..., 3).

        Before t0 the segment is at rest at P0, after t0 + T at rest at P1.
        """
        t = np.asarray(t, dtype=float)
        u = np.clip((t - self.t0) / self.T, 0.0, 1.0) if self.T > 0 else np.ones_like(t)
        s, s1, s2, s3 = s_derivatives(u)
        D = np.asarray(self.P1) - np.asarray(self.P0)
        T = self.T if self.T > 0 else 1.0
        return (self.P0 + s[..., None] * D, (s1 / T)[..., None] * D,
                (s2 / T ** 2)[..., None] * D, (s3 / T ** 3)[..., None] * D)

    def at(self, t):
        """
        Return position, velocity and acceleration at one time t (float), lists of 3 floats.

        The values of ``sample`` (the same operations, on floats), for a controller's every
        tick: 2 us against 16 us with arrays of one time.
        """
        u = min(max((t - self.t0) / self.T, 0.0), 1.0) if self.T > 0 else 1.0
        s, s1, s2, _ = _polynomials(u)
        T = self.T if self.T > 0 else 1.0
        v, a = s1 / T, s2 / T ** 2
        P0, D = self._floats
        return ([p + s * d for p, d in zip(P0, D)], [v * d for d in D], [a * d for d in D])

    @cached_property
    def _floats(self):
        return (np.asarray(self.P0, dtype=float).tolist(),
                (np.asarray(self.P1) - np.asarray(self.P0)).tolist())


def segment(P0, P1, t0, v_max, a_max):
    """Return the fastest segment from P0 to P1 within the limits, starting at t0."""
    P0, P1 = np.asarray(P0, dtype=float), np.asarray(P1, dtype=float)
    return Segment(P0, P1, float(t0), float(duration(np.linalg.norm(P1 - P0), v_max, a_max)))


class Chain:
    """Segments chained rest to rest through the waypoints; sample() covers the whole chain."""

    def __init__(self, waypoints, v_max, a_max, t0=0.0):
        waypoints = np.asarray(waypoints, dtype=float)
        if waypoints.ndim != 2 or waypoints.shape[1] != 3 or len(waypoints) < 2:
            raise ValueError('waypoints: expected (N >= 2, 3) positions, got shape '
                             f'{waypoints.shape}')
        self.segments = []
        t = t0
        for P0, P1 in zip(waypoints[:-1], waypoints[1:]):
            self.segments.append(segment(P0, P1, t, v_max, a_max))
            t = self.segments[-1].t1

    @property
    def t0(self):
        return self.segments[0].t0

    @property
    def t1(self):
        return self.segments[-1].t1

    def sample(self, t):
        """Return position, velocity, acceleration, jerk at times t (N,), each (N, 3)."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        ends = np.array([s.t1 for s in self.segments])
        which = np.minimum(np.searchsorted(ends, t, side='left'), len(self.segments) - 1)
        out = [np.empty((len(t), 3)) for _ in range(4)]
        for k in np.unique(which):
            mask = which == k
            for o, v in zip(out, self.segments[k].sample(t[mask])):
                o[mask] = v
        return tuple(out)
